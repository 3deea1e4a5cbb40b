"""Moves as users get them: the real nodes over ROS, against the same controller in one
process and against the minimum time (issue 18).

sim, planner and controller run as separate processes on a ROS domain of their own, as the
process tests start them (``test/rigs/arm_rig.py``). For each move of the suite
(``bench_trajectory.SUITE``) a goal on ``/goal_point`` takes the arm to the move's start, as
a user's would, and the arm comes to rest there; then the move's goal is published. The move
takes from that publication until the arm came, for good, within 1° on both joints of where
it came to rest, on ``/sim/ground_truth`` (the sim's stamps; the publication is stamped on
the same clock). Beside it, per move, from the configuration the arm started from (to
0.01 rad):

- in one process: the same controller on the same plant in simulated time, planning after
  the CPU time it costs (``in_process``), timed the same way;
- the minimum: the least time over the goal's elbow branches under the limits the sim
  imposes (current limits, the battery's sag, brownout, the floor)
  (``minimum_time.suite_minimums``, cached in ``bench/.minimum_cache.json``);
- where the time through ROS went, from the controller's ``goal_reached`` event: the
  planner's round trip, the timing in the controller's worker, the hand-over, waiting to
  start, the trajectory, and the rest (the goal's delivery, tracking and settling);
- the lowest point of either link (mm; below 0 is in the floor);
- the worst tracking error: the largest gap on either joint between the true arm and the
  controller's setpoint (``/controller/setpoint``) for the same instant, over the move's runs;
- kept: the runs that started on a fine trajectory the controller kept: from an earlier
  goal along the same path (each move's runs after its first, from the same start), or
  between presets, which it has kept before the first move (as on a robot that has been on
  a few seconds: the bench waits for them). The ratios are given apart for the runs that
  started on a kept trajectory and those that did not.

    python bench/bench_ros.py                  # the suite, idle (a few minutes)
    python bench/bench_ros.py --load           # with two busy loops beside it
    python bench/bench_ros.py --sim-speed 5    # in simulated time, 5x real time
    python bench/bench_ros.py --moves 4,5 --repeats 3
    python bench/bench_ros.py --random 8 --seed 1  # 8 moves drawn at random instead
    python bench/bench_ros.py --param feedback_voltage_reserve:=0.5
    python bench/bench_ros.py --param planning_priority:=0 --planner-param realtime_priority:=0

Needs the package built and sourced. Not a test: it prints a table and asserts nothing.
"""

import argparse
from contextlib import contextmanager, nullcontext
import dataclasses
import math
from pathlib import Path
import re
import statistics
import sys
import tempfile
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE)]

from arm_rig import ArmRig  # noqa: E402
from bench_trajectory import SUITE  # noqa: E402
import busy  # noqa: E402
from geometry_msgs.msg import PointStamped  # noqa: E402
from in_process import PlanHandOff, simulate, TimedCore  # noqa: E402
import minimum_time  # noqa: E402
import numpy as np  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from ros_harness import Probe, ros_domain  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.control.controller import ArmController  # noqa: E402
from arm_control.control.events import parse_event  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402
from arm_control.plans.cache import preset_pairs  # noqa: E402
from arm_control.plans.goals import GoalValidator  # noqa: E402

SETTLED_RAD = math.radians(1.0)     # within this of where the arm came to rest
REST_FOR_S = 0.3                    # ... for this long
# At rest: both joints within this band over REST_FOR_S. A held arm is never still: the
# feedback on noisy sensors moves it 0.1-0.4 deg (in one process 0.1 deg over 0.3 s).
REST_BAND_RAD = SETTLED_RAD / 2
MOVE_TIMEOUT_S = 10.0
LOAD_BUDGET_S = 3600.0
# The controller's goal_reached sentence: '... (error ...; planner round trip 18.9 ms, ...)'.
PART = re.compile(r'([a-z][a-z -]*?) (-?[\d.]+) ms')


def settled_s(times, q, start_s: float) -> float:
    """How long after ``start_s`` the arm came within SETTLED_RAD of where it came to rest
    (its mean over the last REST_FOR_S) and stayed; NaN when it never came to rest."""
    times, q = np.asarray(times, float), np.asarray(q, float)
    last = times >= times[-1] - REST_FOR_S
    if len(times) < 3 or times[-1] - start_s < REST_FOR_S:
        return math.nan
    rest = q[last].mean(axis=0)
    if np.max(np.ptp(q[last], axis=0)) > REST_BAND_RAD:      # still moving at the end
        print(f'  not at rest at the end: {np.degrees(np.ptp(q[last], axis=0))} deg over '
              f'{times[-1] - times[last][0]:.2f} s', file=sys.stderr)
        return math.nan
    outside = np.flatnonzero(np.any(np.abs(q - rest) > SETTLED_RAD, axis=1))
    settled = times[outside[-1] + 1] if len(outside) else times[0]
    return max(float(settled) - start_s, 0.0)


