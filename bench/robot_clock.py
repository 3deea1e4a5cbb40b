"""The arm on the robot's clock: commands applied on arrival against the robot's loop at
phases spread over its period (issue 38).

Each row is one way of running: the reference row applies each command the instant it
arrives (the sim's ``command_timing: on_arrival``); the others read the sensors and apply the
latest command only at the robot loop's instants, at ``robot_loop_phase_s`` past each whole
period of the clock. Per row:

- the hold at (0.0, 1.75), the issue's, and at the start (1.5708, −1.5708): over 2 s, the
  fastest joint speed (rad/s) and the largest swing (deg) on the true state (bars: 0.1 rad/s,
  0.5 deg);
- the moves of the suite (``bench_trajectory.SUITE``): each move's time from its goal until
  it came within 1° of where it came to rest and stayed (``bench_ros.settled_s``), over the
  minimum under the electrical limits (``minimum_time.suite_minimums``): worst and median
  (bars: 1.10x idle, 1.25x with two busy processes); beside it, on the robot loop, the same
  time counted from the loop's first instant at or after the goal (the soonest any command
  could act: the wait before it is the robot's loop, the rest ours); through ROS also how
  long after the goal the first moving command reached the robot, and how long it waited
  there for the loop's next instant (``robot_clock_ros.Start``); and the lowest point of
  either link over all moves from their goals (mm; below 0 is in the floor). In one process the arm
  starts at 0 V and drops until the controller's first command acts: not part of a move.

In one process (default), deterministic: ``RobotLoop`` (the core and the plant on 1 ms steps;
the controller ticks at whole periods and its command arrives 4 ms later; the planner plans
in the core's step). Through ROS (``--ros``): the three nodes as ``bench_ros`` starts them,
the sim's ``command_timing`` and ``robot_loop_phase_s`` set per row (the controller ticks at
a phase of its own, so the phase between the two varies from run to run).

    python bench/robot_clock.py                       # in one process: every mode, phase
    python bench/robot_clock.py --ros [--load]        # through ROS (minutes)
    python bench/robot_clock.py --phases 0,10 --moves 0,4
    python bench/robot_clock.py --write-docs          # keep the table in docs/benchmarks
"""

import argparse
import dataclasses
import math
from pathlib import Path
import statistics
import sys

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE), str(HERE.parent)]

from bench_trajectory import SUITE  # noqa: E402
import docs_table  # noqa: E402
import minimum_time  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.control.robot_loop import RobotLoop  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402

HOLDS = ((0.0, 1.75), (1.5708, -1.5708))
HOLD_S, HOLD_AFTER_S = 2.0, 1.0          # measured over 2 s after 1 s held
PHASES_MS = (0, 5, 10, 15, 19)
SETTLED_RAD = math.radians(1.0)
REST_FOR_S = 0.3
MOVE_TIMEOUT_S = 6.0


@dataclasses.dataclass
class Row:
    label: str
    timing: str                      # the sim's command_timing
    phase_ms: float
    mode: str                        # the controller's command_mode (or the rig's mode)
    hold_speed: float = math.nan
    hold_swing_deg: float = math.nan
    ratios: list = dataclasses.field(default_factory=list)
    # On the robot loop: each move's time counted from the first loop instant at or after
    # its goal, over the minimum (the wait for the loop is the robot's, not ours).
    loop_ratios: list = dataclasses.field(default_factory=list)
    to_robot_ms: list = dataclasses.field(default_factory=list)   # goal -> first move command
    loop_wait_ms: list = dataclasses.field(default_factory=list)  # ... -> the instant it acts
    names: list = dataclasses.field(default_factory=list)      # the move of each ratio
    lowest_mm: float = math.inf
    failed: list = dataclasses.field(default_factory=list)


def settled_s(times, q, start_s: float) -> float:
    """From ``start_s`` until within SETTLED_RAD of the rest it came to (its mean over the
    last REST_FOR_S), for good; NaN when it never came to rest."""
    times, q = np.asarray(times), np.asarray(q)
    last = times >= times[-1] - REST_FOR_S
    rest = q[last].mean(axis=0)
    if np.max(np.ptp(q[last], axis=0)) > SETTLED_RAD:
        return math.nan
    outside = np.flatnonzero(np.any(np.abs(q - rest) > SETTLED_RAD, axis=1))
    return max(float(times[outside[-1] + 1] if len(outside) else times[0]) - start_s, 0.0)


