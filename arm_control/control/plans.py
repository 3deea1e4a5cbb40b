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

from collections import OrderedDict
from dataclasses import dataclass, replace
from enum import Enum
import math
import time
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.goals import Goal, GoalValidator
from arm_control.control.motions import ChainedTrajectory
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics, UnreachableError
from arm_control.model.world import ForbiddenSpace
from arm_control.timing import (estimated_bent_duration_s, estimated_duration_s,
                                refined_trajectory, time_optimal_trajectory, Trajectory,
                                TrajectoryError, TrajectoryLimits)
from arm_control.timing.shaping import prove_room_cells

# Branches whose quick estimate is within this fraction of the best one's are timed in full.
BRANCH_SCREEN_MARGIN = 0.25
# A request is one worked out ahead (``PresetAnswers``), or finds a kept trajectory
# (``KeptTrajectories``: its path's waypoints too), when its start is within this of that
# one's (the pose it travels as rounds the angles) and its goal within this.
SAME_START_RAD = 1e-6
SAME_GOAL_M = 1e-9
# Fine trajectories from rest kept for goals that come again along the same path (besides
# those between presets, kept for good).
KEPT_TRAJECTORIES = 128
# The first waypoint of a plan may differ from the requested start by rounding only ...
PLAN_START_TOLERANCE_RAD = 0.01
# ... and its last must put the tool on the goal.
PLAN_GOAL_TOLERANCE_M = 0.002


@dataclass(frozen=True)
class PlanRequest:
    """Plan a path from ``start_q`` to ``goal``; the motion starts at ``start_time_s`` moving
    at ``start_velocity_rad_s`` (a preempted motion) or, when None, on acceptance at rest."""

    request_id: int
    goal: Goal
    start_q: tuple[float, float]
    start_velocity_rad_s: tuple[float, float]
    start_time_s: Optional[float]
    sent_time_s: float
    lead_s: float = 0.1


@dataclass(frozen=True)
class PathPlan:
    """A planner's answer as the timing takes it: joint waypoints, or the reason there are
    none (the planner's own ``Plan`` has the same fields)."""

    waypoints_rad: np.ndarray
    reason: str = ''

    @property
    def ok(self) -> bool:
        return not self.reason


@dataclass(frozen=True)
class TimedPlan:
    """A request's answer: a checked, timed trajectory, or the reason there is none.

    ``compute_s``: the CPU time of the timing; ``answered_s``: when the planner answered
    (NaN: in-process, no round trip); ``received_s``: when the core got it (the node's
    clock) -- where a goal's time goes, before the arm moves. ``handover_s`` (NaN: none):
    this answer refines the motion taken for the same request, from this long after that
    motion's start. ``kept``: the fine trajectory kept from an earlier goal along the same
    path (``KeptTrajectories``), which needs no refinement.
    """

    request: PlanRequest
    trajectory: object = None
    reason: str = ''
    compute_s: float = 0.0
    answered_s: float = math.nan
    received_s: float = math.nan
    handover_s: float = math.nan
    kept: bool = False

    @property
    def ok(self) -> bool:
        return self.trajectory is not None


class Anywhere:
    """Free space everywhere: for timing the way out of forbidden space, which the arm is
    already in (the planner's first leg from a start pushed there)."""

    def is_free(self, q):
        free = np.ones(np.asarray(q, float).shape[:-1], dtype=bool)
        return bool(free) if free.ndim == 0 else free