def breakdown_ms(sentence: str) -> dict:
    """{'planner round trip': ms, 'timing': ms, ...} from a goal_reached sentence."""
    return {name.strip(): float(value) for name, value in
            PART.findall(sentence.split(';', 1)[1] if ';' in sentence else '')}


def lowest_mm(arm, q) -> float:
    q = np.atleast_2d(q)
    elbow_y = arm.shoulder.length_m * np.sin(q[:, 0])
    tool_y = elbow_y + arm.elbow.length_m * np.sin(q[:, 0] + q[:, 1])
    return 1000.0 * float(np.min(np.minimum(elbow_y, tool_y)))


class RosMoves:
    """The nodes, and the means to run one move through them."""

    def __init__(self, rig: ArmRig, simulated: bool):
        self.rig = rig
        node = rig.probe.node
        if simulated:
            node.set_parameters([Parameter('use_sim_time', value=True)])
        self.truth = []                 # (sim stamp s, shoulder, elbow)
        self.setpoints = []             # (when the command acts s, shoulder, elbow)
        node.create_subscription(JointState, '/sim/ground_truth',
                                 lambda msg: self.truth.append(angles(msg)), 1000)
        node.create_subscription(JointState, '/controller/setpoint',
                                 lambda msg: self.setpoints.append(angles(msg)), 1000)

    def go_to(self, xy):
        """The arm taken to ``xy`` by a goal, at rest: where it rests (rad), or None."""
        result = self.move(xy)
        if result['outcome'] != 'goal_reached' or not math.isfinite(result['ros_s']):
            print(f'  could not take the arm to {xy}: {result["outcome"]} '
                  f'{result["sentence"][:120]}', file=sys.stderr, flush=True)
            return None
        return result['q'][-1]

    def move(self, goal_xy) -> dict:
        """Publish the goal, wait for the arm to come to rest; the move's figures."""
        rig = self.rig
        began = time.monotonic()
        del self.truth[:]
        del self.setpoints[:]
        message = PointStamped()
        message.header.frame_id = 'arm_base'
        message.header.stamp = rig.probe.node.get_clock().now().to_msg()
        published_s = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
        message.point.x, message.point.y = float(goal_xy[0]), float(goal_xy[1])
        rig.goal_pub.publish(message)
        outcome = ('goal_reached', 'goal_failed', 'goal_rejected', 'estop', 'control_failed')
        rig.spin_until(lambda: any(parse_event(e)[0] in outcome
                                   for e in rig.events_heard(began)), MOVE_TIMEOUT_S)

        def at_rest():          # over REST_FOR_S of samples since the goal, whatever their rate
            truth, first = self.truth, len(self.truth) - 1
            if truth[-1][0] < published_s + REST_FOR_S:
                return False
            while first > 0 and truth[first - 1][0] >= truth[-1][0] - REST_FOR_S:
                first -= 1
            q = np.array([row[1:] for row in truth[first:]])
            return truth[-1][0] - truth[first][0] >= 0.9 * REST_FOR_S \
                and np.max(np.ptp(q, axis=0)) < REST_BAND_RAD
        rig.spin_until(lambda: len(self.truth) > 5 and at_rest(), 3.0)
        rig.spin_for(REST_FOR_S)
        events = [e for e in rig.events_heard(began) if parse_event(e)[0] in outcome]
        rows = np.array([row for row in self.truth if row[0] >= published_s - 0.05])
        kind, _, sentence = parse_event(events[0]) if events else ('none', '', '')
        return {'outcome': kind, 'sentence': sentence, 'published_s': published_s,
                'ros_s': settled_s(rows[:, 0], rows[:, 1:], published_s) if len(rows) else
                math.nan,
                'q': rows[:, 1:] if len(rows) else np.zeros((0, 2)),
                'tracking_deg': tracking_deg(rows, np.array(self.setpoints))}


def angles(msg: JointState) -> tuple:
    """(stamp s, shoulder rad, elbow rad) of a JointState."""
    named = dict(zip(msg.name, msg.position))
    return (msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec,
            named.get('shoulder', math.nan), named.get('elbow', math.nan))


