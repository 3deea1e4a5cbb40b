"""Planners the planning tests share, built once a module."""

from planning_checks import FRC_FILE
import pytest

from arm_control import config
from arm_control.planning.planner import Planner


@pytest.fixture(scope='module')
def frc():
    """The competition robot's arm and a planner on it at the file's resolution (1°)."""
    arm, planner_config = config.load('planner', FRC_FILE)
    return Planner(arm, planner_config)


@pytest.fixture(scope='module')
def seed_planner(arm):
    return Planner(arm, config.load('planner')[1])
