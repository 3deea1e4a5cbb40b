"""From a planner's path to a checked, timed trajectory -- the slow part of taking a goal.

The controller core asks for a plan (``PlanRequest``) and takes back a ``TimedPlan``. What
lies between -- checking the path, choosing the elbow branch by time, timing the path -- is
here, pure and free of the core's mutable state, so the node runs it in a worker process
while its control loop keeps the beat, and tests and benchmarks call it directly.

The elbow branch is chosen by time, the same way in-process and through the planner node
(``fastest_branch``): each free branch's path is estimated quickly; when others come within
``BRANCH_SCREEN_MARGIN`` of the best, those are estimated again with their best bend (the
first grid of the shape search) and the fastest wins. Ranking
uses the arm's own limits (the battery, the current limits), not the controller's reserves,
so the planner node, which knows only the arm, ranks exactly as the controller would.

Through the worker a goal from rest is answered twice: at once with a quick trajectory the
arm starts on (``time_quick``), then with the rest of it bent and timed finely from where
the quick one will be a little later (``refine``), which takes over there when it arrives in
time and ends sooner. The user waits only for the first.
"""

from dataclasses import replace
import math
import time
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics, UnreachableError
from arm_control.model.world import ForbiddenSpace
from arm_control.plans.cache import KeptTrajectories, PlanCache
from arm_control.plans.goals import GoalValidator
from arm_control.plans.messages import PlanRequest, TimedPlan
from arm_control.timing import (estimated_bent_duration_s, estimated_duration_s,
                                refined_trajectory, time_optimal_trajectory, Trajectory,
                                TrajectoryError, TrajectoryLimits)
from arm_control.timing.shaping import prove_room_cells
from arm_control.timing.timed import ChainedTrajectory

# Branches whose quick estimate is within this fraction of the best one's are timed in full.
BRANCH_SCREEN_MARGIN = 0.25
# The first waypoint of a plan may differ from the requested start by rounding only ...
PLAN_START_TOLERANCE_RAD = 0.01
# ... and its last must put the tool on the goal.
PLAN_GOAL_TOLERANCE_M = 0.002


class Anywhere:
    """Free space everywhere: for timing the way out of forbidden space, which the arm is
    already in (the planner's first leg from a start pushed there)."""

    def is_free(self, q):
        free = np.ones(np.asarray(q, float).shape[:-1], dtype=bool)
        return bool(free) if free.ndim == 0 else free


class PlanTimer:
    """Checks and times plans for one arm and controller configuration."""

    def __init__(self, arm: ArmConfig, config: ControllerConfig):
        self.arm, self.config = arm, config
        self.dynamics = ArmDynamics(arm)
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.forbidden = ForbiddenSpace(arm)
        self.clear_space = ForbiddenSpace(arm, arm.world.clearance_rad)
        self.limits = TrajectoryLimits.from_config(arm, config)
        self.ranking = BranchRanking(arm)
        self.cache = PlanCache()           # the worker's side: kept trajectories

    def time_plan(self, request: PlanRequest, plan, quick: bool = False) -> TimedPlan:
        """Check ``plan`` (anything with ``ok``, ``reason`` and ``waypoints_rad``) against the
        request and time it; ``quick``: from rest, on few stages and not bent (``refine``
        makes it better from a little later) -- or, for a goal that comes again from rest
        along the same path, the fine trajectory kept from the last time (``cache``)."""
        started = time.perf_counter()
        kept = self.cache.trajectory(request, plan)
        if kept is not None:
            return TimedPlan(request, kept, compute_s=time.perf_counter() - started, kept=True)
        try:
            trajectory, reason = self._time(request, plan, quick)
        except TrajectoryError as error:
            trajectory = None
            reason = f'no trajectory along the plan to {request.goal.label}: {error}'
        return TimedPlan(request, trajectory, reason, time.perf_counter() - started)

    def fine_from_rest(self, request: PlanRequest, plan):
        """The fine trajectory of ``plan`` from rest, to keep (``KeptTrajectories``), or None:
        not a plan from rest, or no trajectory along it."""
        if not KeptTrajectories.keepable(request, plan):
            return None
        timed = self.time_plan(request, plan)
        return timed.trajectory if timed.ok else None

    def refine(self, quick: TimedPlan, handover_s: float) -> Optional[TimedPlan]:
        """The answer that takes over from ``quick``'s trajectory ``handover_s`` after its
        start: the rest bent and timed finely (``refined_trajectory``), or None when that
        would not end sooner."""
        started = time.perf_counter()
        located = quick.trajectory.path_at(handover_s) \
            if isinstance(quick.trajectory, Trajectory) else None
        if located is None:
            return None
        # Bent only where it keeps the clearance, as the quick one was timed.
        space = self.clear_space if self.clear_space.path_is_free(located[0].points) \
            else self.forbidden
        refined = refined_trajectory(quick.trajectory, handover_s, self.dynamics, space,
                                     self.limits)
        if refined is None:
            return None
        return TimedPlan(quick.request, refined, compute_s=time.perf_counter() - started,
                         handover_s=handover_s)

    def _time(self, request: PlanRequest, plan, quick: bool = False):
        label = request.goal.label
        if plan is None or not plan.ok:
            why = getattr(plan, 'reason', '') or 'the planner found no path'
            return None, f'no plan to {label}: {why}'
        waypoints = np.array(plan.waypoints_rad, dtype=float).reshape(-1, 2)
        if len(waypoints) == 0 or not np.all(np.isfinite(waypoints)):
            return None, f'the plan to {label} is empty or not finite'
        start = np.asarray(request.start_q, float)
        if np.max(np.abs(waypoints[0] - start)) > PLAN_START_TOLERANCE_RAD:
            return None, (f'the plan to {label} starts at {np.round(waypoints[0], 3).tolist()} '
                          f'rad, not where the arm is ({np.round(start, 3).tolist()} rad)')
        waypoints[0] = start
        end_xy = self.kinematics.forward(waypoints[-1])
        if math.dist(end_xy, request.goal.xy) > PLAN_GOAL_TOLERANCE_M:
            return None, (f'the plan to {label} ends at ({end_xy[0]:.3f}, {end_xy[1]:.3f}) m, '
                          'not at the goal')
        escape = len(waypoints) > 2 and not self.forbidden.is_free(start)
        out, rest = (waypoints[:2], waypoints[1:]) if escape else (None, waypoints)
        if len(rest) > 1 and not self.forbidden.path_is_free(rest):
            return None, f'the plan to {label} enters forbidden space: refused'
        # A path that keeps the clearance is bent (when the timing finds a faster shape)
        # only where it keeps it still.
        space = self.clear_space if self.clear_space.path_is_free(rest) else self.forbidden
        velocity = request.start_velocity_rad_s
        if out is None:
            return time_optimal_trajectory(rest, self.dynamics, space, self.limits,
                                           start_velocity_rad_s=velocity, quick=quick), ''
        first = time_optimal_trajectory(out, self.dynamics, Anywhere(), self.limits,
                                        start_velocity_rad_s=velocity)
        second = time_optimal_trajectory(rest, self.dynamics, space, self.limits)
        return ChainedTrajectory([first, second]), ''

    def plan_and_time(self, request: PlanRequest, planner) -> TimedPlan:
        """Plan with ``planner`` in-process and time the plan: each free elbow branch is
        planned (``plan_to_configurations``) and the fastest taken (``fastest_branch``); a
        planner that cannot plan to a configuration chooses the branch itself."""
        started = time.perf_counter()
        if hasattr(planner, 'plan_to_configurations'):
            plan = self.ranking.plan(planner, request.start_q, request.goal.xy)
        else:
            plan = planner.plan(request.start_q, request.goal.xy)
        return replace(self.time_plan(request, plan), compute_s=time.perf_counter() - started)


