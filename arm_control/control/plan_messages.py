"""What passes between the controller node, its plan worker and the worker's keeper.

Each message is a type of its own, so a reader dispatches on the type (``match``) and a new
kind cannot be mistaken for an old one. They go as pickles over the processes' pipes.

Node -> worker: ``Settings`` first and on every change, then ``TimePlan`` per plan;
``KeepPath`` and ``Keeping`` are for the keeper alone; ``None`` (the pipe's end) stops it.
Worker -> node: ``TimedPlan`` (``plans.py``) answers, ``Done`` when a request has had all
of them, ``Kept`` counts the trajectories kept, ``Ready`` once warm.
Worker -> keeper: ``KeeperSettings``, ``KeeperJob``; keeper -> worker: ``KeeperResult``.
A ``generation`` numbers the settings: what was timed with older ones is dropped.
"""

from dataclasses import dataclass

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.plans import PathPlan, PlanRequest


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
