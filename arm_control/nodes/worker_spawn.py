"""Starting the plan worker's process: light enough to run before the controller's own
modules load (``controller_start``), so both load at once."""

import os
from pathlib import Path
import subprocess
import sys

started = []                # the worker the executable started, for the node's PlanWorker

# The arm_control the worker imports: this process's own (``-P`` keeps the working directory
# off its path, where another copy of the package, a checkout's, would be found first).
PACKAGE_ROOT = str(Path(__file__).resolve().parents[2])


def spawn(*args, nice: int = 0) -> subprocess.Popen:
    """``python -m arm_control.nodes.plan_worker`` (with ``args``, at ``nice``), pickles over
    its stdin and stdout, on this process's arm_control."""
    path = os.environ.get('PYTHONPATH')
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [PACKAGE_ROOT] + ([path] if path else [])))
    return subprocess.Popen([sys.executable, '-P', '-m', 'arm_control.nodes.plan_worker', *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=environment,
                            preexec_fn=(lambda: os.nice(nice)) if nice else None)


def take_started():
    """The worker ``main`` started (once), else None."""
    return started.pop() if started else None
