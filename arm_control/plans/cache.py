"""Answers worked out before they are asked for: what makes a robot's repeated goals quick.

A robot goes from preset to preset, again and again, so most goals have been seen before.
Five things serve them, each where its work is done; none is ever waited for:

- preset trees (``planning/trees.py``, the planner node): shortest-path trees toward each
  preset, built one a tick while the planner idles after start; a path to a preset from
  anywhere is then read off a tree instead of searched.
- ``PresetAnswers`` (the planner node): the whole answer to each request between two
  presets, worked out after the trees, one a tick while the planner idles.
- quick then refined (the plan worker, ``PlanTimer``): a goal from rest is answered at once
  with a quick timing the arm starts on; the fine one takes over at a hand-over time.
- ``KeptTrajectories`` (the plan worker): the fine trajectory from rest of a path timed
  before, answered at once with nothing to refine.
- the keeper (a process of the worker's, at nice 10, SIGSTOPped while a goal is planned or
  followed): times finely the paths answered from rest and, once the arm has had no goal for
  a while, those between presets, and fills ``KeptTrajectories``.

A request is one of these when its start is the stored one's to within rounding (the pose
it travelled as) and its goal the same point: ``SAME_START_RAD``, ``SAME_GOAL_M``.
"""

from collections import OrderedDict
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
