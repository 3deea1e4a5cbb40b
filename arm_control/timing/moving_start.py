"""Timing a path that starts at a given path speed (a preempted move), and braking distances.

TOPP-RA (toppra) times the path under the rows of ``rows.rows``; their term D·√x (back-EMF
and viscous friction) is outside its canonical form, so it is linearised about the previous
profile x₀ (Newton's method),

    D·√x ≈ D·(x + x₀) / (2·√x₀),

which overestimates D·√x (√x is concave), so every row whose √x term is positive -- the
motor driving against its own back-EMF, the side that bounds acceleration and top speed -- is
conservative at every iteration; the braking rows are exact at the fixed point. Each
iteration also corrects the bus sag the rows assume toward the one the profile causes
(``bus.BusSag``); the profile is re-solved until both stop changing.
"""

import functools
import math

import numpy as np

from arm_control.model.dynamics import ArmDynamics
from arm_control.timing.bus import along, bus_profile, BusSag, safe
from arm_control.timing.limits import TrajectoryLimits
from arm_control.timing.path import BlendedPath
from arm_control.timing.rows import PathTerms, rows, speed_caps

# Path-speed floor for the back-EMF linearisation (ṡ in rad/s of path): √x₀ never below this.
_SPEED_FLOOR = 1e-3
_NEWTON_ITERATIONS = 8
_NEWTON_TOLERANCE = 0.003          # relative change of the profile's duration


@functools.cache
def toppra_solver():
    """(TOPPRA, the rows as its constraint), imported at the first use: toppra pulls in
    scipy.interpolate and matplotlib (0.8 s), which only a moving start needs, so that the
    controller's own process starts without them."""
    import toppra
    import toppra.algorithm
    import toppra.constraint
    toppra.setup_logging('CRITICAL')   # failures are reported here, not by toppra's logger

    class RowsConstraint(toppra.constraint.LinearConstraint):
        """Rows a·u + b·x + c within ±w, precomputed on the grid, plus x ≤ x_bound."""

        def __init__(self, a, b, c, w, x_bound):
            super().__init__()
            self.dof = 2
            self.identical = True
            self.set_discretization_type(toppra.constraint.DiscretizationType.Interpolation)
            self._rows = (a, b, c)
            m = a.shape[1]
            self._F = np.vstack([np.eye(m), -np.eye(m)])
            self._g = np.concatenate([w, w])
            self._x_bound = x_bound

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            a, b, c = self._rows
            x_bound = np.column_stack([np.zeros(len(gridpoints)), self._x_bound])
            return toppra.constraint.canlinear_colloc_to_interpolate(
                a, b, c, self._F, self._g, None, x_bound, gridpoints, identical=True)

    return toppra.algorithm.TOPPRA, RowsConstraint


def _hardest_braking(A, B, C, D, W, x) -> float:
    """The most negative s̈ every row allows at x = ṡ² (rows of one sample); ≥ 0 when the
    rows allow no braking at all."""
    r = B * x + C + D * math.sqrt(x)
    lowest = -math.inf
    for a, offset, w in zip(A, r, W):
        if abs(a) > 1e-12:
            lowest = max(lowest, min((-w - offset) / a, (w - offset) / a))
    return lowest


