"""What a goal costs the controller: path, branch choice and timing, per move.

``PlanTimer.plan_and_time`` (planned in-process): the path of each free elbow branch
(planner), the branch choice (the quick estimates), the timing of the branches kept, and the
total, median and p95 over repeats, CPU and wall, on the default arm
(``bench_trajectory.SUITE``) and on the FRC robot (its 30 preset-to-preset moves). A fresh
controller's first goal also pays for its caches (the forbidden-space cells it proves); it is
reported apart.

    python bench/bench_trajectory.py --planning [repeats]
    # on a busy machine, two busy loops beside it:
    for i in 1 2; do timeout 120 python3 -c 'while True: pass' & done; \
        python bench/bench_trajectory.py --planning; kill %1 %2
"""

import itertools
import math
import time

from bench_trajectory import _start_configuration, BENCH, Move, print_table, SUITE
import numpy as np

from arm_control import config
from arm_control.model.world import ForbiddenSpace

PLANNING_REPEATS = 15
FRC_ROBOT = BENCH.parent / 'config' / 'frc_robot.yaml'


class _TimedPlanner:
    """The planner, with the CPU time of its calls added up."""

    def __init__(self, planner):
        self.planner, self.cpu_s = planner, 0.0

    def plan(self, start_q, goal_xy):
        return self._timed(self.planner.plan, start_q, goal_xy)

    def plan_to_configuration(self, start_q, goal_q):
        return self._timed(self.planner.plan_to_configuration, start_q, goal_q)

    def _timed(self, call, *args):
        began = time.thread_time()
        try:
            return call(*args)
        finally:
            self.cpu_s += time.thread_time() - began


def planning_moves(arm, files):
    """(name, start q, goal xy): this suite on the default arm, else every preset to every
    other preset."""
    forbidden = ForbiddenSpace(arm)
    if files:
        presets = {name: (x, y) for name, x, y in arm.presets}
        pairs = [(f'{a} -> {b}', presets[a], presets[b])
                 for a, b in itertools.permutations(presets, 2)]
    else:
        pairs = SUITE
    for name, start_xy, goal_xy in pairs:
        move = Move(name, start_xy, goal_xy, arm, None, None, forbidden, None)
        yield name, _start_configuration(move), goal_xy


def planning_times(files=(), repeats=PLANNING_REPEATS):
    """Rows of path / branch choice / timing / total ms per move, and the pooled totals."""
    from arm_control.control.controller import ArmController
    from arm_control.control.goals import Goal
    from arm_control.control.plans import PlanRequest
    from arm_control.planning.planner import Planner
    arm, controller = config.load('controller', *files)
    planner = _TimedPlanner(Planner(arm, config.load('planner', *files)[1]))
    core = ArmController(arm, controller)
    timing_cpu = [0.0]
    timer = core.plan_timer
    time_plan = timer.time_plan

    def timed_time_plan(request, plan):
        began = time.thread_time()
        try:
            return time_plan(request, plan)
        finally:
            timing_cpu[0] += time.thread_time() - began

    timer.time_plan = timed_time_plan
    requests = [PlanRequest(i, Goal(goal[0], goal[1], name), tuple(q), (0.0, 0.0), None, 0.0)
                for i, (name, q, goal) in enumerate(planning_moves(arm, files))]
    first = []
    samples = {r.goal.label: [] for r in requests}
    for repeat in range(repeats + 1):
        for request in requests:
            planner.cpu_s, timing_cpu[0] = 0.0, 0.0
            wall, cpu = time.perf_counter(), time.thread_time()
            timed = timer.plan_and_time(request, planner)
            cpu, wall = time.thread_time() - cpu, time.perf_counter() - wall
            if repeat == 0:            # the first goal of a fresh controller pays its caches
                first.append(1e3 * wall)
                continue
            samples[request.goal.label].append(
                (planner.cpu_s, cpu - planner.cpu_s - timing_cpu[0], timing_cpu[0], cpu, wall,
                 timed.trajectory.duration_s if timed.ok else math.nan))
    rows, pooled = [], []
    for name, values in samples.items():
        ms = np.array(values)[:, :5] * 1e3
        pooled.append(ms[:, 3:5])
        median, p95 = np.median(ms, axis=0), np.percentile(ms, 95, axis=0)
        rows.append({'move': name, 'path ms': f'{median[0]:.1f}',
                     'branch choice ms': f'{median[1]:.1f}', 'timing ms': f'{median[2]:.1f}',
                     'total ms CPU median / p95': f'{median[3]:.1f} / {p95[3]:.1f}',
                     'total ms wall median / p95': f'{median[4]:.1f} / {p95[4]:.1f}',
                     'duration s': f'{np.median(np.array(values)[:, 5]):.3f}'})
    pooled = np.vstack(pooled)
    return rows, pooled, first


def planning(repeats=PLANNING_REPEATS):
    for label, files in (('default arm', ()), ('FRC robot', (str(FRC_ROBOT),))):
        rows, pooled, first = planning_times(files, repeats)
        print(f'\nPlanning per goal on the {label} (PlanTimer.plan_and_time: path of each '
              f'free branch + branch choice + timing), {repeats} repeats per move; path, '
              'choice and timing: CPU medians')
        print_table(rows)
        print(f'all {len(pooled)} goals: CPU median {np.median(pooled[:, 0]):.1f} ms, p95 '
              f'{np.percentile(pooled[:, 0], 95):.1f} ms; wall median '
              f'{np.median(pooled[:, 1]):.1f} ms, p95 {np.percentile(pooled[:, 1], 95):.1f} '
              f'ms; the first goal of a fresh controller: {first[0]:.0f} ms wall')
