"""What a goal costs before the arm moves: the planner node's work and the worker's, per goal.

A goal from rest goes the way it goes through ROS, each step called as the nodes call it:

- planner: what the planner node does for plan_path (``PresetAnswers.plan``): from one
  preset to another, the answer it worked out at start-up; otherwise (``BranchRanking.plan``)
  the path of each free elbow branch from one grid search (none for a preset's branch: the
  node builds their shortest-path trees at start-up), the branch choice (quick estimates,
  and when another branch comes within the margin, a quick timing of the close ones). This
  bench prepares both as the node does;
- quick: what the worker answers at once (``PlanTimer.time_plan(quick=True)``): the path
  checked and timed on a few dozen stages, not bent. The arm starts on it;
- the user waits for planner + quick (the round trips through DDS and the pipe to the
  worker come on top: about a millisecond each). The nodes run both at real-time priority
  (``planner.realtime_priority``, ``controller.planning_priority``), and so does this bench;
- refine: what the worker does next while the arm moves (``PlanTimer.refine``): the rest
  of the path bent and timed finely from the hand-over time (``HandoverClock``, from the
  quick timing's wall time), which takes over there if it is ready by then.

Per move on the default arm (``bench_trajectory.SUITE``) and on the FRC robot (its 30
preset-to-preset moves), repeated: CPU medians of each step, the user's wait (CPU and wall,
median and p95), the refinement's wall time against its hand-over, and the durations: the
quick trajectory, quick-then-refined (what the arm does), and the fine one from rest
(``time_plan``, what a goal took before, after waiting for it). The first goal of a fresh
planner and worker also pays for their caches (the forbidden-space cells they prove); it is
reported apart.

    python bench/planning_time.py [repeats]            # idle
    python bench/planning_time.py --loaded [repeats]   # two busy loops beside it (busy.py)
"""

import itertools
import math
from pathlib import Path
import sys
import time

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent)]

import busy  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402
from arm_control.plans.cache import PresetAnswers  # noqa: E402
from arm_control.plans.goals import Goal  # noqa: E402
from arm_control.plans.messages import PlanRequest  # noqa: E402
from arm_control.plans.timer import PlanTimer  # noqa: E402
from arm_control.plans.worker import HandoverClock  # noqa: E402
from arm_control.realtime import raised  # noqa: E402

PLANNING_REPEATS = 10
FRC_ROBOT = BENCH.parent / 'config' / 'frc_robot.yaml'


def _start_configuration(arm, forbidden, start_xy):
    """The start point's elbow-negative branch when it is free, else the other."""
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    positive, negative = kinematics.inverse(*start_xy)
    for q in (negative, positive):
        q = np.array([forbidden.to_joint_range(q[k], k) or q[k] for k in range(2)])
        if forbidden.is_free(q):
            return q
    raise ValueError(f'the start {start_xy} is forbidden on both branches')


def planning_moves(arm, files):
    """(name, start q, goal xy): the trajectory bench's suite on the default arm, else every
    preset to every other preset."""
    from bench_trajectory import SUITE
    forbidden = ForbiddenSpace(arm)
    if files:
        presets = {name: (x, y) for name, x, y in arm.presets}
        pairs = [(f'{a} -> {b}', presets[a], presets[b])
                 for a, b in itertools.permutations(presets, 2)]
    else:
        pairs = SUITE
    for name, start_xy, goal_xy in pairs:
        yield name, _start_configuration(arm, forbidden, start_xy), goal_xy


def _timed(call):
    """(result, CPU s, wall s)."""
    cpu, wall = time.thread_time(), time.perf_counter()
    result = call()
    return result, time.thread_time() - cpu, time.perf_counter() - wall


def one_goal(answers, timer, clock, request, planner_priority=0):
    """The steps of one goal, as the nodes run them (the planner's answer and the quick
    timing at their real-time priorities): {step: (CPU s, wall s)} and durations."""
    with raised(planner_priority):
        plan, plan_cpu, plan_wall = _timed(
            lambda: answers.plan(request.start_q, request.goal.xy))
    with raised(timer.config.planning_priority):
        quick, quick_cpu, quick_wall = _timed(
            lambda: timer.time_plan(request, plan, quick=True))
    handover = clock.handover_s(quick_wall, quick.trajectory.duration_s if quick.ok else 0.0)
    refined, refine_cpu, refine_wall = _timed(lambda: timer.refine(quick, handover))
    clock.seen(quick_wall, refine_wall)
    quick_s = quick.trajectory.duration_s if quick.ok else math.nan
    in_time = refined is not None and refine_wall < handover
    return {'planner': (plan_cpu, plan_wall), 'quick': (quick_cpu, quick_wall),
            'refine': (refine_cpu, refine_wall), 'handover': handover, 'quick s': quick_s,
            'moved s': handover + refined.trajectory.duration_s if in_time else quick_s,
            'refined in time': in_time, 'plan': plan}