def time_moving(path: BlendedPath, grid, terms: PathTerms, limits: TrajectoryLimits,
                start_speed: float, margin_v: float = 0.0, guess=None, bus_hint=None):
    """TOPP-RA from ``start_speed`` to rest, back-EMF linearised, the bus sag found first
    by the exact timing on a coarse grid (``bus.bus_profile``) and raised where it falls
    short.

    Returns (x on the grid, controllable start x) or (None, controllable start x) when the
    start speed is out of reach. x is the squared path speed ṡ².
    """
    x_bound = speed_caps(limits, terms.dq) ** 2            # inf where nothing caps it
    start_x = start_speed ** 2
    if limits.supply is None:
        bus = BusSag(terms, limits, grid)
    else:
        sigma, sag = bus_profile(path, terms.dynamics, limits, along(grid, margin_v), start_speed,
                                 bus_hint)
        bus = BusSag(terms, limits, grid, np.interp(grid, sigma, sag), relax=0.0)
    if start_x > x_bound[0]:
        # Moving faster than the caps allow already: let it slow down into them, at half
        # the hardest braking the start allows.
        A, B, C, D, W = rows(terms, limits, 0.0, margin_v)
        braking = _hardest_braking(A[0], B[0], C[0], D[0], W, start_x)
        slowing = 0.5 * (-braking if braking < 0.0 else 0.0)
        x_bound = np.maximum(x_bound, start_x * 1.001 - 2.0 * slowing * grid)
    if guess is None:
        # Start from the speed at which back-EMF alone would use the whole budget.
        A, B, C, D, W = rows(terms, limits, 0.0, margin_v)
        headroom = np.maximum(W - np.abs(C), 0.05 * W)
        emf_cap = np.min(headroom / np.maximum(np.abs(D), 1e-9), axis=1)
        guess = np.minimum(x_bound, emf_cap ** 2)
    x_prev = np.asarray(guess, float)
    duration_prev = math.inf
    reachable_start = math.inf
    solver_class, rows_constraint = toppra_solver()
    for iteration in range(_NEWTON_ITERATIONS + 4):
        root = np.sqrt(np.maximum(x_prev, _SPEED_FLOOR ** 2))
        A, B, C, D, W = rows(terms, limits, bus.sag, margin_v, coulomb_speed=root)
        constraint = rows_constraint(A, B + D / (2 * root[:, None]),
                                     C + D * root[:, None] / 2, W, x_bound)
        solver = solver_class([constraint], path, gridpoints=grid, solver_wrapper='seidel')
        _, sd, _, K = solver.compute_parameterization(start_speed, 0.0, return_data=True)
        if K is None or np.isnan(K).any():
            return None, 0.0
        reachable_start = K[0, 1]
        if sd is None:
            # Not (yet) controllable from the start speed. Give up when far out of reach;
            # else linearise next about the fastest controllable speeds and try again.
            if reachable_start < (0.25 if iteration == 0 else 0.6) * start_x:
                break
            x_prev, duration_prev = np.minimum(K[:, 1], x_bound), math.inf
            continue
        if np.isnan(sd).any():
            return None, reachable_start
        duration = piece_duration(grid, sd)
        converged = abs(duration - duration_prev) <= _NEWTON_TOLERANCE * duration
        x_prev, duration_prev = sd ** 2, duration
        settled = bus.settle(x_prev)
        if converged and settled or iteration >= _NEWTON_ITERATIONS and settled:
            break
    if start_x > reachable_start * (1 + 1e-6) + 1e-9 or math.isinf(duration_prev):
        return None, reachable_start
    return x_prev, reachable_start


def piece_duration(grid, speed) -> float:
    mean = 0.5 * (speed[1:] + speed[:-1])
    return float(np.sum(np.diff(grid) / np.maximum(mean, 1e-12)))


def stopping_distance(start, direction, speed, dynamics: ArmDynamics,
                      limits: TrajectoryLimits, longest_rad):
    """Path length the hardest braking the limits allow takes to stop, or None (exact
    back-EMF, the bus at the lowest the current limits allow).

    Steps the path speed forward with the most negative s̈ every row allows at the current
    ṡ: A·u + B·x + C + D·√x within ±W.
    """
    if longest_rad <= 0.0:
        return None
    path = BlendedPath(np.array([start, start + longest_rad * direction]), np.zeros(0))
    stages = int(min(150, max(20, math.ceil(longest_rad / 0.01))))
    grid = np.linspace(0.0, longest_rad, stages + 1)
    terms = PathTerms.along(dynamics, path, grid)
    sag = 0.0 if limits.supply is None else safe(limits, len(grid))
    A, B, C, D, W = rows(terms, limits, sag)
    x = speed ** 2
    for i, delta in enumerate(np.diff(grid)):
        lowest = _hardest_braking(A[i], B[i], C[i], D[i], W, x)
        if not math.isfinite(lowest) or lowest >= 0.0:
            return None
        x_next = x + 2 * delta * lowest
        if x_next <= 0.0:
            return float(grid[i] + x / (-2 * lowest))
        x = x_next
    return None
