"""Shortest collision-free joint-space paths: Dijkstra over the grid, then shortcuts.

A plan is a list of joint configurations joined by straight lines in joint space (the
arm paper's linear trajectories, §3.2), costing the joint travel Σ(|Δθa| + |Δθb|). It runs
from the exact start, through grid cells, to the exact goal: start and goal join nearby free
cells by checked straight segments. The grid path is then shortened by line-of-sight
shortcuts, each checked by ``ForbiddenSpace.segment_is_free`` at ``check_step_rad``; by the
triangle inequality a shortcut never costs more travel. A start inside forbidden space (the
arm was pushed there) first takes the shortest way out, to the nearest free cell from which
the goal can be reached; only that first segment is not free.
"""

import math

import numpy as np

from arm_control.config import ArmConfig, PlannerConfig
from arm_control.model.kinematics import TwoLinkKinematics, UnreachableError
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.graph import ConfigurationGrid
from arm_control.planning.plan import NoPlan, Plan
from arm_control.planning.shortcut import COARSE_FACTOR, segment_is_free, shortcut
from arm_control.planning.trees import GoalTrees

# Lazily found blocked edges are cut and the search re-run at most this often per query.
MAX_SEARCHES = 50
# The search first looks only this far (factor × the straight move's travel + margin), which
# is exact when it finds the goal there, and everywhere otherwise.
SEARCH_GUESS_FACTOR = 1.5
SEARCH_GUESS_MARGIN_RAD = math.radians(30.0)
BRANCH_NAMES = ('elbow-positive', 'elbow-negative')
# A start within this of a tree's goal on both joints (a robot resting on a preset, its pose
# sent as a tool pose and back) plans from that tree.
TREE_START_RAD = 1e-6


def _degrees(q) -> str:
    return f'({math.degrees(q[0]):.1f}, {math.degrees(q[1]):.1f}) deg'


