"""Planning per goal as a user waits for it through ROS, on a robot's world (issue 18).

The three nodes on a ROS domain of their own with a robot's parameter file (by default the
FRC robot's: body, bumpers, intake, extension and height limits). After the controller has
kept its trajectories between presets (as on a robot that has been on for a few seconds),
goals are published on ``/goal_point`` one after another, each from where the last came to
rest:

- every preset to every other preset (an Euler circuit over the ordered pairs), as a
  driver's buttons send them;
- points anywhere the arm can reach in free space (seeded), which the planner must search
  for, between two presets.

For each goal, from the controller's ``goal_reached`` event: the planner's round trip
(controller to planner and back over DDS, the planner's work included) plus the timing in
the controller's worker: what the user waits for before the arm moves. And, on
``/sim/ground_truth``, every sample checked against the world's forbidden space.

    python bench/planning_ros.py                       # FRC robot, idle
    python bench/planning_ros.py --load                # with two busy loops beside it
    python bench/planning_ros.py --robot default       # the default arm
    python bench/planning_ros.py --points 20 --laps 2
"""

import argparse
import math
from pathlib import Path
import random
import sys

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent / 'test' / 'rigs')]

from arm_rig import ArmRig  # noqa: E402
from bench_ros import breakdown_ms, nodes, RosMoves, wait_for_presets_kept  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.model.kinematics import UnreachableError  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.parameters import default_parameter_file  # noqa: E402
from arm_control.plans.goals import GoalValidator  # noqa: E402


def euler_circuit(names) -> list:
    """A walk through every ordered pair of ``names`` once (a complete digraph's every node
    has as many edges in as out, so one exists), starting and ending at the first."""
    unused = {a: [b for b in names if b != a] for a in names}
    stack, walk = [names[0]], []
    while stack:                                        # Hierholzer's algorithm
        here = stack[-1]
        if unused[here]:
            stack.append(unused[here].pop())
        else:
            walk.append(stack.pop())
    return walk[::-1]


def free_points(arm, count: int, seed: int) -> list:
    """``count`` goal points the arm can reach on some free elbow branch, drawn uniformly
    over its reach (seeded)."""
    validator, rng, points = GoalValidator(arm), random.Random(seed), []
    reach_m = arm.shoulder.length_m + arm.elbow.length_m
    while len(points) < count:
        x, y = rng.uniform(-reach_m, reach_m), rng.uniform(0.0, reach_m)
        try:
            if validator.free_configurations(x, y):
                points.append((x, y))
        except UnreachableError:
            pass
    return points


def goals(arm, points: int, laps: int, seed: int) -> list:
    """(kind, label, (x, y)): the presets' circuit, ``laps`` times, then free points, each
    from a preset."""
    presets = {name: (x, y) for name, x, y in arm.presets}
    walk = euler_circuit(list(presets))
    plan = [('preset to preset', f'{a} -> {b}', presets[b])
            for _ in range(laps) for a, b in zip(walk, walk[1:])]
    names = list(presets)
    for i, xy in enumerate(free_points(arm, points, seed)):
        name = names[i % len(names)]
        plan.append(('to a preset', f'-> {name}', presets[name]))
        plan.append(('any free point', f'-> ({xy[0]:.2f}, {xy[1]:.2f})', xy))
    return plan


def run(args):
    files = () if args.robot == 'default' else (str(default_parameter_file(args.robot)),)
    arm, _ = config.load('controller', *files)
    forbidden = ForbiddenSpace(arm)
    node_args = {name: ('--params-file', files[0]) for name in ArmRig.NODES} if files else {}
    results = []
    with nodes('planning_ros', node_args, args.load, args.domain) as rig:
        ros = RosMoves(rig, simulated=False)
        rig.start_all()
        rig.ready(90.0)
        keeping = wait_for_presets_kept(rig, arm)
        ros.go_to(arm.presets[0][1:])
        for kind, label, xy in goals(arm, args.points, args.laps, args.seed):
            result = ros.move(xy)
            parts = breakdown_ms(result['sentence'])
            q = result['q']
            inside = int(np.count_nonzero(~np.asarray(forbidden.is_free(q)))) if len(q) else 0
            # A goal along a kept trajectory says 'kept trajectory' (its look-up).
            timing_ms = parts.get('timing', parts.get('kept trajectory', math.nan))
            planner_ms = parts.get('planner round trip', math.nan)
            results.append({'kind': kind, 'label': label, 'outcome': result['outcome'],
                            'planner_ms': planner_ms, 'timing_ms': timing_ms,
                            'wait_ms': planner_ms + timing_ms, 'forbidden samples': inside})
            print(f'  {kind} {label}: {result["outcome"]}, waited '
                  f'{results[-1]["wait_ms"]:.1f} ms', file=sys.stderr, flush=True)
        log_dir = rig.log_dir
    print_table(args, results, keeping, log_dir)
    return results


def print_table(args, results, keeping, log_dir) -> None:
    print(f'\nPlanning per goal through ROS on {args.robot} '
          f'({"two busy loops beside it" if args.load else "idle"}); {keeping}; node logs in '
          f'{log_dir}\n')
    print('| goals | reached | wait median ms | wait p95 ms | wait max ms | planner round trip '
          'median / p95 ms | timing median / p95 ms | samples in forbidden space |')
    print('|---|---|---|---|---|---|---|---|')
    kinds = list(dict.fromkeys(r['kind'] for r in results)) + ['all']

    def values(rows, key):
        found = np.array([r[key] for r in rows if r['outcome'] == 'goal_reached'])
        return found[np.isfinite(found)]

    def stats(found, *statistics):
        return [f'{f(found):.1f}' if len(found) else '-' for f in statistics]
    median, p95 = np.median, (lambda found: np.percentile(found, 95))
    for kind in kinds:
        rows = [r for r in results if kind in ('all', r['kind'])]
        reached = sum(r['outcome'] == 'goal_reached' for r in rows)
        print(f'| {kind} | {reached} of {len(rows)} | '
              f'{" | ".join(stats(values(rows, "wait_ms"), median, p95, np.max))} | '
              f'{" / ".join(stats(values(rows, "planner_ms"), median, p95))} | '
              f'{" / ".join(stats(values(rows, "timing_ms"), median, p95))} | '
              f'{sum(r["forbidden samples"] for r in rows)} |')
    for r in results:
        if r['outcome'] != 'goal_reached':
            print(f'not reached: {r["kind"]} {r["label"]}: {r["outcome"]}')


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--robot', default='frc_robot.yaml',
                        help="a parameter file in the package's config, or 'default'")
    parser.add_argument('--load', action='store_true', help='two busy loops throughout')
    parser.add_argument('--points', type=int, default=12, help='free points, each from a preset')
    parser.add_argument('--laps', type=int, default=1, help="times round the presets' circuit")
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--domain', type=int, help='a ROS domain reserved for you')
    run(parser.parse_args())


if __name__ == '__main__':
    main()
