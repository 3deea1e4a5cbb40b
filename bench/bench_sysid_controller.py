"""The controller on the identified file against the true and the default file (issue 40):
is it as fast and as precise on the file ``sysid`` writes as on the arm's true parameters?

For each arm (bench/arms/*.yaml and the demo arm, each layered over arm.yaml): the file
``sysid`` writes is identified in-process (``bench_sysid_arms.identify``: the node's drive on
the true arm, seeded as that bench's runs). Then the controller and the planner run the
benchmark suite (``bench_trajectory.SUITE``) with each file -- true, identified, default
(arm.yaml alone) -- on the TRUE arm, in one process on the robot's clock (``RobotLoop`` as
``robot_clock.py`` runs it: profiles played at the robot loop's instants at phase 0,
commands 4 ms late, physics on 1 ms steps; deterministic). Per move and file:

- time: from the goal, given once the arm is at rest at the start (``hold_until_at_rest``),
  until within 1 deg of where the arm came to rest, for good (``robot_clock.settled_s``),
  over the minimum under the electrical limits on the true arm
  (``minimum_time.suite_minimums``; ``--no-minimum``: seconds); 'refused' when the goal
  failed (no trajectory within the limits of the arm the file describes);
- tracking: the largest distance of the true arm from the controller's setpoint at its
  ticks, from the goal until settled (deg, the larger joint), and the final error: how far
  the arm came to rest from the goal's configuration (deg);
- the lowest point of either link from the goal on (mm above the floor's level).

    python bench/bench_sysid_controller.py [--runs 1] [--arms bench/arms/a.yaml ...]
                                           [--moves 0,4] [--no-minimum] [--write-docs]
"""

import argparse
import dataclasses
import glob
import math
from pathlib import Path
import statistics
import sys

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent)]

from bench_sysid import CONFIG, layered  # noqa: E402
from bench_sysid_arms import identify  # noqa: E402
from bench_trajectory import SUITE  # noqa: E402
import docs_table  # noqa: E402
import minimum_time  # noqa: E402
import numpy as np  # noqa: E402
from robot_clock import settled_s, start_configuration  # noqa: E402

from arm_control import config, parameters  # noqa: E402
from arm_control.control.robot_loop import RobotLoop  # noqa: E402
from arm_control.model.plant import ArmPlant  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402
from arm_control.sysid.settings import SysIdConfig  # noqa: E402

HOLD_BEFORE_S = 0.5
AT_REST_DEG = 0.05               # the start: the arm moved less than this over REST_FOR_S ...
REST_FOR_S = 0.3
HOLD_AT_MOST_S = 3.0             # ... held at most this long for it
MOVE_TIMEOUT_S = 6.0
FILES = ('true', 'identified', 'default')


@dataclasses.dataclass
class Move:
    time_s: float                    # NaN: not settled, or refused
    tracking_deg: float
    final_deg: float
    lowest_mm: float
    refused: bool = False            # the goal failed: no trajectory within the arm's limits
    start_rest_deg: float = 0.0      # how far the arm moved over REST_FOR_S before the goal


def hold_until_at_rest(loop) -> float:
    """Hold at the start until the arm moved less than AT_REST_DEG over REST_FOR_S (in one
    process it starts at 0 V and drops until the first command acts): a move is timed from
    an arm at rest. Returns that movement (deg)."""
    loop.run(HOLD_BEFORE_S)
    window = round(REST_FOR_S * 1000.0)
    moved = math.inf
    for _ in range(round((HOLD_AT_MOST_S - HOLD_BEFORE_S) / 0.1) + 1):
        q = np.array([s[:2] for _, s in loop.history[-window:]])
        moved = math.degrees(float(np.max(np.ptp(q, axis=0))))
        if moved < AT_REST_DEG:
            break
        loop.run(0.1)
    return moved


def run_move(model, truth, controller_config, planner, start_q, goal_xy, seed) -> Move:
    """One move: the controller and planner with ``model``, the plant the true arm."""
    loop = RobotLoop(model, controller_config, planner, start=start_q, seed=seed)
    loop.plant = ArmPlant(truth, start_q, loop.plant.physics_step_s, seed)
    setpoints = []                   # (s, setpoint q) of each tick
    step = loop.core.step

    def recorded(now_s, *args, **kwargs):
        volts = step(now_s, *args, **kwargs)
        setpoints.append((now_s, np.array(loop.core.last_step.setpoint[0], float)))
        return volts
    loop.core.step = recorded
    start_rest = hold_until_at_rest(loop)
    goal_s = loop.now_s
    loop.lowest_m = math.inf         # the move's, not the start's drop
    loop.submit_goal(*goal_xy)
    loop.run(MOVE_TIMEOUT_S)
    refused = loop.core.goals.counts['failed'] > 0
    times = np.array([t for t, _ in loop.history])
    q = np.array([s[:2] for _, s in loop.history])
    after = times >= goal_s
    moved_s = math.nan if refused else settled_s(times[after], q[after], goal_s)
    until = goal_s + (moved_s if math.isfinite(moved_s) else MOVE_TIMEOUT_S)
    ticks = [(t, s) for t, s in setpoints if goal_s <= t <= until]
    true_q = np.column_stack([np.interp([t for t, _ in ticks], times, q[:, j])
                              for j in range(2)])
    tracking = np.max(np.abs(np.array([s for _, s in ticks]) - true_q))
    goal_q = loop.core.goals.goal_q
    final = (np.max(np.abs(q[-1] - goal_q)) if goal_q is not None else math.nan)
    return Move(moved_s, math.degrees(tracking), math.degrees(final), 1000.0 * loop.lowest_m,
                refused, start_rest)


