"""Line-of-sight shortcuts of a grid path: by the triangle inequality a shortcut never costs
more joint travel, and each is checked with ``ForbiddenSpace.segment_is_free``."""

import numpy as np

from arm_control.model.world import ForbiddenSpace
from arm_control.planning.graph import segments_free

# A segment is first sampled this many times more coarsely: most blocked ones fail there.
COARSE_FACTOR = 10
# ... and a shortcut candidate before that, this many times.
SIGHT_FACTOR = 30
# Shortcut candidates that pass the coarse check are checked finely, farthest first, this
# many, each first at a step this many times coarser (a grazing segment fails there).
MAX_FINE_CHECKS = 6
MIDDLE_FACTOR = 3
# At most this many corners ahead are tried from each kept waypoint.
MAX_CANDIDATES = 24


def segment_is_free(forbidden: ForbiddenSpace, q_from, q_to,
                    coarse_factor: float = COARSE_FACTOR) -> bool:
    """``ForbiddenSpace.segment_is_free`` at ``check_step_rad``, after a pass at a
    ``coarse_factor`` times coarser step that rejects most blocked segments for a
    fraction of the cost (a forbidden sample is forbidden at any step)."""
    step = forbidden.check_step_rad
    coarse = forbidden.segment_is_free(q_from, q_to, coarse_factor * step)
    return coarse and forbidden.segment_is_free(q_from, q_to, step)


def shortcut(forbidden: ForbiddenSpace, path: np.ndarray) -> np.ndarray | None:
    """Drop the waypoints a checked straight segment can skip.

    From each kept waypoint, jump to the farthest corner of the grid path in sight: the
    corners ahead (up to ``MAX_CANDIDATES``, evenly spread) are tried at once at a coarse
    step (a forbidden sample is forbidden at any step), then the farthest that passed is
    checked with ``ForbiddenSpace.segment_is_free`` at ``check_step_rad``, after a pass
    at ``MIDDLE_FACTOR`` times that step. With none in sight, the next
    grid step (checked when the grid path was found) is kept.
    """
    step = forbidden.check_step_rad
    last = len(path) - 1
    moves = np.diff(path, axis=0)
    corners = np.flatnonzero(np.any(np.abs(np.diff(moves, axis=0)) > 1e-12, axis=1)) + 1
    corners = np.append(corners, last)
    kept, unchecked = [0], []
    while kept[-1] < last:
        anchor = kept[-1]
        ahead = corners[corners > anchor + 1]
        if len(ahead) > MAX_CANDIDATES:               # evenly spread, the last included
            ahead = ahead[np.linspace(0, len(ahead) - 1, MAX_CANDIDATES).round().astype(int)]
        for factor in (SIGHT_FACTOR, COARSE_FACTOR):     # coarsest first: cheap misses
            ahead = ahead[segments_free(forbidden, np.broadcast_to(
                path[anchor], (len(ahead), 2)), path[ahead], factor * step)]
        in_sight = ahead
        chosen = anchor + 1
        for corner in in_sight[::-1][:MAX_FINE_CHECKS]:
            if segment_is_free(forbidden, path[anchor], path[corner], MIDDLE_FACTOR):
                chosen = int(corner)
                break
        if chosen == anchor + 1:
            unchecked.append(anchor)
        kept.append(chosen)
    # The grid steps kept were checked with the same samples up to rounding; recheck them
    # with the function a caller would use, and fall back to the whole grid path if not.
    if all(forbidden.segment_is_free(path[a], path[a + 1], step) for a in unchecked):
        return path[kept]
    return path if forbidden.path_is_free(path, step) else None
