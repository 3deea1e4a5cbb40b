"""A planned path in joint space, or the reason there is none; its travel Σ(|Δθa| + |Δθb|)."""

from dataclasses import dataclass
from enum import Enum
import math
from typing import Optional

import numpy as np


class NoPlan(str, Enum):
    """Why there is no plan."""

    BAD_INPUT = 'bad_input'                 # a start or goal not finite
    OUT_OF_REACH = 'out_of_reach'           # the goal point beyond the arm's annulus
    FORBIDDEN_GOAL = 'forbidden_goal'       # the goal in forbidden space (on every branch)
    SEPARATED = 'separated'                 # forbidden space parts the start from the goal
    NO_CONNECTION = 'no_connection'         # the grid finds no way (narrow, boxed in, ...)

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True, eq=False)
class Plan:
    """A path in joint space, or the reason there is none.

    Waypoints are continuous angles inside the joint travel, joined by straight segments
    that never enter forbidden space -- except a start pushed into it (even past a hard
    stop), whose first segment is the shortest way out.
    """

    waypoints_rad: np.ndarray   # (N, 2) start -> goal, continuous angles; (0, 2) when no plan
    reason: str                 # '' on success, else a sentence a user understands
    cost_rad: float             # Σ(|Δθa| + |Δθb|) along the waypoints (inf when no plan)
    why: Optional[NoPlan] = None    # None on success

    @property
    def ok(self) -> bool:
        return not self.reason

    @classmethod
    def failure(cls, reason: str, why: NoPlan) -> 'Plan':
        return cls(np.zeros((0, 2)), reason, math.inf, why)

    @classmethod
    def through(cls, waypoints) -> 'Plan':
        """A plan along ``waypoints``, repeated points dropped (no zero-length segments,
        but always a start and a goal, equal when the arm is already there)."""
        waypoints = np.array(waypoints, dtype=float).reshape(-1, 2)
        moved = np.concatenate([[True], np.any(np.diff(waypoints, axis=0) != 0.0, axis=1)])
        waypoints = waypoints[moved] if np.count_nonzero(moved) >= 2 else waypoints[[0, -1]]
        waypoints.setflags(write=False)
        return cls(waypoints, '', travel_rad(waypoints))


def travel_rad(waypoints) -> float:
    """Σ(|Δθa| + |Δθb|) along a polyline in joint space."""
    waypoints = np.asarray(waypoints, dtype=float).reshape(-1, 2)
    return float(np.abs(np.diff(waypoints, axis=0)).sum())
