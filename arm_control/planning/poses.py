"""A plan travels as tool poses (nav_msgs/GetPlan's Path, x, y, yaw = shoulder + elbow): joint
waypoints to poses, and back to continuous joint angles inside each joint's travel."""

import math

import numpy as np

from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace


def poses_from_waypoints(kinematics: TwoLinkKinematics,
                         waypoints_rad) -> list[tuple[float, float, float]]:
    """Each waypoint's tool pose (x, y, yaw), yaw = shoulder + elbow wrapped to [−π, π)."""
    return [tuple(float(v) for v in kinematics.tool_pose(q))
            for q in np.asarray(waypoints_rad, dtype=float).reshape(-1, 2)]


def _unwrapped(angle: float, near: float, low: float, high: float) -> float:
    """angle + 2πk inside [low, high] nearest ``near``; without one, nearest ``near``."""
    turn = 2.0 * math.pi
    k_low, k_high = math.ceil((low - angle) / turn), math.floor((high - angle) / turn)
    if k_low <= k_high:
        k = min(max(round((near - angle) / turn), k_low), k_high)
    else:
        k = round((near - angle) / turn)
    return angle + turn * k


def waypoints_from_poses(kinematics: TwoLinkKinematics, poses, start_q,
                         forbidden: ForbiddenSpace) -> np.ndarray:
    """Tool poses (x, y, yaw) back to continuous joint angles, (N, 2).

    Each angle is taken by whole turns into its joint's travel, nearest the previous
    waypoint (``start_q`` for the first); an angle with no turn inside the travel (a start
    pushed past a hard stop) stays nearest the previous one.
    """
    previous = np.asarray(start_q, dtype=float).ravel()
    out = []
    for x, y, yaw in poses:
        q = kinematics.configuration_from_pose(x, y, yaw)
        q = [_unwrapped(q[k], previous[k], *forbidden.limits[k]) for k in range(2)]
        out.append(q)
        previous = np.array(q)
    return np.array(out, dtype=float).reshape(-1, 2)
