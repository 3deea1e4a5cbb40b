"""A client's joint trajectory as one more motion of the core: followed in closed loop with
the simulated arm like a planned one, reached, and ended by the same safety rules."""

import math

from controller_rig import Rig
import numpy as np
import pytest
from trajectory_checks import moveit_style, request

from arm_control.control.motions import Motion
from arm_control.control.state_machine import ArmState
from arm_control.parameters import read_parameter_files
from arm_control.plans.goals import Goal
from arm_control.plans.trajectory_goals import FollowSettings, TrajectoryGoals

DEG = math.pi / 180.0


@pytest.fixture(scope='module')
def goals(arm, controller_config):
    settings = FollowSettings.from_parameters(read_parameter_files((), 'controller'))
    return TrajectoryGoals(arm, controller_config, settings)


def settled(rig, seconds=0.5):
    rig.run(seconds)
    assert rig.core.state in (ArmState.WAITING, ArmState.HOLDING)


def follow(rig, goals, rows):
    """Hand the rows to the core as the node does: checked from the setpoint, then followed."""
    core = rig.core
    prepared = goals.prepare(request(('shoulder', 'elbow'), rows), rig.now,
                             lambda t: core._reference(t))
    motion = Motion(prepared.trajectory, prepared.begin_s)
    x, y = core.kinematics.forward(prepared.final_q)
    accepted, _ = core.goals.follow(rig.now, Goal(x, y, 'trajectory', replan=False), motion)
    assert accepted
    return motion


def test_a_moveit_style_trajectory_is_tracked_closely_and_reached(arm, controller_config,
                                                                  goals):
    rig = Rig(arm, controller_config)
    settled(rig)
    start = rig.core.last_step.setpoint[0].copy()
    rows = moveit_style(start, (1.0, -0.6), 2.5, count=25)
    motion = follow(rig, goals, rows)
    assert rig.core.state == ArmState.TRACKING
    errors = []
    rig.observers.append(lambda loop, reading, voltage: errors.append(
        np.abs(loop.true_q - motion.sample(loop.now)[0])))
    assert rig.run(4.0, until=rig.in_state(ArmState.HOLDING))
    worst = np.max(errors, axis=0)
    # Tracked within 1 deg on both joints the whole way, and arrived at the last point.
    assert np.all(worst < 1.0 * DEG), np.degrees(worst)
    assert np.all(np.abs(rig.true_q - (1.0, -0.6)) <= controller_config.goal_tolerance_rad)
    assert rig.core.goals.counts['reached'] == 1


def test_an_estop_ends_the_trajectory_and_it_is_not_planned_again(arm, controller_config,
                                                                  goals):
    rig = Rig(arm, controller_config)
    settled(rig)
    start = rig.core.last_step.setpoint[0].copy()
    motion = follow(rig, goals, moveit_style(start, (1.0, -0.6), 2.5))
    rig.run(0.5)
    rig.core.estop(rig.now)
    assert rig.core.setpoints.timeline.last is not motion
    rig.run(1.0)
    rig.core.reset(rig.now)
    rig.run(1.0)
    assert rig.core.state == ArmState.WAITING and not rig.core.pending_goals()


def test_a_push_off_the_trajectory_leaves_it_without_planning_it_again(arm, controller_config,
                                                                       goals):
    rig = Rig(arm, controller_config)
    settled(rig)
    start = rig.core.last_step.setpoint[0].copy()
    motion = follow(rig, goals, moveit_style(start, (1.0, -0.6), 2.5))
    rig.run(0.3)
    rig.plant.state[0] += 0.3                        # pushed 17 deg
    rig.run(1.0)
    assert rig.core.setpoints.timeline.last is not motion
    assert not rig.core.pending_goals()


def test_a_trajectory_is_refused_while_a_driver_is_in_charge(arm, controller_config, goals):
    rig = Rig(arm, controller_config)
    settled(rig)
    rig.core.driver_command(rig.now, 0.1, 0.0)
    rig.run(0.1)
    assert rig.core.state == ArmState.DRIVER
    core = rig.core
    prepared = goals.prepare(request(('shoulder', 'elbow'), [(2.0, (1.2, -1.0))]), rig.now,
                             lambda t: core._reference(t))
    accepted, _ = core.goals.follow(rig.now, Goal(1.0, 1.0, 'trajectory', replan=False),
                                    Motion(prepared.trajectory, prepared.begin_s))
    assert not accepted and core.state == ArmState.DRIVER