def tracking_deg(truth, setpoints) -> float:
    """The largest gap on either joint between the true arm and the controller's setpoint
    for the same instant (deg): the setpoints, stamped with when their command acts,
    interpolated at the sim's stamps."""
    if len(truth) == 0 or len(setpoints) < 2:
        return math.nan
    inside = (truth[:, 0] >= setpoints[0, 0]) & (truth[:, 0] <= setpoints[-1, 0])
    gaps = [truth[inside, 1 + k] - np.interp(truth[inside, 0], setpoints[:, 0],
                                             setpoints[:, 1 + k]) for k in range(2)]
    wrapped = (np.abs(np.array(gaps)) + math.pi) % (2 * math.pi) - math.pi
    return math.degrees(float(np.max(np.abs(wrapped)))) if inside.any() else math.nan


def in_process_s(arm, controller_config, planner, start_q, goal_xy, seed) -> float:
    """The same move in one process, timed as through ROS."""
    core = ArmController(arm, controller_config)
    record = simulate(arm, controller_config, TimedCore(core),
                      lambda t: core.submit_goal(t, *goal_xy), start_q, seed,
                      PlanHandOff(core, planner))
    times, states = np.array(record['time']), np.array(record['state'])
    return settled_s(times, states[:, :2], 0.0)


def fmt(value, spec='.3f') -> str:
    return '-' if value is None or not math.isfinite(value) else format(value, spec)


@contextmanager
def nodes(name: str, node_args: dict, load: bool, domain=None):
    """The rig (``ArmRig``) of the three nodes on a ROS domain of their own (``domain``, else
    a free one), two busy loops beside them under ``load``; the caller starts the nodes, and
    they are closed on the way out."""
    loops = busy.start(2, LOAD_BUDGET_S) if load else []
    try:
        with ros_domain() if domain is None else nullcontext(domain) as domain:
            probe = Probe(domain, name)
            rig = ArmRig(domain, probe, Path(tempfile.mkdtemp(prefix=f'arm_{name}_')),
                         node_args)
            try:
                yield rig
            finally:
                rig.close()
                probe.close()
    finally:
        busy.stop(loops)


def run(args) -> list:
    arm, controller_config = config.load('controller')
    overrides = dict(param.split(':=', 1) for param in args.param)
    controller_config = dataclasses.replace(controller_config, **{
        name: type(getattr(controller_config, name))(float(value))
        for name, value in overrides.items()})
    suite = random_moves(arm, args.random, args.seed) if args.random else SUITE
    moves = [suite[i] for i in args.moves] if args.moves else suite
    node_args = {'controller': tuple(arg for param in args.param for arg in ('-p', param)),
                 'planner': tuple(arg for param in args.planner_param for arg in ('-p', param))}
    if args.sim_speed:
        node_args = {'sim': ('-p', f'sim_time_factor:={args.sim_speed:g}'),
                     'planner': node_args['planner'] + ('-p', 'use_sim_time:=true'),
                     'controller': node_args['controller'] + ('-p', 'use_sim_time:=true')}
    rows = []
    with nodes('bench_ros', node_args, args.load, args.domain) as rig:
        ros = RosMoves(rig, bool(args.sim_speed))
        clock = []                              # (wall s, sim s) of each /clock
        if args.sim_speed:
            rig.probe.node.create_subscription(Clock, '/clock', lambda m: clock.append(
                (time.monotonic(), m.clock.sec + 1e-9 * m.clock.nanosec)), 100)
        rig.start_all()
        rig.ready(90.0)
        args.keeping = wait_for_presets_kept(rig, arm)
        del clock[:]
        for name, start_xy, goal_xy in moves:
            for _ in range(args.repeats):
                start_q = ros.go_to(start_xy)
                result = ros.move(goal_xy) if start_q is not None else \
                    {'outcome': 'no start', 'sentence': '', 'ros_s': math.nan}
                result.update(name=name, goal_xy=goal_xy, start_q=start_q)
                rows.append(result)
                print(f'  {name}: {result["outcome"]}, {fmt(result["ros_s"])} s through ROS',
                      file=sys.stderr, flush=True)
        log_dir = rig.log_dir
        if len(clock) > 1:      # in step with the controller: as fast as it answers
            (wall0, sim0), (wall1, sim1) = clock[0], clock[-1]
            args.clock_rate = (sim1 - sim0) / (wall1 - wall0)
            sim = rig.node_diagnostics('/sim')
            args.late_commands = sim[-1]['commands late for their period'] if sim else '?'
    # After the nodes: IPOPT's threads and this process's planning would disturb them.
    planner = Planner(arm, config.load('planner')[1])
    # A warm-up, as the nodes' worker does before it is ready: the first timing in a process
    # loads the compiled kernels (0.1-0.2 s), which the first move would wait for.
    first = next(row for row in rows if row['start_q'] is not None)
    in_process_s(arm, controller_config, planner, np.round(first['start_q'], 2),
                 first['goal_xy'], 0)
    for row in rows:
        if row['start_q'] is None:
            row['minimum_s'] = row['local_s'] = math.nan
            continue
        start_q = np.round(row['start_q'], 2)
        index = suite.index(next(m for m in suite if m[0] == row['name']))
        row['local_s'] = in_process_s(arm, controller_config, planner, start_q,
                                      row['goal_xy'], index)
        row['minimum_s'] = minimum_time.suite_minimums(
            arm, controller_config, [(row['name'], start_q, row['goal_xy'])],
            minimum_time.CACHE)[row['name']]['min_s']
    print_table(arm, rows, args, log_dir)
    return rows