def fmt(value, spec='.2f') -> str:
    return '-' if value is None or not math.isfinite(value) else format(value, spec)


def one_arm(path, default, settings, controller_config, moves, runs, use_minimum, lines):
    truth = config.ArmConfig.from_parameters(layered(CONFIG / 'arm.yaml', path))
    starts = [(name, start_configuration(truth, start), goal) for name, start, goal in moves]
    minimums = (minimum_time.suite_minimums(truth, controller_config, starts,
                                            minimum_time.CACHE) if use_minimum else None)
    files = {'true': [truth], 'default': [default],
             'identified': [identify(truth, default, settings, run)[0] for run in range(runs)]}
    results = {}                     # (file, run) -> [Move]
    for name in FILES:
        for run, model in enumerate(files[name]):
            planner = Planner(model, config.load('planner')[1])
            results[name, run] = [run_move(model, truth, controller_config, planner, start_q,
                                           goal, k)
                                  for k, (_, start_q, goal) in enumerate(starts)]
    scale = ([minimums[name]['min_s'] for name, _, _ in starts] if use_minimum
             else [1.0] * len(starts))
    unit = 'time / minimum' if use_minimum else 'time s'
    columns = [('true', 0)] + [('identified', r) for r in range(runs)] + [('default', 0)]
    heads = ['true'] + [f'identified {r + 1}' if runs > 1 else 'identified'
                        for r in range(runs)] + ['default']
    lines += [f'### {Path(path).name}', '',
              f'{unit}, tracking deg (the largest distance from the setpoint), final error '
              f'deg, per file: {" / ".join(heads)}', '',
              f'| move | {unit} | tracking deg | final deg |', '|---|---|---|---|']
    for k, (name, _, _) in enumerate(starts):
        cells = [' / '.join('refused' if field == 'time_s' and results[c][k].refused
                            else fmt(getattr(results[c][k], field)
                                     / (scale[k] if field == 'time_s' else 1.0), spec)
                            for c in columns)
                 for field, spec in (('time_s', '.2f'), ('tracking_deg', '.2f'),
                                     ('final_deg', '.2f'))]
        lines.append(f'| {name} | ' + ' | '.join(cells) + ' |')
    lines += ['', 'total s: over the moves the true file does not refuse', '',
              f'| file | settled | refused | {unit}: worst | median | total s | '
              'tracking deg: worst | median | final deg: worst | lowest mm |',
              '|---|---|---|---|---|---|---|---|---|---|']
    doable = [k for k, move in enumerate(results['true', 0]) if not move.refused]
    for column, head in zip(columns, heads):
        rows = results[column]
        ratios = [r.time_s / s for r, s in zip(rows, scale)]
        finite = [r for r in ratios if math.isfinite(r)]
        tracking = [r.tracking_deg for r in rows]
        lines.append(
            f'| {head} | {len(finite)} of {len(rows)} | {sum(r.refused for r in rows)} | '
            f'{fmt(max(finite, default=math.nan))} | '
            f'{fmt(statistics.median(finite) if finite else math.nan)} | '
            f'{fmt(sum(rows[k].time_s for k in doable))} | {fmt(max(tracking))} | '
            f'{fmt(statistics.median(tracking))} | {fmt(max(r.final_deg for r in rows))} | '
            f'{min(r.lowest_mm for r in rows):.0f} |')
    lines.append('')
    print('\n'.join(lines[-len(columns) - len(starts) - 10:]), flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=1, help='identified files per arm')
    parser.add_argument('--arms', nargs='*', default=sorted(glob.glob(str(BENCH / 'arms' /
                                                                          '*.yaml')))
                        + [str(CONFIG / 'sysid_demo_arm.yaml')])
    parser.add_argument('--moves', type=lambda text: [int(i) for i in text.split(',')],
                        help='indices into the suite, e.g. 0,4')
    parser.add_argument('--no-minimum', action='store_true',
                        help='move times in seconds, not over the minimum (which takes '
                             'minutes per arm the first time)')
    parser.add_argument('--write-docs', action='store_true')
    args = parser.parse_args()
    default = config.ArmConfig.from_parameters(layered(CONFIG / 'arm.yaml'))
    settings = SysIdConfig.from_parameters(
        parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sysid'))
    controller_config = config.load('controller')[1]
    moves = [SUITE[i] for i in args.moves] if args.moves else SUITE
    lines = [f'The controller and the planner with each file on the true arm, in one process '
             f'(RobotLoop: profiles at the robot loop, phase 0, commands 4 ms late; 1 ms '
             f'physics; deterministic); {len(moves)} moves of the suite; identified files from '
             f'runs 1-{args.runs} of bench_sysid_arms.', '']
    for path in args.arms:
        one_arm(path, default, settings, controller_config, moves, args.runs,
                not args.no_minimum, lines)
    if args.write_docs:
        print(docs_table.write('sysid_controller', 'The controller on the identified file',
                               'python bench/bench_sysid_controller.py '
                               + ' '.join(sys.argv[1:]), '\n'.join(lines)))


if __name__ == '__main__':
    main()
