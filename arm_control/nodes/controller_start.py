"""The ``controller`` executable: its plan worker's process is started first, before the
node's modules are imported, so that the worker loads its timing code while the controller
loads its own, not after it (on a busy machine each takes seconds, and the first goal waits
for both); and its DDS participant joins before them too (``join_early``)."""

import sys

from arm_control.nodes.worker_spawn import spawn, started


def main(args=None):
    started.append(spawn())
    from arm_control.nodes.common import join_early
    joining = join_early(args, 'controller')        # discovered while the modules load
    if isinstance(joining, int):
        sys.exit(joining)
    from arm_control.nodes.controller import main as controller_main
    controller_main(args)
