"""What the planning tests check a plan with: the FRC robot's file, the 0.1 deg check step, a
free path's properties, the highest point along a path."""

import math
from pathlib import Path

import numpy as np
import pytest

from arm_control.planning.plan import travel_rad


FRC_FILE = Path(__file__).resolve().parents[2] / 'config' / 'frc_robot.yaml'
CHECK_STEP_RAD = math.radians(0.1)          # every returned path is checked at this step


def presets(planner):
    return {name: (x, y) for name, x, y in planner.arm.presets}


def assert_free_path(planner, plan, start=None, goal=None):
    """The plan's path is free at 0.1°, inside the joint travel, from start to goal."""
    assert plan.ok, plan.reason
    path = plan.waypoints_rad
    assert path.ndim == 2 and path.shape[1] == 2 and len(path) >= 2
    assert planner.forbidden.path_is_free(path, CHECK_STEP_RAD)
    assert plan.cost_rad == pytest.approx(travel_rad(path))
    if start is not None:
        np.testing.assert_allclose(path[0], start, atol=1e-12)
    if goal is not None:
        np.testing.assert_allclose(path[-1], goal, atol=1e-12)


def highest_point_m(planner, path, step_rad=CHECK_STEP_RAD):
    """The highest y any point of the arm reaches along a joint-space path."""
    samples = []
    for a, b in zip(path[:-1], path[1:]):
        count = int(np.ceil(np.max(np.abs(b - a)) / step_rad)) + 2
        samples.append(a + np.linspace(0.0, 1.0, count)[:, None] * (b - a))
    q = np.concatenate(samples)
    kinematics = planner.kinematics
    y_elbow = kinematics.upper_m * np.sin(q[:, 0])
    y_tool = y_elbow + kinematics.fore_m * np.sin(q[:, 0] + q[:, 1])
    return float(max(y_elbow.max(), y_tool.max()))


# The grid