def wait_for_presets_kept(rig, arm, timeout_s=120.0) -> str:
    """Wait until the controller has the trajectories between presets kept, as on a robot
    that has been on for a little while; what it had, and when, since it was ready."""
    began = time.monotonic()
    pairs = len(preset_pairs(GoalValidator(arm)))

    def kept():
        values = rig.node_diagnostics('/controller')
        return int(values[-1].get('trajectories kept', 0)) if values else 0
    rig.spin_until(lambda: kept() >= pairs, timeout_s)
    return (f'{min(kept(), pairs)} of the {pairs} trajectories between presets were kept '
            f'{time.monotonic() - began:.1f} s after the controller was ready')


def print_table(arm, rows, args, log_dir) -> None:
    conditions = ', '.join(filter(None, [
        'two busy loops beside it' if args.load else 'idle',
        f'simulated time at {args.sim_speed:g}x (its clock ran at '
        f'{getattr(args, "clock_rate", math.nan):.2f}x, and '
        f'{getattr(args, "late_commands", "?")} commands came late for their period)'
        if args.sim_speed else 'real time',
        f'{args.repeats} runs a move (the median)' if args.repeats > 1 else '',
        ', '.join(args.param), ', '.join(f'planner {p}' for p in args.planner_param)]))
    print(f'\nMoves through ROS ({conditions}); node logs in {log_dir}; '
          f'{getattr(args, "keeping", "")}\n')
    print('| move | ROS s | one process s | minimum s | ROS / min | one process / min | '
          'planner round trip ms | timing ms | hand-over + waiting ms | trajectory s | '
          'delivery, tracking, settling ms | lowest mm | worst tracking error deg | kept |')
    print('|---|---|---|---|---|---|---|---|---|---|---|---|---|---|')
    ratios, planning, contact = {False: [], True: []}, [], 0
    for name in dict.fromkeys(row['name'] for row in rows):
        runs = [row for row in rows if row['name'] == name and 'q' in row]
        if not runs:
            print(f'| {name} | no start | | | | | | | | | | | | |')
            continue
        ros_s = statistics.median(row['ros_s'] for row in runs)
        parts = [breakdown_ms(row['sentence']) for row in runs
                 if row['outcome'] == 'goal_reached']

        def part(key):
            values = [p.get(key, math.nan) for p in parts]
            return statistics.median(values) if values else math.nan
        for p in parts:                 # a kept trajectory's lookup is its timing
            p.setdefault('timing', p.get('kept trajectory', math.nan))
        known = sum(part(k) for k in ('planner round trip', 'timing', 'hand-over',
                                      'waiting to start', 'trajectory'))
        minimum_s = statistics.median(row['minimum_s'] for row in runs)
        local_s = statistics.median(row['local_s'] for row in runs)
        lowest = min(lowest_mm(arm, row['q']) for row in runs if len(row['q']))
        contact += lowest < 0.0
        tracked = [row['tracking_deg'] for row in runs if math.isfinite(row['tracking_deg'])]
        tracking = max(tracked, default=math.nan)
        for row in runs:
            ratios[was_kept(row)].append(row['ros_s'] / row['minimum_s'])
        planning += [p.get('planner round trip', math.nan) + p.get('timing', math.nan)
                     for p in parts]
        print(f'| {name} | {fmt(ros_s)} | {fmt(local_s)} | {fmt(minimum_s)} | '
              f'{fmt(ros_s / minimum_s, ".2f")} | {fmt(local_s / minimum_s, ".2f")} | '
              f'{fmt(part("planner round trip"), ".0f")} | {fmt(part("timing"), ".0f")} | '
              f'{fmt(part("hand-over") + part("waiting to start"), ".0f")} | '
              f'{fmt(part("trajectory") / 1000.0)} | {fmt(1000.0 * ros_s - known, ".0f")} | '
              f'{lowest:.0f} | {fmt(tracking, ".2f")} | '
              f'{sum(was_kept(row) for row in runs)}/{len(runs)} |')
    bar = 1.25 if args.load else 1.10
    print()
    everything = ratios[False] + ratios[True]
    for runs, label in ((ratios[False], 'timed when asked'),
                        (ratios[True], 'on a kept trajectory'), (everything, 'every run')):
        finite = [r for r in runs if math.isfinite(r)]
        if finite:
            print(f'ROS / minimum, {label}: median {statistics.median(finite):.2f}, worst '
                  f'{max(finite):.2f}; within {bar:.2f}x: {sum(r <= bar for r in finite)} of '
                  f'{len(runs)} runs.')
    beyond = [f'{row["name"].split(":")[0]} run {k + 1} from '
              f'{np.round(row["start_q"], 2).tolist()} ({row["ros_s"] / row["minimum_s"]:.2f})'
              for name in dict.fromkeys(row['name'] for row in rows)
              for k, row in enumerate(r for r in rows if r['name'] == name)
              if row['ros_s'] / row['minimum_s'] > bar]
    if beyond:
        print(f'Beyond {bar:.2f}x: {"; ".join(beyond)}.')
    print(f'Floor contact on {contact} moves.')
    planned = [p for p in planning if math.isfinite(p)]
    if planned:
        print(f'Planning per goal through ROS (planner round trip + timing): median '
              f'{statistics.median(planned):.0f} ms, p95 {np.percentile(planned, 95):.0f} ms.')


