"""Simulation, planning and control of a two-joint FRC-style arm."""

import os

# The arm's matrices are 2x2 and 4x4: BLAS threads cannot speed them up, and OpenBLAS's idle
# threads spin between calls. At 50 Hz they never sleep, and the controller burnt a whole
# core (118 % CPU with them, 17 % without), starving the sim and planner on a 2-core machine.
# This runs before numpy loads in every node; a value set by the user is kept.
for _variable in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_variable, '1')
