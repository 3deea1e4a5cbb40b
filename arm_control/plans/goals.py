"""Goals: which points the arm accepts, and which elbow branch it takes to reach them.

A goal is a point (x, y) in ``arm_base``. It is rejected, with a sentence saying why, when
a coordinate is NaN or infinite, its frame is not ``arm_base`` (or empty), its z is off the
arm's plane by more than 1 mm, it lies outside the reachable annulus
|La − Lb| ≤ √(x² + y²) ≤ La + Lb (unless ``clamp_unreachable_goals``: then it is moved
radially onto the annulus, as GoArmSim did), or every inverse-kinematics branch of it is
forbidden.

The elbow branch is chosen for the motion, not by a quadrant rule: among the branches that
are free, the one that gets there soonest -- by the planner's cost or the trajectory's
duration when one is given, by the least joint travel otherwise.
"""

from dataclasses import dataclass, field
import math
from typing import Callable, Optional, Sequence

import numpy as np

from arm_control.config import ArmConfig, FRAME_ID
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace
from arm_control.text import quote

PLANE_TOLERANCE_M = 0.001        # |z| allowed off the arm's plane
# Clamped points land this far inside the annulus, so rounding cannot push them out again.
CLAMP_MARGIN_M = 1e-6


@dataclass(frozen=True)
class Goal:
    """A validated point to reach, with a label for people (the preset's name, or the point)."""

    x_m: float
    y_m: float
    label: str
    note: str = ''                  # e.g. that it was clamped onto the annulus
    replan: bool = True             # interrupted, planned again (not a client's trajectory)

    @property
    def xy(self) -> tuple[float, float]:
        return (self.x_m, self.y_m)


@dataclass(frozen=True)
class GoalCheck:
    """The verdict on a requested goal: the goal, or the reason it was rejected (a sentence,
    and a few words for counting rejections by kind)."""

    goal: Optional[Goal]
    reason: str = ''
    category: str = ''

    @property
    def ok(self) -> bool:
        return self.goal is not None


@dataclass(frozen=True)
class Branch:
    """One inverse-kinematics solution, as joint angles inside the joints' ranges."""

    name: str                       # 'positive-elbow' or 'negative-elbow'
    q_rad: tuple[float, float]
    forbidden_reason: Optional[str] = None

    @property
    def free(self) -> bool:
        return self.forbidden_reason is None


@dataclass(frozen=True)
class DirectPlan:
    """A straight joint-space path (same fields as the planner's ``Plan``)."""

    ok: bool
    reason: str = ''
    waypoints_rad: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    cost_rad: float = math.inf


def describe_point(x: float, y: float) -> str:
    return f'({x:.3f}, {y:.3f}) m'


def clamp_to_annulus(x: float, y: float, inner_m: float, outer_m: float) -> tuple[float, float]:
    """Move (x, y) radially onto inner ≤ r ≤ outer; the origin goes straight up."""
    radius = math.hypot(x, y)
    if inner_m + CLAMP_MARGIN_M <= radius <= outer_m - CLAMP_MARGIN_M:
        return x, y
    heading = math.atan2(y, x) if radius > 0.0 else math.pi / 2
    target = min(max(radius, inner_m + CLAMP_MARGIN_M), outer_m - CLAMP_MARGIN_M)
    return target * math.cos(heading), target * math.sin(heading)


