"""How fast the planner answers, at 1° and 0.5°, with scipy's Dijkstra and a plain one.

On ``config/frc_robot.yaml`` (the world where planning matters): start-up cost (building
the grid and checking its cells; edges are checked lazily) and, for comparison, what
checking every edge up front would add; then the latency of ``Planner.plan`` over a fixed,
seeded set of queries whose straight joint-space move is blocked, so every one runs the
graph search, with scipy.sparse.csgraph.dijkstra and with the plain-Python heapq Dijkstra
on the same CSR graph (which stops once the goal cells are settled); the last column is
the time spent in the search itself, the rest being collision checks (connections, lazy
edge checks, shortcuts), the same for both. Each method starts from a freshly built
planner, so the lazy edge checks are paid as in a fresh node.

    python bench/bench_planner.py            # add --quick for fewer queries
"""

import math
import os
from pathlib import Path
import statistics
import sys
import time

import numpy as np

from arm_control import config
from arm_control.config import PlannerConfig
from arm_control.planning.planner import Planner

FRC_FILE = Path(__file__).resolve().parents[1] / 'config' / 'frc_robot.yaml'
RESOLUTIONS_DEG = (1.0, 0.5)
SEED = 20240501


def queries(planner, count, rng):
    """Free starts and reachable goal points with a free branch, straight move blocked."""
    (s_low, s_high), (e_low, e_high) = planner.forbidden.limits
    chosen = []
    while len(chosen) < count:
        start = np.array([rng.uniform(s_low, s_high), rng.uniform(e_low, e_high)])
        radius, bearing = rng.uniform(0.3, 1.75), rng.uniform(-0.5, math.pi + 0.5)
        goal = (radius * math.cos(bearing), radius * math.sin(bearing))
        if not planner.forbidden.is_free(start):
            continue
        branches = [np.array(q) for q in planner.kinematics.inverse(*goal)]
        free = [q for q in branches if planner.forbidden.is_free(q)]
        if free and not any(planner.forbidden.segment_is_free(start, q, 0.01) for q in free):
            chosen.append((start, goal))
    return chosen


def latencies_ms(planner, pairs):
    """Wall-clock ms of each ``plan`` call, and of the graph searches within it (on the
    grid itself and on the one grown by the clearance, where plans are made first)."""
    search_s = [0.0]

    def timed(searching):
        def timed_search(*args, **kwargs):
            began = time.perf_counter()
            try:
                return searching(*args, **kwargs)
            finally:
                search_s[0] += time.perf_counter() - began
        return timed_search

    for each in (planner, planner.clear):
        if each is not None:
            each.grid.shortest_paths = timed(each.grid.shortest_paths)
    samples, searches, planned = [], [], 0
    for start, goal in pairs:
        search_s[0] = 0.0
        began = time.perf_counter()
        plan = planner.plan(start, goal)
        samples.append(1000 * (time.perf_counter() - began))
        searches.append(1000 * search_s[0])
        planned += plan.ok
    return samples, searches, planned


def main():
    quick = '--quick' in sys.argv
    arm, base = config.load('planner', FRC_FILE)
    reference = Planner(arm, base)
    pairs = queries(reference, 10 if quick else 40, np.random.default_rng(SEED))
    heap_pairs = pairs[:5 if quick else 15]
    print(f'FRC robot, {len(pairs)} seeded queries that need a search (heapq: the first '
          f'{len(heap_pairs)}); check step {math.degrees(arm.world.check_step_rad):.2f} deg; '
          f'load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores\n')
    print('| grid | cells | start-up (lazy edges) | + every edge checked | search | '
          'queries planned | median | p95 | max | search alone, median |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for resolution_deg in RESOLUTIONS_DEG:
        planner_config = PlannerConfig(math.radians(resolution_deg))
        began = time.perf_counter()
        eager = Planner(arm, planner_config)
        startup_s = time.perf_counter() - began
        began = time.perf_counter()
        eager.grid.check_all_edges()
        eager_s = time.perf_counter() - began
        cells = f'{eager.grid.shoulder.count} × {eager.grid.elbow.count}'
        for method, subset in (('scipy', pairs), ('heapq', heap_pairs)):
            planner = Planner(arm, planner_config, search=method)
            samples, searches, planned = latencies_ms(planner, subset)
            print(f'| {resolution_deg:g}° | {cells} | {startup_s:.2f} s | {eager_s:.2f} s | '
                  f'{method} | {planned}/{len(subset)} | {statistics.median(samples):.1f} ms | '
                  f'{np.percentile(samples, 95):.1f} ms | {max(samples):.1f} ms | '
                  f'{statistics.median(searches):.1f} ms |')


if __name__ == '__main__':
    main()
