"""What passes between the controller's core, the planner, the plan worker and its keeper.

A goal's plan is asked for with a ``PlanRequest``, the planner's path comes as a
``PathPlan`` and the timed answer as a ``TimedPlan``. Between the processes each message is
a type of its own, so a reader dispatches on the type (``match``) and a new
kind cannot be mistaken for an old one. They go as pickles over the processes' pipes.

Node -> worker: ``Settings`` first and on every change, then ``TimePlan`` per plan;
``KeepPath`` and ``Keeping`` are for the keeper alone; ``None`` (the pipe's end) stops it.
Worker -> node: ``TimedPlan`` answers, ``Done`` when a request has had all
of them, ``Kept`` counts the trajectories kept, ``Ready`` once warm.
Worker -> keeper: ``KeeperSettings``, ``KeeperJob``; keeper -> worker: ``KeeperResult``.
A ``generation`` numbers the settings: what was timed with older ones is dropped.
"""

from dataclasses import dataclass
import math
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.plans.goals import Goal


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


@dataclass(frozen=True)
class Settings:
    arm: ArmConfig
    config: ControllerConfig


@dataclass(frozen=True)
class TimePlan:
    request: PlanRequest
    plan: PathPlan


@dataclass(frozen=True)
class KeepPath:
    """A path between presets, timed finely from rest before anyone asks for it."""

    request: PlanRequest
    plan: PathPlan


@dataclass(frozen=True)
class Keeping:
    """Whether the keeper may work now (the arm holds) or must stop (a goal is under way)."""

    allowed: bool


@dataclass(frozen=True)
class Ready:
    pass


@dataclass(frozen=True)
class Done:
    request_id: int


@dataclass(frozen=True)
class Kept:
    count: int


@dataclass(frozen=True)
class KeeperSettings:
    generation: int
    settings: Settings


@dataclass(frozen=True)
class KeeperJob:
    generation: int
    request: PlanRequest
    plan: PathPlan
    pinned: bool            # kept for good (a preset's path), not only while it is used


@dataclass(frozen=True)
class KeeperResult:
    generation: int
    request: PlanRequest
    plan: PathPlan
    trajectory: object      # the fine Trajectory from rest
    pinned: bool