def random_moves(arm, count: int, seed: int) -> list:
    """``count`` moves no one tuned for, as (name, start_xy, goal_xy): points drawn evenly
    over the reachable annulus above the floor that are goals the controller accepts; every
    other move a short hop (goal 0.1-0.4 m from the start), where a goal's fixed costs weigh
    most."""
    rng = np.random.default_rng(seed)
    validator = GoalValidator(arm)
    inner, outer = validator.kinematics.reach_m

    def goal_point(near=None):
        while True:
            if near is None:
                radius = math.sqrt(rng.uniform(inner ** 2, outer ** 2))
                angle = rng.uniform(0.0, math.pi)
                x, y = radius * math.cos(angle), radius * math.sin(angle)
            else:
                step, heading = rng.uniform(0.1, 0.4), rng.uniform(-math.pi, math.pi)
                x, y = near[0] + step * math.cos(heading), near[1] + step * math.sin(heading)
            x, y = round(x, 2), round(y, 2)
            if validator.check(x, y).ok:
                return x, y
    moves = []
    for k in range(count):
        start = goal_point()
        goal = goal_point(start if k % 2 else None)
        moves.append((f'random {k}: {start} -> {goal}', start, goal))
    return moves


def was_kept(row) -> bool:
    """The move started on a fine trajectory the controller kept (``KeptTrajectories``)."""
    return 'kept trajectory' in breakdown_ms(row.get('sentence', ''))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--load', action='store_true', help='two busy loops throughout')
    parser.add_argument('--sim-speed', type=float, default=0.0,
                        help='run in simulated time, this many times real time')
    parser.add_argument('--moves', type=lambda text: [int(i) for i in text.split(',')],
                        help='indices into the suite, e.g. 4,5')
    parser.add_argument('--random', type=int, default=0,
                        help='this many moves drawn at random (seeded) instead of the suite')
    parser.add_argument('--seed', type=int, default=0, help='the seed of --random')
    parser.add_argument('--repeats', type=int, default=1, help='runs of each move')
    parser.add_argument('--domain', type=int, help='a ROS domain reserved for you')
    parser.add_argument('--param', action='append', default=[],
                        help="a numeric controller parameter, 'name:=value' (repeatable), "
                             'for the node and the one-process run alike')
    parser.add_argument('--planner-param', action='append', default=[],
                        help="a planner parameter, 'name:=value' (repeatable)")
    run(parser.parse_args())


if __name__ == '__main__':
    main()