class GoalValidator:
    """Checks goals against the arm's reach and forbidden space; lists the free branches."""

    def __init__(self, arm: ArmConfig, clamp_unreachable_goals: bool = False):
        self.arm = arm
        self.clamp_unreachable_goals = clamp_unreachable_goals
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.forbidden = ForbiddenSpace(arm)
        # A goal's configuration keeps the clearance: holding there, the arm's overshoot
        # and sensor noise stay out of forbidden space.
        self.clear_space = ForbiddenSpace(arm, arm.world.clearance_rad)

    def check(self, x: float, y: float, z: float = 0.0, frame_id: str = '',
              label: Optional[str] = None) -> GoalCheck:
        """Accept the point as a Goal, or say in a sentence why not."""
        values = (x, y, z)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            return GoalCheck(None, f'goal ({x}, {y}, {z}) has a coordinate that is not a '
                                   'finite number', 'not finite')
        where = label or describe_point(x, y)
        if frame_id not in ('', FRAME_ID):
            return GoalCheck(None, f'goal {where} is in frame {quote(frame_id)}: goals must be '
                                   f"in '{FRAME_ID}' (or leave frame_id empty); there is no TF "
                                   'here to transform it', 'wrong frame')
        if abs(z) > PLANE_TOLERANCE_M:
            return GoalCheck(None, f'goal {where} has z = {z:.4f} m: the arm moves in the '
                                   f'plane z = 0 (within {PLANE_TOLERANCE_M * 1000:.0f} mm)',
                             'off the plane')
        inner, outer = self.kinematics.reach_m
        note = ''
        if not self.kinematics.is_reachable(x, y):
            radius = math.hypot(x, y)
            if not self.clamp_unreachable_goals:
                return GoalCheck(None, f'goal {where} is {radius:.3f} m from the shoulder: out '
                                       f'of reach, the arm reaches {inner:.3f} to {outer:.3f} m',
                                 'out of reach')
            x, y = clamp_to_annulus(x, y, inner, outer)
            note = (f'clamped from {radius:.3f} m onto the reachable annulus at '
                    f'{describe_point(x, y)}')
        branches = self.branches(x, y)
        if not any(branch.free for branch in branches):
            why = '; '.join(f'{b.name}: {b.forbidden_reason}' for b in branches)
            return GoalCheck(None, f'goal {where} is in forbidden space, or within the '
                                   f'{math.degrees(self.clear_space.margin_rad):.1f} deg '
                                   f'clearance of it, on every elbow branch ({why})',
                             'forbidden')
        return GoalCheck(Goal(float(x), float(y), label or describe_point(x, y), note))

    def branches(self, x: float, y: float) -> list[Branch]:
        """Both IK solutions (one when they coincide), mapped into the joints' ranges and
        each marked free or forbidden with the reason."""
        out: list[Branch] = []
        for name, (shoulder, elbow) in zip(('positive-elbow', 'negative-elbow'),
                                           self.kinematics.inverse(x, y)):
            in_range = [self.forbidden.to_joint_range(angle, index)
                        for index, angle in enumerate((shoulder, elbow))]
            if any(angle is None for angle in in_range):
                joint = self.arm.joints[in_range.index(None)]
                bad = (shoulder, elbow)[in_range.index(None)]
                reason = (f'{joint.name} would be at {math.degrees(bad):.1f} deg, outside its '
                          f'limits [{math.degrees(joint.min_angle_rad):.1f}, '
                          f'{math.degrees(joint.max_angle_rad):.1f}] deg')
                q = (float(shoulder), float(elbow))
            else:
                q = (float(in_range[0]), float(in_range[1]))
                reason = self.clear_space.why_forbidden(np.array(q))
            if any(np.allclose(q, other.q_rad, atol=1e-9) for other in out):
                continue                    # on the annulus's edge both branches coincide
            out.append(Branch(name, q, reason))
        return out

    def free_configurations(self, x: float, y: float) -> list[tuple[float, float]]:
        return [branch.q_rad for branch in self.branches(x, y) if branch.free]


def joint_travel_rad(start_q, goal_q) -> float:
    """|Δθa| + |Δθb|: the paper's path cost, for joints that do not wrap."""
    return float(np.sum(np.abs(np.asarray(goal_q, float) - np.asarray(start_q, float))))


def choose_branch(start_q, candidates: Sequence, cost: Optional[Callable] = None):
    """The candidate configuration that gets there soonest, or None when there is none.

    ``cost(q)`` -- the planner's cost or a trajectory's duration -- ranks them when given
    and finite for at least one; it returns None (or inf) for a candidate it cannot reach.
    Otherwise the least joint travel wins.
    """
    candidates = [tuple(float(v) for v in q) for q in candidates]
    if not candidates:
        return None
    if cost is not None:
        costs = [cost(q) for q in candidates]
        ranked = [(c, i) for i, c in enumerate(costs) if c is not None and math.isfinite(c)]
        if ranked:
            return candidates[min(ranked)[1]]
        return None
    return min(candidates, key=lambda q: joint_travel_rad(start_q, q))


class StraightLinePlanner:
    """A planner for worlds where a straight joint-space line is enough (no obstacles in
    the way): the free branch whose straight segment from the start is free and soonest.

    Same call as the graph planner (``plan(start_q, goal_xy)``), so tests and benchmarks
    can run the controller without it; a move that needs a detour gets ``ok=False``.
    """

    def __init__(self, arm: ArmConfig, duration_s: Optional[Callable] = None):
        self.validator = GoalValidator(arm)
        self.forbidden = self.validator.forbidden
        self.duration_s = duration_s        # waypoints -> seconds, to rank branches by time

    def plan(self, start_q, goal_xy) -> DirectPlan:
        start = np.asarray(start_q, float)
        x, y = goal_xy
        if not self.validator.kinematics.is_reachable(x, y):
            return DirectPlan(False, f'goal {describe_point(x, y)} is out of reach')
        reachable = [q for q in self.validator.free_configurations(x, y)
                     if self.forbidden.segment_is_free(start, q)]
        if not reachable:
            return DirectPlan(False, f'no straight joint-space move from {np.round(start, 3)} '
                                     f'rad reaches {describe_point(x, y)} through free space')
        cost = None
        if self.duration_s is not None:
            cost = lambda q: self.duration_s(np.array([start, q]))  # noqa: E731
        best = choose_branch(start, reachable, cost)
        if best is None:
            return DirectPlan(False, f'no timed straight move reaches {describe_point(x, y)}')
        return DirectPlan(True, '', np.array([start, best]), joint_travel_rad(start, best))
