"""Does checking a client's trajectory hold up the control loop? Through ROS.

sim, planner and controller run as processes on a domain of their own (as the process tests
run them). Phases: the arm held, no goals; then FollowJointTrajectory goals sent back to back
(each waits for its result), first ones the motors can give as asked, then ones they cannot
(each retimed: the heaviest check). Per phase: the goals and their outcomes, and the
controller's own loop period, worst and mean, from its ``/diagnostics`` (one figure a
second), and the longest a client waited for a goal's response (accepted; the check comes after).

    python bench/trajectory_loop.py                # 8 goals a phase
    python bench/trajectory_loop.py --goals 20 --write-docs

Needs the package built and sourced, and control_msgs. Not a test: it asserts nothing.
"""

import argparse
from pathlib import Path
import sys
import tempfile
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE)]

from arm_rig import ArmRig, diagnostic_values  # noqa: E402
from control_msgs.action import FollowJointTrajectory  # noqa: E402
from docs_table import write  # noqa: E402
import numpy as np  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from ros_harness import Probe  # noqa: E402
from trajectory_checks import moveit_style  # noqa: E402
from trajectory_messages import goal_of  # noqa: E402

UP, DOWN = (1.5708, -1.5708), (0.9, -0.5)


def send(rig, client, goal):
    """(seconds until the acceptance came back, error code) of one goal, waited for."""
    began = time.monotonic()
    future = client.send_goal_async(goal)
    rig.spin_until(future.done, 10.0)
    accepted_s = time.monotonic() - began
    result = future.result().get_result_async()
    rig.spin_until(result.done, 20.0)
    return accepted_s, result.result().result.error_code


def loop_periods(rig, since):
    worst, mean = [], []
    for message in rig.diagnostics.messages(since):
        values = diagnostic_values(message, '/controller')
        if values and values.get('loop period worst (s)', 'nan') != 'nan':
            worst.append(1000 * float(values['loop period worst (s)']))
            mean.append(1000 * float(values['loop period mean (s)']))
    return worst, mean


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--goals', type=int, default=8)
    parser.add_argument('--domain', type=int, default=92)
    parser.add_argument('--write-docs', action='store_true')
    args = parser.parse_args()
    probe = Probe(args.domain, 'trajectory_loop')
    rig = ArmRig(args.domain, probe, Path(tempfile.mkdtemp(prefix='arm_trajectory_loop_')))
    client = ActionClient(probe.node, FollowJointTrajectory,
                          '/controller/follow_joint_trajectory')
    lines = ['| phase | goals | outcomes (error_code: count) | goal response ms, '
             'worst | loop period ms, worst of each second: max | median | loop period '
             'ms, mean |', '|---|---|---|---|---|---|---|']
    try:
        rig.start_all()
        rig.ready(90.0)
        assert rig.spin_until(client.server_is_ready, 20.0)
        for phase, seconds in (('held, no goals', None), ('as asked (3 s each)', 3.0),
                               ('retimed (0.4 s asked)', 0.4)):
            since = time.monotonic()
            codes, waits = [], []
            if seconds is None:
                rig.spin_for(float(args.goals))
            for k in range(args.goals if seconds else 0):
                start, end = (UP, DOWN) if k % 2 == 0 else (DOWN, UP)
                wait, code = send(rig, client, goal_of(('shoulder', 'elbow'),
                                                       moveit_style(start, end, seconds, 30)))
                codes.append(code)
                waits.append(1000 * wait)
                rig.spin_for(0.3)
            rig.spin_for(1.5)
            worst, mean = loop_periods(rig, since)
            outcomes = ', '.join(f'{c}: {codes.count(c)}' for c in sorted(set(codes))) or '-'
            lines.append(f'| {phase} | {len(codes)} | {outcomes} | '
                         f'{max(waits, default=float("nan")):.0f} | {max(worst):.1f} | '
                         f'{np.median(worst):.1f} | {np.mean(mean):.2f} |')
    finally:
        rig.close()
        probe.close()
    table = '\n'.join(lines)
    print(table)
    if args.write_docs:
        print(write('trajectory_loop', 'Checking client trajectories beside the control loop '
                    '(through ROS)', 'python bench/trajectory_loop.py ' +
                    ' '.join(sys.argv[1:]), table))


if __name__ == '__main__':
    main()
