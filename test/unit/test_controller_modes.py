"""Driver mode, every transition of the state machine taken by the real controller, and
settings changed at run time, in closed loop with the simulated arm."""

import dataclasses
import math

from controller_rig import DEG, reading_at, Rig, START
import numpy as np
import pytest

from arm_control.control.controller import ArmController
from arm_control.control.state_machine import ArmState, TRANSITIONS, Trigger


# --- driver mode -----------------------------------------------------------------------------

def test_driver_mode_moves_the_tool_at_the_commanded_velocity(arm, controller_config):
    rig = Rig(arm, controller_config)
    rig.run(0.2)
    for _ in range(50):                                 # 1 s at 0.3 m/s forward
        rig.core.driver_command(rig.now, 0.3, 0.0)
        rig.step()
    q, qd, _ = rig.core.last_step.setpoint
    tool_velocity = rig.kinematics.jacobian(q) @ qd
    assert tool_velocity == pytest.approx((0.3, 0.0), abs=0.01)
    assert rig.core.state == ArmState.DRIVER


def test_driver_mode_stops_short_of_the_floor_and_holds(arm, controller_config):
    rig = Rig(arm, controller_config, start=(0.8, -1.2))
    rig.run(0.2)
    for _ in range(150):                                # 3 s of full stick straight down
        rig.core.driver_command(rig.now, 0.0, -5.0)
        rig.step()
    x, y = rig.kinematics.forward(rig.true_q)
    assert y > 0.0 and rig.true_q[0] > 0.0              # short of the floor ...
    assert y < 0.25                                     # ... but it did go down
    assert rig.lowest_m == 0.0
    assert rig.run(1.0, rig.in_state(ArmState.WAITING))  # commands stopped: hold
    here = rig.true_q
    rig.run(1.0)
    assert np.max(np.abs(rig.true_q - here)) < 0.3 * DEG


def test_driver_speed_is_limited(arm, controller_config):
    core = ArmController(arm, controller_config)
    core.step(0.0, reading_at(START))
    core.driver_command(0.0, 100.0, 0.0)
    assert np.hypot(*core.setpoints.driver.tool_velocity_mps) == pytest.approx(
        controller_config.driver_max_speed_mps)
    assert not core.driver_command(0.0, math.nan, 0.0)[0]


# --- every transition of the table, taken by the real controller -------------------------

def bring_to(state, arm, controller_config, planner):
    """A rig whose core is in ``state``."""
    asynchronous = state == ArmState.PLANNING
    rig = Rig(arm, controller_config, None if asynchronous else planner)
    if state == ArmState.NO_SENSORS:
        return rig
    rig.step()
    core = rig.core
    if state == ArmState.PLANNING:
        core.submit_preset(rig.now, 'high_score')
        rig.step()
    elif state == ArmState.TRACKING:
        core.submit_preset(rig.now, 'back_score')
        rig.step()
    elif state == ArmState.HOLDING:
        core.submit_goal(rig.now, 0.85, 1.0)
        rig.run(5.0, rig.in_state(ArmState.HOLDING))
    elif state == ArmState.ERROR:
        core.submit_goal(rig.now, math.nan, 0.0)
    elif state == ArmState.DRIVER:
        core.driver_command(rig.now, 0.1, 0.0)
        rig.step()
    elif state == ArmState.ESTOPPED:
        core.estop(rig.now)
    elif state == ArmState.DISABLED:
        core.enable(rig.now, False)
    assert core.state == state
    return rig


def take(trigger, rig, planner):
    """Do to the controller what should fire ``trigger`` in its current state."""
    core, state = rig.core, rig.core.state
    if trigger == Trigger.SENSORS_BACK:
        rig.step()
    elif trigger == Trigger.SENSORS_BACK_HELD:                # a goal held, the sensors lost
        core.submit_goal(rig.now, 0.85, 1.0)
        rig.run(5.0, rig.in_state(ArmState.HOLDING))
        rig.sensors_on = False
        rig.run(0.3)
        rig.sensors_on = True
        rig.step()
    elif trigger == Trigger.SENSORS_LOST:
        rig.sensors_on = False
        rig.run(0.3)
    elif trigger == Trigger.GOAL:
        if state in (ArmState.PLANNING, ArmState.TRACKING, ArmState.DRIVER):
            core.submit_preset(rig.now, 'mid_score')      # preempts (a queued goal waits)
        else:
            core.submit_goal(rig.now, 1.0, 1.0)
        rig.run(1.0, lambda: core.state != state)
    elif trigger == Trigger.PLAN_READY:
        (request,) = core.planning.take()
        core.on_timed_plan(rig.now, core.plan_timer.time_plan(
            request, planner.plan(request.start_q, request.goal.xy)))
    elif trigger == Trigger.PLAN_FAILED:
        rig.run(2.0, rig.in_state(ArmState.ERROR))
    elif trigger == Trigger.ARRIVED:
        rig.run(6.0, rig.in_state(ArmState.HOLDING))
    elif trigger == Trigger.GOAL_FAILED:
        core.submit_goal(rig.now, 1.0, 1.0, frame_id='map')
    elif trigger == Trigger.CANCEL:
        core.cancel(rig.now)
    elif trigger == Trigger.ESTOP:
        core.estop(rig.now)
    elif trigger == Trigger.RESET:
        core.reset(rig.now)
    elif trigger == Trigger.DISABLE:
        core.enable(rig.now, False)
    elif trigger == Trigger.ENABLE:
        core.enable(rig.now, True)
    elif trigger == Trigger.DRIVER_COMMAND:
        core.driver_command(rig.now, 0.1, 0.0)
    elif trigger == Trigger.DRIVER_IDLE:
        rig.run(2.0, rig.in_state(ArmState.WAITING))
    elif trigger == Trigger.MOVED:
        rig.plant.reset((0.8, 0.9))                     # pushed, or the sim reset
        rig.step()


@pytest.mark.parametrize('state, trigger', sorted(TRANSITIONS, key=str))
def test_the_controller_takes_each_transition(arm, controller_config, planner, state, trigger):
    rig = bring_to(state, arm, controller_config, planner)
    take(trigger, rig, planner)
    assert (state, trigger, TRANSITIONS[(state, trigger)]) in rig.core.machine.history


def test_new_gains_act_from_the_next_period(arm, controller_config):
    """Run-time tuning: two cores see the same readings; one has its proportional gain
    doubled before the third period. Its feedback then differs by exactly kp·e."""
    kp, ki, kd = controller_config.shoulder_pid
    cores = [ArmController(arm, controller_config) for _ in range(2)]
    readings = [reading_at(START), reading_at((START[0] - 0.02, START[1]))] * 2
    for k, reading in enumerate(readings[:2]):
        for core in cores:
            core.step(0.02 * k, reading)
    cores[1].retune(arm, dataclasses.replace(controller_config, shoulder_pid=(2 * kp, ki, kd)))
    for core in cores:
        core.step(0.04, readings[2])
    error = cores[0].last_step.tracking_error_rad[0]
    assert abs(error) > 0.003
    difference = cores[1].last_step.feedback_v[0] - cores[0].last_step.feedback_v[0]
    assert difference == pytest.approx(kp * error, rel=1e-6)
