"""The joint states or the commands stalled mid-move, through ROS: does the arm get its goal,
out of the floor?

A DDS write blocks for about 330 ms now and then when a node joins the graph
(``dds_write_block.py``), in the sim as in the controller: the readings stop, the controller
sends 0 V once they are ``joint_state_timeout_s`` old, and the sim, frozen meanwhile, catches
up when it is let go. Here the sim is paused (SIGSTOP) for ``--stall`` s at a random moment
0.2-1.2 s into "low back -> low front", a fast move low over the top, ``--runs`` times; each
run prints whether the goal was reached, the lowest point of either link (below 0 is in the
floor) and what the controller said when the readings came back (or, off its plan, when it
left it). With ``--pause controller`` the controller's process is paused instead, as a
blocked write of its own freezes it: no commands, so the sim applies 0 V after
``command_timeout_s`` while the arm moves on.

    python bench/sensor_stalls.py                    # 8 runs of 0.25 s stalls
    python bench/sensor_stalls.py --stall 0.35 --load
    python bench/sensor_stalls.py --pause controller --load

Needs the package built and sourced. Not a test: it asserts nothing. Node logs stay in the
directory it names.
"""

import argparse
from pathlib import Path
import random
import sys
import tempfile
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE)]

from arm_rig import ArmRig  # noqa: E402
from bench_ros import lowest_mm  # noqa: E402
import busy  # noqa: E402
import numpy as np  # noqa: E402
from ros_harness import Probe, ros_domain  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from arm_control import config  # noqa: E402

LOW_BACK, LOW_FRONT = (-1.5, 0.15), (1.6, 0.1)


def one_run(rig, arm, node: str, stall_s: float, into_s: float) -> tuple:
    """(outcome, lowest point mm, what the controller said when the readings came back)."""
    if rig.state == 'estopped':
        rig.call(Trigger, '/controller/reset')
        rig.spin_for(1.0)
    if not rig.reach_in_tries(*LOW_BACK):
        return 'could not reach the start', float('nan'), ''
    rig.wait_still()
    began = time.monotonic()
    rig.send(*LOW_FRONT)
    if not rig.wait_state('tracking', 5.0):
        return f'did not start ({rig.state})', float('nan'), ''
    rig.spin_for(into_s)
    rig.pause(node)
    time.sleep(stall_s)
    rig.resume(node)
    rig.spin_until(lambda: rig.said('goal_reached', began) or rig.state == 'estopped', 10.0)
    rig.spin_for(0.5)
    q = np.array([m.position for m in rig.truth.messages(began)])
    lowest = lowest_mm(arm, q) if len(q) else float('nan')      # nan: counted as failed
    back = [sentence for kind in ('sensors_back', 'off_plan')
            for _, _, sentence in rig.said(kind, began)]
    outcome = 'reached' if rig.said('goal_reached', began) else rig.state
    return outcome, lowest, back[-1] if back else '(nothing said)'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--stall', type=float, default=0.25, help='seconds the node is paused')
    parser.add_argument('--pause', choices=('sim', 'controller'), default='sim')
    parser.add_argument('--runs', type=int, default=8)
    parser.add_argument('--load', action='store_true', help='two busy loops throughout')
    parser.add_argument('--seed', type=int, default=1, help='of the moments of the stalls')
    args = parser.parse_args()
    arm, _ = config.load('controller')
    moments = random.Random(args.seed)
    log_dir = tempfile.mkdtemp(prefix='arm_sensor_stalls_')
    print(f'{args.stall:g} s stalls of the {args.pause} on low back -> low front'
          f'{", two busy loops" if args.load else ", idle"}; node logs in {log_dir}\n')
    print('| run | stall at s | outcome | lowest mm | said when the readings came back |')
    print('|---|---|---|---|---|')
    failed = 0
    loops = busy.start(2, 3600.0) if args.load else None
    try:
        with ros_domain() as domain:
            probe = Probe(domain)
            rig = ArmRig(domain, probe, log_dir)
            try:
                rig.start_all()
                rig.ready()
                for run in range(1, args.runs + 1):
                    into_s = moments.uniform(0.2, 1.2)
                    outcome, lowest, said = one_run(rig, arm, args.pause, args.stall, into_s)
                    failed += outcome != 'reached' or not lowest >= 0.0
                    said = said.split(': ', 1)[-1]
                    print(f'| {run} | {into_s:.2f} | {outcome} | {lowest:.0f} | {said} |',
                          flush=True)
            finally:
                rig.close()
                probe.close()
    finally:
        if loops:
            busy.stop(loops)
    print(f'\n{failed} of {args.runs} runs missed the goal or touched the floor.')


if __name__ == '__main__':
    main()
