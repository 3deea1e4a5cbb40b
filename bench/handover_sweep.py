"""Where a goal from rest ends, by the hand-over time of its refinement (in one process).

A goal from rest is answered with a quick trajectory, then refined from a hand-over time
(``plans/worker.py``). Per move of ``bench_trajectory.SUITE``, from its nominal
start along the path the planner gives: the minimum under the electrical limits, the quick
trajectory's and the fine one's durations (the fine: what a kept trajectory gives), and the
end of the refined answer (hand-over + the refinement's duration) for each hand-over time;
'-' where the refinement would not end sooner than the quick trajectory (the quick one is
kept). The durations are deterministic; the compute times are not (median of a few).

    python bench/handover_sweep.py
    python bench/handover_sweep.py --handovers 0.03,0.06,0.1 --moves 3 --write-docs
"""

import argparse
from pathlib import Path
import statistics
import sys
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE), str(HERE.parent)]

from bench_trajectory import SUITE  # noqa: E402
import docs_table  # noqa: E402
import minimum_time  # noqa: E402
import robot_clock  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402
from arm_control.plans.goals import Goal  # noqa: E402
from arm_control.plans.messages import PlanRequest  # noqa: E402
from arm_control.plans.timer import PlanTimer  # noqa: E402

HANDOVERS_S = (0.03, 0.045, 0.06, 0.08, 0.1, 0.12, 0.15)
REPEATS = 3


def timed_ms(function):
    """(the last result, the median compute time in ms over ``REPEATS`` calls)."""
    times = []
    for _ in range(REPEATS):
        began = time.perf_counter()
        result = function()
        times.append(1000.0 * (time.perf_counter() - began))
    return result, statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--handovers', type=lambda text: [float(h) for h in text.split(',')],
                        default=list(HANDOVERS_S), help='hand-over times (s), comma-separated')
    parser.add_argument('--moves', type=lambda text: [int(i) for i in text.split(',')],
                        help='indices into the suite (default: all)')
    parser.add_argument('--write-docs', action='store_true',
                        help='keep the table in docs/benchmarks/handover_sweep.md')
    args = parser.parse_args()
    arm, controller_config = config.load('controller')
    planner = Planner(arm, config.load('planner')[1])
    timer = PlanTimer(arm, controller_config)
    suite = [SUITE[i] for i in args.moves] if args.moves else SUITE
    moves = [(name, robot_clock.start_configuration(arm, start), goal)
             for name, start, goal in suite]
    minimums = minimum_time.suite_minimums(arm, controller_config, moves, minimum_time.CACHE)
    heads = ['move', 'minimum s', 'quick s (ms)', 'fine s (ms)'] + \
        [f'refined from {h:g} s' for h in args.handovers]
    lines = ['| ' + ' | '.join(heads) + ' |', '|' + '---|' * len(heads)]
    for name, start_q, goal_xy in moves:
        request = PlanRequest(0, Goal(*goal_xy, name), start_q, (0.0, 0.0), None, 0.0)
        plan = timer.ranking.plan(planner, start_q, goal_xy)
        quick, quick_ms = timed_ms(lambda: timer.time_plan(request, plan, quick=True))
        fine, fine_ms = timed_ms(lambda: timer.time_plan(request, plan))
        cells = [name, f"{minimums[name]['min_s']:.3f}",
                 f'{quick.trajectory.duration_s:.3f} ({quick_ms:.0f})',
                 f'{fine.trajectory.duration_s:.3f} ({fine_ms:.0f})']
        for handover_s in args.handovers:
            refined, refine_ms = timed_ms(lambda: timer.refine(quick, handover_s))
            cells.append('-' if refined is None else
                         f'{handover_s + refined.trajectory.duration_s:.3f} ({refine_ms:.0f})')
        lines.append('| ' + ' | '.join(cells) + ' |')
        print(lines[-1], flush=True)
    table = ('in one process; durations in s, compute times in ms (median of '
             f'{REPEATS}, a shared machine) in brackets.\n\n' + '\n'.join(lines))
    print('\n' + table)
    if args.write_docs:
        docs_table.write('handover_sweep', 'Where a goal from rest ends, by its hand-over',
                         'python bench/' + ' '.join([Path(sys.argv[0]).name] + sys.argv[1:]),
                         table)


if __name__ == '__main__':
    main()