class BranchRanking:
    """Which of a goal's elbow branches gets there soonest, judged on the arm alone."""

    def __init__(self, arm: ArmConfig):
        self.dynamics = ArmDynamics(arm)
        self.validator = GoalValidator(arm)
        self.forbidden = self.validator.forbidden
        self.clear_space = ForbiddenSpace(arm, arm.world.clearance_rad)
        self.limits = TrajectoryLimits.from_arm(arm)

    def preset_configurations(self) -> list:
        """Every free elbow branch of every preset: the goals a robot keeps going to."""
        return [q for _, x, y in self.validator.arm.presets
                for q in self.validator.free_configurations(x, y)]

    def plan(self, planner, start_q, goal_xy):
        """What the planner node answers: of the goal's free elbow branches, the path
        (``planner.plan_to_configurations``) that gets there soonest; with none free, or
        none timed, the planner's own answer (its reason why not)."""
        try:
            branches = self.validator.free_configurations(*goal_xy)
        except UnreachableError:
            branches = []                  # out of reach: the planner's answer says so
        plans = planner.plan_to_configurations(start_q, branches) if branches else []
        fastest = self.fastest_branch([plan for plan in plans if plan.ok])
        return fastest if fastest is not None else planner.plan(start_q, goal_xy)

    def prove_cells(self, tiles: int | None = None) -> bool:
        """``ForbiddenSpace.prove_cells`` for every space the estimates check (the
        clearance's and the room the bend search keeps), ``tiles`` more at a time (None:
        all); True once all are."""
        return (self.clear_space.prove_cells(tiles)
                and prove_room_cells(self.validator.arm, tiles))

    def duration_s(self, waypoints) -> float:
        """The path's duration from rest to rest, estimated with the first grid of bends
        (``estimated_bent_duration_s``: the bend often decides which branch is faster)."""
        space = self.clear_space if self.clear_space.path_is_free(waypoints) else self.forbidden
        return estimated_bent_duration_s(waypoints, self.dynamics, space, self.limits)

    def fastest_branch(self, plans):
        """Of ``plans`` (each with ``waypoints_rad``), the one that gets there soonest: all
        estimated quickly; when others come within the margin of the best, those are
        estimated with their bend and the fastest of them wins."""
        if len(plans) <= 1:
            return plans[0] if plans else None
        estimates = [estimated_duration_s(p.waypoints_rad, self.dynamics, self.limits)
                     for p in plans]
        best = min(estimates)
        close = [k for k, estimate in enumerate(estimates)
                 if estimate <= best * (1.0 + BRANCH_SCREEN_MARGIN)]
        if len(close) == 1:
            return plans[close[0]]
        duration, index = min((self.duration_s(plans[k].waypoints_rad), k) for k in close)
        return plans[index] if math.isfinite(duration) else None
