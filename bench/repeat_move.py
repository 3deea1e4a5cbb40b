"""One move through ROS, again and again: how deep it goes, and the stalls that came with it.

sim, planner and controller run as separate processes on a ROS domain of their own (as the
process tests run them). Each run resets the sim, takes the arm to the start point, then
publishes the goal and follows the move on ``/sim/ground_truth``. Per run: the outcome, the
time to rest, how far either link went below the floor (0: not at all), and the silences
longer than 30 ms heard here on ``voltage_command`` and on the true state during the move
(a stall of the controller, of the sim, or of this process).

    python bench/repeat_move.py                       # back -> low front, 12 runs
    python bench/repeat_move.py --start -1.5 0.15 --goal 1.5 0.15 --runs 20
    python bench/repeat_move.py --param feedback_voltage_reserve:=0.5   # the controller's

Needs the package built and sourced. Not a test: it asserts nothing and prints a table.
"""

import argparse
from pathlib import Path
import sys
import tempfile
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE)]

from arm_rig import ArmRig  # noqa: E402
from bench_ros import RosMoves  # noqa: E402
import numpy as np  # noqa: E402
from ros_harness import Probe  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402

SILENCE_S = 0.03


def silences_ms(times) -> list:
    gaps = np.diff(np.asarray(times, float))
    return [round(1000 * gap) for gap in gaps if gap > SILENCE_S]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--start', type=float, nargs=2, default=(-1.0, 1.0))
    parser.add_argument('--goal', type=float, nargs=2, default=(1.6, 0.12))
    parser.add_argument('--runs', type=int, default=12)
    parser.add_argument('--domain', type=int, default=91)
    parser.add_argument('--param', action='append', default=[],
                        help="a controller parameter, 'name:=value' (repeatable)")
    args = parser.parse_args()
    forbidden = ForbiddenSpace(config.load('controller')[0])
    probe = Probe(args.domain, 'repeat_move')
    controller_args = tuple(arg for param in args.param for arg in ('-p', param))
    rig = ArmRig(args.domain, probe, Path(tempfile.mkdtemp(prefix='arm_repeat_move_')),
                 {'controller': controller_args})
    moves = RosMoves(rig, False)
    heard = []
    probe.node.create_subscription(Float64MultiArray, '/voltage_command',
                                   lambda _: heard.append(time.monotonic()), 100)
    below = 0
    try:
        rig.start_all()
        rig.ready(90.0)
        print(f'{tuple(args.start)} -> {tuple(args.goal)} m through ROS, {args.runs} runs; '
              f'node logs in {rig.log_dir}')
        print('| run | outcome | s to rest | below the floor mm | '
              'silences on voltage_command ms | silences on the true state ms |')
        print('|---|---|---|---|---|---|')
        for run in range(args.runs):
            if run:
                rig.reset_sim()
            moves.go_to(tuple(args.start))
            began = time.monotonic()
            del heard[:]
            result = moves.move(tuple(args.goal))
            truth = [(t, m) for t, m in rig.truth if t >= began]
            q = np.array([m.position for _, m in truth]).reshape(-1, 2)
            depth_mm = -1000 * float(np.min(forbidden.lowest_point_m(q))) if len(q) else \
                float('nan')
            below += depth_mm > 0.0
            print(f"| {run} | {result['outcome']} | {result['ros_s']:.3f} | {depth_mm:.0f} | "
                  f'{silences_ms(heard)} | {silences_ms([t for t, _ in truth])} |', flush=True)
    finally:
        rig.close()
        probe.close()
    print(f'below the floor in {below} of {args.runs} runs')


if __name__ == '__main__':
    main()
