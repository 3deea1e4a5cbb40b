"""A planned path in joint space, or the reason there is none; its travel Σ(|Δθa| + |Δθb|)."""

from dataclasses import dataclass
import math

import numpy as np


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

    @property
    def ok(self) -> bool:
        return not self.reason

    @classmethod
    def failure(cls, reason: str) -> 'Plan':
        return cls(np.zeros((0, 2)), reason, math.inf)

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