def planning_times(files=(), repeats=PLANNING_REPEATS):
    """Rows per move, the pooled user waits (CPU, wall; ms) and the first goal's wall ms."""
    arm, controller = config.load('controller', *files)
    planner_config = config.load('planner', *files)[1]
    planner = Planner(arm, planner_config)
    timer, clock = PlanTimer(arm, controller), HandoverClock()
    for q in timer.ranking.preset_configurations():      # as the node does at start-up
        planner.prepare(q)
    answers = PresetAnswers(timer.ranking, planner)
    while answers.pending:
        answers.prepare_next()
    requests = [PlanRequest(i, Goal(goal[0], goal[1], name), tuple(q), (0.0, 0.0), None, 0.0)
                for i, (name, q, goal) in enumerate(planning_moves(arm, files))]
    first = None
    samples = {r.goal.label: [] for r in requests}
    for repeat in range(repeats + 1):
        for request in requests:
            steps = one_goal(answers, timer, clock, request, planner_config.realtime_priority)
            if first is None:          # the first goal of a fresh planner and worker
                first = 1e3 * (steps['planner'][1] + steps['quick'][1])
            if repeat > 0:
                samples[request.goal.label].append(steps)
    rows, pooled = [], []
    for request in requests:
        runs = samples[request.goal.label]
        ms = {k: 1e3 * np.array([run[k] for run in runs])
              for k in ('planner', 'quick', 'refine')}
        handover_ms = 1e3 * np.median([run['handover'] for run in runs])
        wait = ms['planner'] + ms['quick']                   # (repeats, CPU / wall)
        pooled.append(wait)
        fine = timer.time_plan(request, runs[-1]['plan'])
        rows.append({
            'move': request.goal.label,
            'planner ms': f'{np.median(ms["planner"][:, 0]):.1f}',
            'quick ms': f'{np.median(ms["quick"][:, 0]):.1f}',
            'wait ms CPU median / p95': f'{np.median(wait[:, 0]):.1f} / '
                                        f'{np.percentile(wait[:, 0], 95):.1f}',
            'wait ms wall median / p95': f'{np.median(wait[:, 1]):.1f} / '
                                         f'{np.percentile(wait[:, 1], 95):.1f}',
            'refine ms wall / hand-over ms': f'{np.median(ms["refine"][:, 1]):.0f} / '
                                             f'{handover_ms:.0f}',
            'refined in time': f'{sum(r["refined in time"] for r in runs)}/{len(runs)}',
            'quick s': f'{runs[-1]["quick s"]:.3f}',
            'moved s': f'{np.median([r["moved s"] for r in runs]):.3f}',
            'fine from rest s': f'{fine.trajectory.duration_s:.3f}' if fine.ok else 'none'})
    return rows, np.vstack(pooled), first


def planning(repeats=PLANNING_REPEATS):
    from bench_trajectory import print_table
    for label, files in (('default arm', ()), ('FRC robot', (str(FRC_ROBOT),))):
        rows, pooled, first = planning_times(files, repeats)
        print(f'\nPlanning per goal on the {label}, {repeats} repeats per move: the planner '
              "node's work and the worker's quick timing (the user waits for both), CPU "
              'medians; the refinement while the arm moves (wall, against its hand-over); '
              'durations of the quick trajectory, of the move (quick, then refined when it '
              'was in time) and of the fine timing from rest')
        print_table(rows)
        print(f'all {len(pooled)} goals, the wait: CPU median {np.median(pooled[:, 0]):.1f} '
              f'ms, p95 {np.percentile(pooled[:, 0], 95):.1f} ms; wall median '
              f'{np.median(pooled[:, 1]):.1f} ms, p95 {np.percentile(pooled[:, 1], 95):.1f} '
              f'ms; the first goal of a fresh planner and worker: {first:.0f} ms wall')


def main():
    numbers = [a for a in sys.argv[1:] if a.isdigit()]
    repeats = int(numbers[0]) if numbers else PLANNING_REPEATS
    loops = busy.start(2, 3600.0) if '--loaded' in sys.argv else []
    try:
        if loops:
            print('two busy loops running beside it (bench/busy.py)')
        planning(repeats)
    finally:
        busy.stop(loops)


if __name__ == '__main__':
    main()