class KeptTrajectories:
    """Fine trajectories from rest, kept for the goals that come again along the same path, as
    6328 keeps its preset-to-preset trajectories: a robot's goals come again and again, and
    the fine trajectory then needs no quick start and no hand-over. A request finds one for
    its very goal whose start and path's waypoints are the kept one's to within rounding:
    the start it is asked from is the last motion's end, which went to the planner and back
    as a tool pose. Those between presets are ``pinned`` (kept for good); of the others the
    ``size`` used last."""

    def __init__(self, size: int = KEPT_TRAJECTORIES):
        self.size = size
        self._pinned = {}                   # goal (x, y) -> [(start, waypoints, trajectory)]
        self._recent = OrderedDict()        # the same, the goal used last at the end

    def __len__(self) -> int:
        return sum(len(entries) for store in (self._pinned, self._recent)
                   for entries in store.values())

    @staticmethod
    def keepable(request: PlanRequest, plan) -> bool:
        """A plan from rest that has a path."""
        return request.start_time_s is None and plan is not None and plan.ok

    def find(self, request: PlanRequest, plan, touch: bool = True):
        """The trajectory kept for ``request`` along ``plan``, or None; ``touch``: counts as
        used."""
        if not self.keepable(request, plan):
            return None
        start = np.asarray(request.start_q, float)
        waypoints = np.asarray(plan.waypoints_rad, float)
        goal = request.goal.xy
        for store in (self._pinned, self._recent):
            for kept_start, kept_waypoints, trajectory in store.get(goal, ()):
                if (kept_waypoints.shape == waypoints.shape
                        and np.max(np.abs(kept_start - start)) <= SAME_START_RAD
                        and np.max(np.abs(kept_waypoints - waypoints)) <= SAME_START_RAD):
                    if touch and store is self._recent:
                        self._recent.move_to_end(goal)
                    return trajectory
        return None

    def add(self, request: PlanRequest, plan, trajectory, pinned: bool = False) -> None:
        if trajectory is None or self.find(request, plan, touch=False) is not None:
            return
        store = self._pinned if pinned else self._recent
        store.setdefault(request.goal.xy, []).append(
            (np.asarray(request.start_q, float), np.array(plan.waypoints_rad, float),
             trajectory))
        if pinned:
            return
        self._recent.move_to_end(request.goal.xy)
        while sum(len(entries) for entries in self._recent.values()) > self.size:
            oldest = next(iter(self._recent))
            self._recent[oldest].pop(0)
            if not self._recent[oldest]:
                del self._recent[oldest]


def preset_pairs(validator: GoalValidator) -> list:
    """(start configuration, goal (x, y)) of every move between two presets: each free elbow
    branch of each preset as the start, toward every other preset."""
    presets = [(x, y) for _, x, y in validator.arm.presets]
    return [(start_q, goal_xy)
            for x, y in presets
            for start_q in validator.free_configurations(x, y)
            for goal_xy in presets if goal_xy != (x, y)]


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
        self.kept = KeptTrajectories()

    def time_plan(self, request: PlanRequest, plan, quick: bool = False) -> TimedPlan:
        """Check ``plan`` (anything with ``ok``, ``reason`` and ``waypoints_rad``) against the
        request and time it; ``quick``: from rest, on few stages and not bent (``refine``
        makes it better from a little later) -- or, for a goal that comes again from rest
        along the same path, the fine trajectory kept from the last time (``kept``)."""
        started = time.perf_counter()
        kept = self.kept.find(request, plan)
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


class PresetAnswers:
    """The planner node's answers between presets, worked out before they are asked for, as
    6328 keeps its preset-to-preset trajectories: a robot goes from preset to preset, and its
    arm rests on the very configuration the last answer ended on, so the next goal from there
    finds its answer ready instead of searching (tens of ms on a robot's world).

    ``pending`` lists what is left to work out (each preset branch as a start, toward every
    other preset), ``prepare_next`` works out one; ``plan`` answers any request, from the
    store when its start and goal are one of these."""

    def __init__(self, ranking: BranchRanking, planner):
        self.ranking, self.planner = ranking, planner
        self.pending = preset_pairs(ranking.validator)
        self._answers = []                     # (start_q, goal_xy, plan)

    @property
    def ready(self) -> int:
        return len(self._answers)

    def prepare_next(self) -> None:
        start_q, goal_xy = self.pending.pop(0)
        plan = self.ranking.plan(self.planner, start_q, goal_xy)
        self._answers.append((np.asarray(start_q, float), goal_xy, plan))

    def plan(self, start_q, goal_xy):
        """The answer ``BranchRanking.plan`` gives, from the store when it holds it."""
        start_q = np.asarray(start_q, float)
        for start, goal, plan in self._answers:
            apart = np.angle(np.exp(1j * (start - start_q)))     # a pose's angles may wrap
            if (np.max(np.abs(apart)) <= SAME_START_RAD
                    and math.dist(goal, goal_xy) <= SAME_GOAL_M):
                return plan
        return self.ranking.plan(self.planner, start_q, goal_xy)