def start_configuration(arm, start_xy):
    """The suite's start: the first free elbow branch (``bench_trajectory``), to 0.01 rad."""
    kinematics, forbidden = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m), \
        ForbiddenSpace(arm)
    for q in reversed(kinematics.inverse(*start_xy)):
        q = np.array([forbidden.to_joint_range(q[k], k) or q[k] for k in range(2)])
        if forbidden.is_free(q):
            return np.round(q, 2)
    raise ValueError(f'the start {start_xy} is forbidden on both branches')


def phase_s(row) -> float:
    return row.phase_ms / 1000.0 if math.isfinite(row.phase_ms) else 0.0


def hold_in_process(arm, controller_config, row, q):
    loop = RobotLoop(arm, controller_config, start=q, mode=row.mode, seed=1,
                     phase_s=phase_s(row), robot_loop=row.timing == 'robot_loop')
    loop.run(HOLD_AFTER_S + HOLD_S)
    states = np.array([s for t, s in loop.history if t > HOLD_AFTER_S])
    return float(np.max(np.abs(states[:, 2:]))), float(np.degrees(np.max(np.ptp(
        states[:, :2], axis=0))))


def move_in_process(arm, controller_config, planner, row, start_q, goal_xy, seed):
    loop = RobotLoop(arm, controller_config, planner, start=start_q, mode=row.mode, seed=seed,
                     phase_s=phase_s(row), robot_loop=row.timing == 'robot_loop')
    loop.run(0.5)
    goal_s = loop.now_s
    loop.lowest_m = math.inf         # the move's: the start drops from 0 V until taken hold of
    loop.submit_goal(*goal_xy)
    loop.run(MOVE_TIMEOUT_S)
    times = np.array([t for t, _ in loop.history])
    q = np.array([s[:2] for _, s in loop.history])
    after = times >= goal_s
    return settled_s(times[after], q[after], goal_s), 1000.0 * loop.lowest_m, \
        first_instant_s(loop, goal_s) - goal_s


def first_instant_s(loop, after_s: float) -> float:
    """The first of ``loop``'s instants (``phase_ms + k·period_ms``) at or after ``after_s``
    (on the robot loop; else ``after_s``: a command acts on arrival)."""
    if not loop.robot_loop:
        return after_s
    periods = math.ceil((round(1000.0 * after_s) - loop.phase_ms) / loop.period_ms)
    return (loop.phase_ms + periods * loop.period_ms) / 1000.0


def rows_for(phases_ms, modes) -> list[Row]:
    rows = [Row('on arrival (reference)', 'on_arrival', math.nan, 'volts')]
    for mode in modes:
        rows += [Row(f'robot loop, {mode}', 'robot_loop', p, mode) for p in phases_ms]
    return rows


def run_in_process(args, rows, moves):
    arm, controller_config = config.load('controller')
    planner = Planner(arm, config.load('planner')[1])
    minimums = minimum_time.suite_minimums(arm, controller_config, moves, minimum_time.CACHE)
    for row in rows:
        speeds, swings = zip(*(hold_in_process(arm, controller_config, row, q) for q in HOLDS))
        row.hold_speed, row.hold_swing_deg = max(speeds), max(swings)
        for k, (name, start_q, goal_xy) in enumerate(moves):
            move_s, lowest, wait_s = move_in_process(arm, controller_config, planner, row,
                                                     start_q, goal_xy, k)
            row.ratios.append(move_s / minimums[name]['min_s'])
            if row.timing == 'robot_loop':
                row.loop_ratios.append((move_s - wait_s) / minimums[name]['min_s'])
            row.names.append(name)
            row.lowest_mm = min(row.lowest_mm, lowest)
            if not math.isfinite(move_s):
                row.failed.append(name)
        print(f'  {row.label} {fmt(row.phase_ms, ".0f")} ms: {summary(row)}', file=sys.stderr,
              flush=True)


def fmt(value, spec='.2f') -> str:
    return '-' if value is None or not math.isfinite(value) else format(value, spec)


def summary(row) -> str:
    finite = [r for r in row.ratios if math.isfinite(r)]
    return (f'hold {row.hold_speed:.3f} rad/s, {row.hold_swing_deg:.2f} deg; moves worst '
            f'{fmt(max(finite, default=math.nan))}, median '
            f'{fmt(statistics.median(finite) if finite else math.nan)}')


