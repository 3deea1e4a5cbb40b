"""What the user waits for a goal through ROS: from its publication to the arm moving, and to
the arm at rest where it stops.

The real nodes (sim, planner, controller: ``test/rigs/arm_rig.py``'s ArmRig, the installed
executables on a ROS domain of their own). For each move of the trajectory bench's suite the
arm is first sent to the move's start and left to settle; then the goal is published and
the sim's true state (``/sim/ground_truth``, its own stamps) is read:

- moving: when the arm left its rest, extrapolated back from the samples between 0.2° and
  3° away from it (the distance grows as t² from rest, so √distance is linear in t);
- at rest: the first sample from which the arm stays within 1° of where it comes to rest;
- the controller's own account of the goal (its goal_reached event: planner round trip,
  timing, trajectory, refinement).

    python bench/user_wait.py                # with install/setup.bash sourced
    python bench/user_wait.py --loaded       # two busy loops beside it (busy.py)
"""

import math
from pathlib import Path
import sys
import tempfile
import time

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent / 'test' / 'rigs'), str(BENCH.parent)]

import busy  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config  # noqa: E402

LEAVING_RAD = (math.radians(0.2), math.radians(3.0))
REST_RAD = math.radians(1.0)


def seconds(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def one_move(rig, start_xy, goal_xy, timeout_s=15.0):
    """(to moving s, to rest s, the controller's account) of one goal sent at rest."""
    for xy, record in ((start_xy, False), (goal_xy, True)):
        rig.spin_for(0.3)
        since = time.monotonic()
        sent = time.time()
        rig.send(*xy)
        assert rig.spin_until(lambda: rig.said('goal_reached', since), timeout_s), \
            rig.event_log(since)
        rig.spin_for(0.6)                         # the arm comes to rest, the samples come in
    samples = [(seconds(m.header.stamp), np.array(m.position)) for _, m in rig.truth
               if seconds(m.header.stamp) >= sent - 0.2]
    t = np.array([s for s, _ in samples])
    q = np.array([p for _, p in samples])
    before = q[np.searchsorted(t, sent) - 1]
    away = np.max(np.abs(q - before), axis=1)
    gone = np.flatnonzero((away > LEAVING_RAD[1]) & (t > sent))[0]
    leaving = np.flatnonzero(away[:gone] > LEAVING_RAD[0])
    leaving = leaving[leaving > np.flatnonzero(away[:gone] <= LEAVING_RAD[0])[-1]]
    if len(leaving) >= 2:
        slope, offset = np.polyfit(t[leaving], np.sqrt(away[leaving]), 1)
        start_s = -offset / slope
    else:                                         # left within a sample: it is somewhere here
        start_s = t[gone - 1]
    rest = q[-1]
    outside = np.flatnonzero(np.max(np.abs(q - rest), axis=1) > REST_RAD)
    rest_s = t[outside[-1] + 1]
    account = rig.said('goal_reached', since)[-1][2]
    return max(start_s, sent) - sent, rest_s - sent, account


def main():
    from arm_rig import ArmRig
    from bench_trajectory import print_table, SUITE
    from ros_harness import Probe, ros_domain
    loops = busy.start(2, 3600.0) if '--loaded' in sys.argv else []
    rows = []
    try:
        with ros_domain() as domain, tempfile.TemporaryDirectory() as logs:
            probe = Probe(domain)
            rig = ArmRig(domain, probe, Path(logs))
            rig.start_all()
            try:
                rig.ready()
                for name, start_xy, goal_xy in SUITE:
                    moving_s, rest_s, account = one_move(rig, start_xy, goal_xy)
                    rows.append({'move': name, 'to moving ms': f'{1e3 * moving_s:.0f}',
                                 'to rest s': f'{rest_s:.3f}',
                                 "the controller's account": account.split('(', 1)[-1]})
                    print(' | '.join(rows[-1].values()), file=sys.stderr, flush=True)
            finally:
                rig.close()
                probe.close()
    finally:
        busy.stop(loops)
    arm = config.load('sim')[0]
    print(f'What the user waits per goal through ROS ({len(rows)} moves of the default arm, '
          f'{"two busy loops beside it" if loops else "idle"}): from the goal\'s publication '
          'to the arm moving (extrapolated from the true state) and to the arm at rest '
          f'within 1 deg; arm {arm.shoulder.length_m} m / {arm.elbow.length_m} m')
    print_table(rows)
    waits = np.array([float(r['to moving ms']) for r in rows])
    print(f'to moving: median {np.median(waits):.0f} ms, worst {np.max(waits):.0f} ms')


if __name__ == '__main__':
    main()
