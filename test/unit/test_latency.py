"""When a command acts, and a reading older than the last prediction, on the controller's
clock."""

import math

import numpy as np
import pytest

from arm_control.control.closed_loop import ClosedLoop
from arm_control.control.latency import COMMAND_TRANSIT_S, CommandDelay
from arm_control.control.sensing import Sensing
from arm_control.control.state_machine import ArmState
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.plant import ArmPlant
from arm_control.model.world import ForbiddenSpace


def test_a_command_acts_after_the_ticks_compute_and_its_transit():
    delay = CommandDelay(period_s=0.02)
    assert delay.delay_s == pytest.approx(COMMAND_TRANSIT_S)    # nothing measured yet
    for compute_s in (0.004, 0.005, 0.030, 0.006, 0.005):       # one slow tick
        delay.sent(compute_s)
    assert delay.delay_s == pytest.approx(0.005 + COMMAND_TRANSIT_S)
    for _ in range(30):
        delay.sent(0.5)                                         # a stalled machine
    assert delay.delay_s == 0.02                                # never beyond a period


MID, STOW = (1.1, 0.9), (0.25, 0.45)


def worst_tracking_deg(arm, controller_config, planner, delay_s, told=True, seed=3,
                       **loop_options):
    """mid → stow in one process, each command acting ``delay_s`` after its tick: the
    largest distance, on either joint, between the arm and the controller's setpoint at the
    instants its commands began to act. ``loop_options``: more of ``ClosedLoop``'s."""
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    start = next(q for q in reversed(kinematics.inverse(*MID))
                 if ForbiddenSpace(arm).is_free(q))
    loop = ClosedLoop(arm, controller_config, planner, start=start, seed=seed,
                      command_delay_s=delay_s, told_delay=told, **loop_options)
    loop.run(0.5)
    errors, apply = [], loop.plant.set_voltage

    def acting(voltage):                      # the plant is at the instant the command acts
        if loop.core.state == ArmState.TRACKING:
            errors.append(np.abs(loop.true_q - loop.core.last_step.setpoint[0]))
        apply(voltage)
    loop.plant.set_voltage = acting
    loop.core.submit_goal(loop.now, *STOW)
    assert loop.run(1.5, loop.in_state(ArmState.HOLDING))
    return math.degrees(np.max(errors))


def test_commands_computed_for_when_they_act_keep_a_late_loop_on_its_trajectory(
        arm, controller_config, planner):
    """Commands that act 10 ms after their reading (a tick's compute through ROS). Told so,
    the core predicts the state to that instant and samples the trajectory there, and the
    arm is where it meant it to be as with no delay (0.1-0.2 deg); not told, 1.6 deg off."""
    at_once = worst_tracking_deg(arm, controller_config, planner, 0.0)
    told = worst_tracking_deg(arm, controller_config, planner, 0.010)
    untold = worst_tracking_deg(arm, controller_config, planner, 0.010, told=False)
    assert at_once < 0.3 and told < 0.3
    assert untold > 1.0


def test_readings_timed_when_taken_keep_the_arm_on_its_trajectory(
        arm, controller_config, planner):
    """Readings that arrive 5 ms after the sensors were read (through ROS: 4 ms at the median,
    9 at p90), commands acting 5 ms after the tick. Timed at their stamps, the estimate is the
    arm's and the arm follows its setpoint as with none; timed at their arrival, the estimate
    lags the arm by 5 ms of motion, and the feedback drives the arm ahead of its setpoint
    (0.1-0.2 deg against 0.8-0.95 deg over seeds 1-5)."""
    stamped = worst_tracking_deg(arm, controller_config, planner, 0.005, reading_age_s=0.005)
    arrival = worst_tracking_deg(arm, controller_config, planner, 0.005, reading_age_s=0.005,
                                 told_age=False)
    assert stamped < 0.3
    assert arrival > 0.6 and arrival > 3 * stamped


def test_a_reading_older_than_the_last_prediction_is_folded_in_at_its_own_time(
        arm, controller_config):
    """The controller predicted to 16 ms (the instant a command acts); then comes a reading
    taken at 13 ms. The estimate at 20 ms is the one it would be had the reading come first;
    folded in at 16 ms it was not."""
    plant = ArmPlant(arm, (1.0, -1.0), seed=5)
    plant.set_voltage((6.0, -3.0))
    first = plant.read()
    plant.advance(0.013)
    later = plant.read()
    volts = (6.0, -3.0)

    def sensing():
        s = Sensing(arm, controller_config.process_noise_rad_s2)
        s.update(0.0, first, 0.0, (0.0, 0.0))
        return s
    in_order, late = sensing(), sensing()
    in_order.update(0.013, later, 0.013, volts)
    in_order.update(0.020, None, None, volts)
    late.update(0.016, None, None, volts)
    late.update(0.020, later, 0.013, volts)
    np.testing.assert_allclose(late.state, in_order.state, atol=1e-5)   # 3 ms late: 3e-3