def ratios_cells(ratios, bar: float) -> str:
    """'worst | median | k of n' of ``ratios`` ('-' where there are none)."""
    if not ratios:
        return '- | - | -'
    finite = [r for r in ratios if math.isfinite(r)]
    return (f'{fmt(max(finite, default=math.nan))} | '
            f'{fmt(statistics.median(finite) if finite else math.nan)} | '
            f'{sum(r <= bar for r in finite)} of {len(ratios)}')


def spread_ms(values) -> str:
    """'median / largest' (ms) of the finite ``values``, or '-'."""
    finite = [v for v in values if math.isfinite(v)]
    return f'{statistics.median(finite):.1f} / {max(finite):.1f}' if finite else '-'


def table(rows, bar: float) -> str:
    lines = ['| sim | phase ms | controller sends | hold: fastest joint rad/s | '
             'hold: swing deg | moves / minimum, from the goal: worst | median | within '
             f'{bar:.2f}x | from the first loop instant: worst | median | within {bar:.2f}x | '
             'goal → first moving command at the robot ms: median / max | its wait for the '
             'loop ms: median / max | lowest mm |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|']
    for row in rows:
        lines.append(
            f'| {row.timing} | {fmt(row.phase_ms, ".0f")} | {row.mode} | '
            f'{row.hold_speed:.3f} | {row.hold_swing_deg:.2f} | '
            f'{ratios_cells(row.ratios, bar)} | {ratios_cells(row.loop_ratios, bar)} | '
            f'{spread_ms(row.to_robot_ms)} | {spread_ms(row.loop_wait_ms)} | '
            f'{row.lowest_mm:.0f} |')
    beyond = []
    for row in rows:
        from_loop = row.loop_ratios or [math.nan] * len(row.ratios)
        beyond += [f'{row.timing} {fmt(row.phase_ms, ".0f")} ms {row.mode}: {name} '
                   f'({ratio:.2f}; from the first loop instant {fmt(loop)})'
                   for name, ratio, loop in zip(row.names, row.ratios, from_loop)
                   if not ratio <= bar]
    if beyond:
        lines.append(f'\nBeyond {bar:.2f}x from the goal: {"; ".join(beyond)}.')
    return '\n'.join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--ros', action='store_true', help='through ROS, not in one process')
    parser.add_argument('--load', action='store_true', help='(--ros) two busy loops beside')
    parser.add_argument('--phases', type=lambda text: [float(p) for p in text.split(',')],
                        default=list(PHASES_MS), help='robot loop phases (ms), e.g. 0,10')
    parser.add_argument('--modes', type=lambda text: text.split(','),
                        default=['volts', 'profile'],
                        help='what the controller sends on the robot loop: volts, profile '
                             '(in one process also volts_at_instant)')
    parser.add_argument('--moves', type=lambda text: [int(i) for i in text.split(',')],
                        help='indices into the suite, e.g. 4,5')
    parser.add_argument('--repeats', type=int, default=1, help='(--ros) runs of each move')
    parser.add_argument('--domain', type=int, help='(--ros) a ROS domain reserved for you')
    parser.add_argument('--write-docs', action='store_true',
                        help='keep the table in docs/benchmarks/robot_clock[_ros].md')
    args = parser.parse_args()
    arm = config.load('controller')[0]
    suite = [SUITE[i] for i in args.moves] if args.moves else SUITE
    moves = [(name, start_configuration(arm, start), goal) for name, start, goal in suite]
    rows = rows_for(args.phases, args.modes)
    if args.ros:
        import robot_clock_ros                      # ROS only when asked for
        where = robot_clock_ros.run(args, rows, suite)
    else:
        run_in_process(args, rows, moves)
        where = 'in one process (RobotLoop: deterministic, 1 ms physics, commands 4 ms late)'
    bar = 1.25 if args.load else 1.10
    text = f'{where}; {len(moves)} moves of the suite.\n\n{table(rows, bar)}\n'
    print('\n' + text)
    if args.write_docs:
        name = 'robot_clock_ros' + ('_load' if args.load else '') if args.ros else 'robot_clock'
        command = 'python bench/robot_clock.py ' + ' '.join(sys.argv[1:])
        print(docs_table.write(name, "The arm on the robot's clock", command, text))


if __name__ == '__main__':
    main()