class Planner:
    """Plans on one arm's configuration space; the grid is built once, here.

    Paths keep ``world.clearance_rad`` from forbidden space on both joints wherever such a
    path exists from a free start, and are merely free otherwise. A path in free space grazes
    forbidden space where that is shorter, and the overshoot of a late command goes in:
    "floor → full extension, low" went 19-43 mm into the floor with every command 10-20 ms
    late, and touches nothing planned in the clearance (``bench/stalls.py --latency``).
    ``forbidden``, ``grid`` and ``trees`` are free space's; ``clear`` plans in the clearance."""

    def __init__(self, arm: ArmConfig, config: PlannerConfig, *, search: str = 'scipy',
                 margin_rad: float | None = None):
        self.arm = arm
        self.config = config
        if search not in ('scipy', 'heapq'):
            raise ValueError(f"search = {search!r}: expected 'scipy' or 'heapq'")
        self.search = search                       # 'heapq': the plain one, for comparison
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.forbidden = ForbiddenSpace(arm, margin_rad or 0.0)
        self.grid = ConfigurationGrid(self.forbidden, config.grid_resolution_rad,
                                      arm.world.check_step_rad)
        self.trees = GoalTrees(self.grid)
        clearance_rad = arm.world.clearance_rad
        self.clear = Planner(arm, config, search=search, margin_rad=clearance_rad) \
            if margin_rad is None and clearance_rad > 0.0 else None

    # Public

    def plan(self, start_q, goal_xy) -> Plan:
        """From ``start_q`` to the point ``goal_xy`` (arm_base, m) on either IK branch;
        the branch with the cheaper path wins (in the clearance where there is a path)."""
        start = self._start(start_q)
        if isinstance(start, Plan):
            return start
        clear = self._clear_plans(start, lambda planner: [planner.plan(start, goal_xy)])
        if clear[0] is not None:
            return clear[0]
        goal_xy = np.asarray(goal_xy, dtype=float).ravel()
        if goal_xy.shape != (2,) or not np.all(np.isfinite(goal_xy)):
            return Plan.failure(f'the goal point must be two finite numbers (x, y), '
                                f'got {goal_xy.tolist()}', NoPlan.BAD_INPUT)
        try:
            branches = self.kinematics.inverse(*goal_xy)
        except UnreachableError as error:
            return Plan.failure(f'the goal is out of reach: {error}', NoPlan.OUT_OF_REACH)
        candidates = [self._in_travel(q) for q in branches]
        free = self.forbidden.is_free(np.array(candidates))
        goals = [goal for goal, ok in zip(candidates, free) if ok]
        refusals = [f'{name} branch {_degrees(q)}: {self.forbidden.why_forbidden(goal)}'
                    for name, q, goal, ok in zip(BRANCH_NAMES, branches, candidates, free)
                    if not ok]
        if not goals:
            return Plan.failure(
                f'the goal ({goal_xy[0]:.3f}, {goal_xy[1]:.3f}) m is forbidden on both elbow '
                f'branches: {"; ".join(refusals)}', NoPlan.FORBIDDEN_GOAL)
        return self._search(start, goals)[0]

    def plan_to_configuration(self, start_q, goal_q) -> Plan:
        """From ``start_q`` to the configuration ``goal_q`` (taken into the joint travel)."""
        return self.plan_to_configurations(start_q, [goal_q])[0]

    def plan_to_configurations(self, start_q, goals_q) -> list[Plan]:
        """``plan_to_configuration`` to each of ``goals_q`` (e.g. a goal's elbow branches):
        one grid search serves them all (one more for those with no path in the clearance)."""
        start = self._start(start_q)
        if isinstance(start, Plan):
            return [start] * len(goals_q)
        plans = self._clear_plans(
            start, lambda planner: planner.plan_to_configurations(start, goals_q), len(goals_q))
        failed = [k for k, plan in enumerate(plans) if plan is None]
        if failed:
            for k, plan in zip(failed, self._plans_to(start, [goals_q[k] for k in failed])):
                plans[k] = plan
        return plans

    def _clear_plans(self, start, plan_with, count: int = 1) -> list:
        """``plan_with(self.clear)`` from a free start: each plan found in the clearance that
        is free in free space too, None in place of the others. From a clear start that holds
        by construction; from one inside the clearance the way out of it is unchecked there,
        so it is checked here."""
        if self.clear is None or not self.forbidden.is_free(start):
            return [None] * count
        clear_start = self.clear.forbidden.is_free(start)
        return [plan if plan.ok and (clear_start or self.forbidden.path_is_free(
                    plan.waypoints_rad)) else None
                for plan in plan_with(self.clear)]

    def _plans_to(self, start, goals_q) -> list[Plan]:
        plans, goals, where = [], [], []
        for goal_q in goals_q:
            goal_q = np.asarray(goal_q, dtype=float).ravel()
            if goal_q.shape != (2,) or not np.all(np.isfinite(goal_q)):
                plans.append(Plan.failure(f'the goal configuration must be two finite angles, '
                                          f'got {goal_q.tolist()}', NoPlan.BAD_INPUT))
                continue
            goal, why = self._goal(goal_q)
            if why is not None:
                plans.append(Plan.failure(f'the goal configuration {_degrees(goal_q)} is '
                                          f'forbidden: {why}', NoPlan.FORBIDDEN_GOAL))
                continue
            plans.append(None)
            goals.append(goal)
            where.append(len(plans) - 1)
        for k, plan in zip(where, self._search(start, goals, each=True) if goals else []):
            plans[k] = plan
        return plans

    def prepare(self, goal_q) -> bool:
        """Build the shortest-path tree toward the configuration ``goal_q`` (a preset's
        branch: ``trees``), so that plans to it need no search; False when it is forbidden
        or already prepared. Only in the clearance where there is one: plans are made there
        but for the few that cannot be."""
        if self.clear is not None:
            return self.clear.prepare(goal_q)
        goal, why = self._goal(np.asarray(goal_q, dtype=float).ravel())
        if why is not None or goal in self.trees:
            return False
        self.trees.build(goal, self.grid.connections(goal, toward=True))
        return True

    def prove_cells(self, tiles: int | None = None) -> bool:
        """``ForbiddenSpace.prove_cells`` for the space plans are checked in (the clearance's
        too): ``tiles`` more at a time (None: all); True once all are."""
        return (self.clear or self).forbidden.prove_cells(tiles)

    # Ends

    def _in_travel(self, q) -> np.ndarray:
        """q with each angle moved by whole turns into its joint's travel where it can be."""
        out = np.array(q, dtype=float)
        for k in range(2):
            moved = self.forbidden.to_joint_range(out[k], k)
            if moved is not None:
                out[k] = moved
        return out

    def _start(self, start_q):
        start = np.asarray(start_q, dtype=float).ravel()
        if start.shape != (2,) or not np.all(np.isfinite(start)):
            return Plan.failure(f'the start configuration must be two finite angles, '
                                f'got {start.tolist()}', NoPlan.BAD_INPUT)
        return self._in_travel(start)

    def _goal(self, q) -> tuple[np.ndarray, str | None]:
        goal = self._in_travel(q)
        return goal, self.forbidden.why_forbidden(goal)

    # Search

    def segment_is_free(self, q_from, q_to, coarse_factor: float = COARSE_FACTOR) -> bool:
        """``shortcut.segment_is_free`` in free space."""
        return segment_is_free(self.forbidden, q_from, q_to, coarse_factor)

    def _search(self, start: np.ndarray, goals: list[np.ndarray], each: bool = False):
        """[the plan to the cheapest of ``goals``], or with ``each`` a plan to each of them,
        from one grid search (a start inside forbidden space: one search per goal, each
        with its own way out)."""
        if each and len(goals) > 1 and not self.forbidden.is_free(start):
            return [self._search(start, [goal])[0] for goal in goals]
        groups = [[k] for k in range(len(goals))] if each else [list(range(len(goals)))]
        start_free = bool(self.forbidden.is_free(start))
        lower_bounds = [float(np.abs(goal - start).sum()) for goal in goals]
        plans = [None] * len(groups)
        if start_free:
            for g, members in enumerate(groups):
                goal = self._straight(start, goals, members)
                if goal is not None:
                    plans[g] = Plan.through([start, goal])
        if all(plans):
            return plans

        grid = self.grid
        links = [grid.connections(goal, toward=True) for goal in goals]
        labels = [{int(label) for k in members for label in grid.components[links[k][0]]}
                  for members in groups]
        narrow = Plan.failure(
            'no connection: the free space around the goal is narrower than the planner grid '
            f'({math.degrees(grid.resolution_rad):.2f} deg); try a finer grid_resolution_rad',
            NoPlan.NO_CONNECTION)
        plans = [plan or (None if labels[g] else narrow) for g, plan in enumerate(plans)]
        open_groups = [g for g, plan in enumerate(plans) if plan is None]
        if not open_groups:
            return plans
        escape = None
        if start_free:
            source_nodes, source_costs = grid.connections(start, toward=False)
            if len(source_nodes) == 0:
                boxed = Plan.failure(
                    f'no connection: the start {_degrees(start)} is boxed in by forbidden '
                    'space closer than the planner grid reaches', NoPlan.NO_CONNECTION)
                return [plan or boxed for plan in plans]
        else:
            escape = self._way_out(start, set().union(*(labels[g] for g in open_groups)))
            if escape is None:
                trapped = Plan.failure(
                    f'no connection: the start {_degrees(start)} is in forbidden space '
                    f'({self.forbidden.why_forbidden(start)}) and no free configuration '
                    'connected to the goal exists', NoPlan.NO_CONNECTION)
                return [plan or trapped for plan in plans]
            source_nodes = np.array([escape])
            source_costs = np.abs(grid.configurations[escape] - start).sum(keepdims=True)
        source_labels = {int(label) for label in grid.components[source_nodes]}
        separated = Plan.failure(
            f'no connection: forbidden space separates the start {_degrees(start)} from the '
            'goal; no collision-free path joins them', NoPlan.SEPARATED)
        for g in open_groups:
            if not labels[g] & source_labels:
                plans[g] = separated
        open_groups = [g for g in open_groups if plans[g] is None]
        if escape is not None:                      # from the way out as from a free start
            way_out = grid.configurations[escape]
            for g in open_groups:
                goal = self._straight(way_out, goals, groups[g])
                if goal is not None:
                    plans[g] = Plan.through([start, way_out, goal])
            open_groups = [g for g in open_groups if plans[g] is None]
        if not open_groups:
            return plans
        if each and escape is None:                 # a goal with a tree needs no search
            for g in open_groups:
                found = self.trees.path(goals[g], source_nodes, source_costs)
                if found is not None:
                    plans[g] = self._finish(start, goals[g], found[0], escape)
            open_groups = [g for g in open_groups if plans[g] is None]
            if not open_groups:
                return plans
        root = self.trees.rooted_at(start, TREE_START_RAD) if escape is None else None
        if root is not None:                        # nor does a start with one, read backwards
            for g in open_groups:
                ways = [(found[1], k, found[0]) for k in groups[g]
                        for found in [self.trees.path_from(root, *links[k])] if found]
                if ways:
                    _, k, nodes = min(ways, key=lambda way: way[0])
                    plans[g] = self._finish(start, goals[k], nodes, escape)
            open_groups = [g for g in open_groups if plans[g] is None]
            if not open_groups:
                return plans
        targets = [(np.concatenate([links[k][0] for k in groups[g]]),
                    np.concatenate([links[k][1] for k in groups[g]])) for g in open_groups]
        # Most detours cost well under half as much again as the straight move.
        guess = SEARCH_GUESS_FACTOR * max(min(lower_bounds[k] for k in groups[g])
                                          for g in open_groups) + SEARCH_GUESS_MARGIN_RAD
        try:
            found = grid.shortest_path_each(source_nodes, source_costs, targets, self.search,
                                            MAX_SEARCHES, guess)
        except RuntimeError:
            blocked = Plan.failure('no connection found: too many grid edges turned out '
                                   'blocked by thin forbidden regions; try a finer '
                                   'grid_resolution_rad', NoPlan.NO_CONNECTION)
            return [plan or blocked for plan in plans]
        for g, result in zip(open_groups, found):
            if result is None:
                plans[g] = separated
                continue
            nodes, _, target = result
            goal = goals[np.repeat(groups[g], [len(links[k][0]) for k in groups[g]])[target]]
            plans[g] = self._finish(start, goal, nodes, escape)
        return plans

    def _straight(self, origin, goals, members):
        """The goal of ``members`` nearest ``origin`` when the straight segment to it is free:
        it costs exactly the lower bound |Δθa| + |Δθb|, so no path is shorter; else None."""
        bounds = [float(np.abs(goals[k] - origin).sum()) for k in members]
        free = [self.segment_is_free(origin, goals[k]) for k in members]
        best = min(range(len(members)), key=lambda i: (not free[i], bounds[i]))
        return goals[members[best]] if free[best] and bounds[best] <= min(bounds) else None

    def _finish(self, start, goal, nodes, escape) -> Plan:
        """The plan along the grid path ``nodes``: from the start (or its way out) to the
        goal, shortcut."""
        middle = self.grid.configurations[nodes]
        path = shortcut(self.forbidden, np.vstack([middle, goal] if escape is not None
                                                  else [start, middle, goal]))
        if path is None:
            return Plan.failure('no connection: the grid path failed its final collision '
                                'check; try a finer grid_resolution_rad', NoPlan.NO_CONNECTION)
        return Plan.through(path if escape is None else np.vstack([start, path]))

    def _way_out(self, start: np.ndarray, labels: set[int]) -> int | None:
        """The free node nearest ``start`` in joint travel among those that reach a goal."""
        grid = self.grid
        candidates = np.flatnonzero(grid.free.ravel()
                                    & np.isin(grid.components, sorted(labels)))
        if len(candidates) == 0:
            return None
        travel = np.abs(grid.configurations[candidates] - start).sum(axis=1)
        return int(candidates[np.argmin(travel)])