class PlanHandoff:
    """The goal being planned: its request, when it must be answered, and what an answer
    means for the arm."""

    def __init__(self, planner_timeout_s: float):
        self.planner_timeout_s = planner_timeout_s
        self.pending: Optional[PlanRequest] = None
        self._outbox: list[PlanRequest] = []
        self._next_id = 1
        self.started_s = math.nan
        self.last: Optional[TimedPlan] = None

    def start(self, now_s: float) -> None:
        """A goal becomes current: it must have a plan within the planner timeout."""
        self.started_s = now_s

    @property
    def deadline_s(self) -> float:
        return self.started_s + self.planner_timeout_s

    def ask(self, now_s: float, goal: Goal, start_q, start_velocity_rad_s,
            start_time_s: Optional[float], lead_s: float) -> None:
        request = PlanRequest(self._next_id, goal, (float(start_q[0]), float(start_q[1])),
                              tuple(float(v) for v in start_velocity_rad_s), start_time_s,
                              now_s, lead_s)
        self._next_id += 1
        self.pending, self._outbox = request, [request]

    @property
    def waiting(self) -> bool:
        """Requests not yet taken."""
        return bool(self._outbox)

    def take(self) -> list[PlanRequest]:
        """Requests to send to the planner (each once)."""
        out, self._outbox = self._outbox, []
        return out

    def drop(self) -> None:
        self.pending, self._outbox = None, []

    def overdue(self, now_s: float) -> bool:
        return self.pending is not None and now_s > self.deadline_s

    def answer(self, now_s: float, timed: TimedPlan, idle_from_s: float) -> 'PlanAnswer':
        """What ``timed`` means now (see ``Verdict``). ``idle_from_s``: when the current
        motion ends (a plan from rest begins then at the earliest)."""
        request = timed.request
        if self.pending is None or request.request_id != self.pending.request_id:
            return PlanAnswer(Verdict.IGNORE)
        self.pending, self.last = None, timed
        if not timed.ok:
            return PlanAnswer(Verdict.FAIL, reason=timed.reason)
        if request.start_time_s is None:
            return PlanAnswer(Verdict.TAKE, begin_s=max(now_s, idle_from_s))
        if now_s <= request.start_time_s:
            return PlanAnswer(Verdict.TAKE, begin_s=request.start_time_s)
        if now_s + 2.0 * request.lead_s > self.deadline_s:
            return PlanAnswer(Verdict.FAIL, reason=f'the plan for {request.goal.label} came '
                                                   'too late to take over the moving arm')
        return PlanAnswer(Verdict.RETRY, lead_s=2.0 * request.lead_s)


class Verdict(Enum):
    IGNORE = 'ignore'   # an answer to an older request
    FAIL = 'fail'       # no plan, or one too late to take over the moving arm: ``reason``
    RETRY = 'retry'     # too late to take over, but there is time to ask again: ``lead_s``
    TAKE = 'take'       # the plan begins at ``begin_s``


@dataclass(frozen=True)
class PlanAnswer:
    verdict: Verdict
    begin_s: float = math.nan
    lead_s: float = math.nan
    reason: str = ''
