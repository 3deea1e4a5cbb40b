"""The ``controller`` executable: its plan worker's process is started first, before the
node's modules are imported, so that the worker loads its timing code while the controller
loads its own, not after it (on a busy machine each takes seconds, and the first goal waits
for both)."""

import os
import subprocess
import sys

_STARTED = []               # the worker ``main`` started, for the node's PlanWorker to take


def spawn(*args, nice: int = 0) -> subprocess.Popen:
    """``python -m arm_control.nodes.plan_worker`` (with ``args``, at ``nice``), pickles over
    its stdin and stdout."""
    return subprocess.Popen([sys.executable, '-m', 'arm_control.nodes.plan_worker', *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            preexec_fn=(lambda: os.nice(nice)) if nice else None)


def take_started():
    """The worker ``main`` started (once), else None."""
    return _STARTED.pop() if _STARTED else None


def main(args=None):
    _STARTED.append(spawn())
    from arm_control.nodes.controller import main as controller_main
    controller_main(args)
