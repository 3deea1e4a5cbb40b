"""Starting the plan worker's process: light enough to run before the controller's own
modules load (``controller_start``), so both load at once."""

import os
import subprocess
import sys

started = []                # the worker the executable started, for the node's PlanWorker


def spawn(*args, nice: int = 0) -> subprocess.Popen:
    """``python -m arm_control.nodes.plan_worker`` (with ``args``, at ``nice``), pickles over
    its stdin and stdout."""
    return subprocess.Popen([sys.executable, '-m', 'arm_control.nodes.plan_worker', *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            preexec_fn=(lambda: os.nice(nice)) if nice else None)


def take_started():
    """The worker ``main`` started (once), else None."""
    return started.pop() if started else None
