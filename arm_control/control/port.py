"""What the core gives back: a ``Step`` each control period, ``News`` for whoever publishes.

Callers read fields, never the core's parts: the volts to apply, the state, the estimate and
setpoint, the events said and the plan requests handed on (``ArmController.step`` and
``ArmController.take_news``).
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np

from arm_control.control.events import Event
from arm_control.control.state_machine import ArmState
from arm_control.plans.goals import Goal
from arm_control.plans.messages import PlanRequest


@dataclass(frozen=True, eq=False)
class Step:
    """One control period: [Va, Vb] to apply until the next, and what they came from."""

    volts: np.ndarray                     # [Va, Vb]
    state: ArmState
    unpowered: bool                       # stopped at 0 V (e-stopped, disabled, in error)
    estimate: Optional[np.ndarray]        # [θa, θb, ωa, ωb]; None before the first reading
    setpoint: tuple                       # (q, q̇, q̈) the arm is made to follow, rad
    tracking_error_rad: np.ndarray        # model's q − estimated q, per joint
    feedforward_v: np.ndarray
    feedback_v: np.ndarray
    events: tuple[Event, ...]             # said during this step (still in the log to take)
    plan_requests: tuple[PlanRequest, ...]    # handed to the core's ``Planning`` in this step
    queue_version: int                    # changes whenever the goal queue does
    goal_q: Optional[np.ndarray]          # where the goal's motion ends, rad; None: no goal


@dataclass(frozen=True)
class News:
    """What changed for people to hear, taken once: events, the state, the goal queue (the
    current goal first) and its version."""

    events: tuple[Event, ...]
    state: ArmState
    goals: tuple[Goal, ...]
    queue_version: int
