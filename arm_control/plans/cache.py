"""Answers worked out before they are asked for: what makes a robot's repeated goals quick.

A robot goes from preset to preset, again and again, so most goals have been seen before.
``PlanCache`` is the one place that says which of the speed mechanisms serves a goal, and
when each is filled; none is ever waited for. A request is one stored when its start is the
stored one's to within rounding (the pose it travelled as) and its goal the same point:
``SAME_START_RAD``, ``SAME_GOAL_M``.
"""

from collections import OrderedDict
from enum import Enum
import math

import numpy as np

from arm_control.plans.goals import GoalValidator
from arm_control.plans.messages import PlanRequest

# A request is one worked out ahead (``PresetAnswers``), or finds a kept trajectory
# (``KeptTrajectories``: its path's waypoints too), when its start is within this of that
# one's (the pose it travels as rounds the angles) and its goal within this.
SAME_START_RAD = 1e-6
SAME_GOAL_M = 1e-9
# Fine trajectories from rest kept for goals that come again along the same path (besides
# those between presets, kept for good).
KEPT_TRAJECTORIES = 128


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


class PresetAnswers:
    """The planner node's answers between presets, worked out before they are asked for, as
    6328 keeps its preset-to-preset trajectories: a robot goes from preset to preset, and its
    arm rests on the very configuration the last answer ended on, so the next goal from there
    finds its answer ready instead of searching (tens of ms on a robot's world).

    ``pending`` lists what is left to work out (each preset branch as a start, toward every
    other preset), ``prepare_next`` works out one; ``plan`` answers any request, from the
    store when its start and goal are one of these. ``ranking``: a ``timer.BranchRanking``."""

    def __init__(self, ranking, planner):
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


class Serves(Enum):
    """Which mechanism answers a request in the worker (``PlanCache.serves``)."""

    KEPT = 'kept'                   # the fine trajectory kept from rest: at once, final
    QUICK_THEN_FINE = 'quick'       # from rest, not kept: quick now, refined from a hand-over
    AT_ONCE = 'at once'             # a moving start (or no path): timed finely, once


class PlanCache:
    """The speed mechanisms, and which serves when. This object is the plan worker's side
    (a ``PlanTimer``'s ``cache``: ``serves``, ``trajectory``, ``keep``); the planner node
    holds its side beside its graph: the trees in its ``Planner``, the answers between
    presets in a ``PresetAnswers``.

    ====================  ======================================  ============================
    mechanism             serves                                  when it works (where)
    ====================  ======================================  ============================
    preset trees          a path to or from a preset, read off a  after start, one tree a tick
                          shortest-path tree: no search           while idle (planner node,
                                                                  ``Planner.prepare``)
    ``PresetAnswers``     the branch-ranked path between two      after the trees, one a tick
                          presets, whole                          while idle (planner node)
    ``KeptTrajectories``  a goal from rest along a path timed     by the keeper (plan worker,
                          before: its fine trajectory at once,    ``cache``)
                          final (``Serves.KEPT``)
    the keeper            fills ``KeptTrajectories``: each path   only while the arm holds,
                          answered from rest, then every path     SIGSTOPped otherwise (its
                          between presets once the arm has had    own process at nice 10,
                          no goal for a while                     ``worker.Keeper``)
    quick -> refine       a goal from rest not kept: a quick      each such request (plan
                          trajectory at once, the fine one takes  worker, ``worker.answer``)
                          over at a hand-over time
                          (``Serves.QUICK_THEN_FINE``)
    ====================  ======================================  ============================

    A goal that preempts a moving arm is timed finely at once (``Serves.AT_ONCE``): the
    mechanisms above are for goals from rest.
    """

    def __init__(self, kept: KeptTrajectories | None = None):
        self.kept = KeptTrajectories() if kept is None else kept

    def serves(self, request: PlanRequest, plan) -> Serves:
        if not KeptTrajectories.keepable(request, plan):
            return Serves.AT_ONCE
        return Serves.KEPT if self.kept.find(request, plan, touch=False) is not None \
            else Serves.QUICK_THEN_FINE

    def trajectory(self, request: PlanRequest, plan):
        """The fine trajectory kept for ``request`` along ``plan``, or None."""
        return self.kept.find(request, plan)

    def has(self, request: PlanRequest, plan) -> bool:
        return self.kept.find(request, plan, touch=False) is not None

    def keep(self, request: PlanRequest, plan, trajectory, pinned: bool = False) -> None:
        """Keep the keeper's fine ``trajectory``; ``pinned``: for good (between presets)."""
        self.kept.add(request, plan, trajectory, pinned)

    def __len__(self) -> int:
        return len(self.kept)
