"""The robot's clock: commands taken only at the loop's instants after they arrive; the
controller learning the loop from the readings' stamps and sending profiles that end held;
the closed loop with commands acting at the robot's next instant, at phases over the period."""

import dataclasses
import math

import numpy as np
import pytest

from arm_control.config import ControllerConfig, SimConfig
from arm_control.control import robot_command
from arm_control.control.robot_command import (AHEAD, ARRIVAL_MARGIN_S, profile_ahead,
                                               RobotClock)
from arm_control.control.robot_loop import RobotLoop
from arm_control.model.profile import Profile, Setpoint
from arm_control.model.robot_commands import RobotCommands, ZERO_V
from arm_control.parameters import ParameterError, read_parameter_files

PERIOD_S = 0.02
HOLD = Profile(0.0, PERIOD_S, ((20.0, 1.0), (20.0, 1.0)),
               (Setpoint((1.0, -1.0), (0.0, 0.0), (3.0, 2.0)),))


@pytest.mark.parametrize('node, settings, name, value', [
    (SimConfig, 'sim', 'command_timing', 'whenever'),
    (SimConfig, 'sim', 'robot_loop_phase_s', 0.03),
    (SimConfig, 'sim', 'robot_loop_phase_s', -0.001),
    (ControllerConfig, 'controller', 'command_mode', 'torque'),
    (ControllerConfig, 'controller', 'robot_feedback_share', 1.5),
    (ControllerConfig, 'controller', 'holding_rate_hz', 30.0),      # 50 Hz / 30 not whole
    (ControllerConfig, 'controller', 'holding_rate_hz', 100.0),     # faster than the loop
    (ControllerConfig, 'controller', 'holding_rate_hz', 0.0),
])
def test_bad_robot_loop_settings_are_refused_naming_them(node, settings, name, value):
    params = read_parameter_files([], settings)
    node.from_parameters(params)
    params[name] = value
    with pytest.raises(ParameterError, match=f"'{name}'"):
        node.from_parameters(params)


@pytest.mark.parametrize('phase_s', [0.0, 0.005, 0.013, 0.019])
def test_a_command_is_taken_at_the_first_instant_after_it_arrives(phase_s):
    """Commands arriving at times spread over three periods: each is in charge from the
    first loop instant at or after its arrival, never before."""
    rng = np.random.default_rng(int(phase_s * 1000))
    arrivals = np.sort(rng.uniform(0.0, 3 * PERIOD_S, 5))
    commands = RobotCommands(12.0, timeout_s=1.0)
    for k, arrived_s in enumerate(arrivals):
        commands.arrive(arrived_s, (float(k + 1), 0.0))
    instants = phase_s + PERIOD_S * np.arange(5)
    for instant in instants:
        commands.take(instant)
        volts = commands.volts(instant, (0.0, 0.0), (0.0, 0.0))
        arrived = arrivals[arrivals <= instant]
        assert volts == ((float(len(arrived)), 0.0) if len(arrived) else ZERO_V)


def test_a_plain_command_times_out_to_zero_volts_and_a_profile_holds():
    commands = RobotCommands(12.0, timeout_s=0.1)
    commands.arrive(0.0, (2.0, 1.0))
    commands.take(0.0)
    assert commands.volts(0.1, (0, 0), (0, 0)) == (2.0, 1.0)
    assert commands.volts(0.12, (0, 0), (0, 0)) == ZERO_V and commands.timed_out(0.12)
    commands.arrive(0.14, HOLD)
    commands.take(0.14)
    assert commands.volts(60.0, (1.0, -1.0), (0.0, 0.0)) == (3.0, 2.0)   # held at its end
    assert not commands.timed_out(60.0)
    assert commands.late == 1                       # taken after its first setpoint's instant


def test_a_profile_not_yet_begun_leaves_the_command_before_it():
    commands = RobotCommands(12.0, timeout_s=0.1)
    commands.arrive(0.0, (2.0, 1.0))
    commands.arrive(0.001, dataclasses.replace(HOLD, start_s=0.04))
    commands.take(0.02)
    assert commands.volts(0.02, (1.0, -1.0), (0.0, 0.0)) == (2.0, 1.0)
    assert commands.volts(0.04, (1.0, -1.0), (0.0, 0.0)) == (3.0, 2.0)


def test_the_clock_learns_the_robot_loop_from_the_stamps():
    clock = RobotClock(0.02)
    assert clock.next_instant(5.0) == 5.0                   # no reading yet: now
    stamps = 100.007 + 0.0201 * np.arange(30)
    for k, stamp in enumerate(stamps):
        if k % 7 != 3:                                      # some readings lost
            clock.observe(stamp)
    assert clock.period_s == pytest.approx(0.0201, abs=1e-6)
    last = stamps[-1]
    assert clock.next_instant(last) == pytest.approx(last + 0.0201)   # not the read one
    assert clock.next_instant(last + 0.025) == pytest.approx(last + 2 * 0.0201)
    assert clock.acting_at(last + 0.0201 - ARRIVAL_MARGIN_S / 2) == \
        pytest.approx(last + 2 * 0.0201)                    # too close: the one after


def test_another_publishers_readings_off_the_grid_do_not_move_it_a_moved_loop_does():
    clock = RobotClock(0.02)
    grid = 50.004 + 0.02 * np.arange(40)
    for k, stamp in enumerate(grid):
        clock.observe(stamp)
        clock.observe(stamp + 0.0093 + 0.0001 * k)          # a second publisher, its own phase
    assert clock.last_s == pytest.approx(grid[-1])
    assert clock.period_s == pytest.approx(0.02, abs=1e-9)
    moved = grid[-1] + 0.011 + 0.02 * np.arange(1, 8)       # the robot's loop jumped 11 ms
    for stamp in moved:
        clock.observe(stamp)
    assert clock.last_s == pytest.approx(moved[-1])
    assert clock.next_instant(moved[-1] + 0.001) == pytest.approx(moved[-1] + 0.02)


def test_a_stamp_across_a_jump_of_the_clock_does_not_move_it_for_good():
    clock = RobotClock(0.02)
    grid = 20.004 + 0.02 * np.arange(30)
    for stamp in grid[:20]:
        clock.observe(stamp)
    clock.observe(grid[20] + 10.0)                          # converted across a clock jump
    for stamp in grid[21:]:
        clock.observe(stamp)
    assert clock.last_s == pytest.approx(grid[-1])
    assert clock.next_instant(grid[-1] + 0.001) == pytest.approx(grid[-1] + 0.02)
    back = grid[-1] - 10.0 + 0.02 * np.arange(1, 8)         # the clock itself went back
    for stamp in back:
        clock.observe(stamp)
    assert clock.last_s == pytest.approx(back[-1])


def _held_core(arm, controller_config, q=(0.3, 1.2)):
    loop = RobotLoop(arm, controller_config, start=q, mode='profile', seed=2)
    loop.run(1.0)
    return loop


def test_a_profile_from_a_hold_ends_at_rest_with_the_holding_volts(arm, controller_config):
    loop = _held_core(arm, controller_config)
    core = loop.core
    start_s = loop.clock.acting_at(loop.now_s)
    core.step(start_s, loop.plant.read(), loop.now_s)
    profile = profile_ahead(core, start_s, PERIOD_S)
    last = profile.setpoints[-1]
    tracking = core.tracking
    holding = tracking.feedforward.dynamics.voltages(
        np.array(last.position_rad), np.zeros(2), np.zeros(2)) + np.array(tracking.pid.integral_v)
    assert len(profile.setpoints) >= AHEAD and last.velocity_rad_s == (0.0, 0.0)
    assert last.feedforward_v == pytest.approx(tuple(holding))
    share = controller_config.robot_feedback_share
    assert profile.gains[0] == pytest.approx((share * controller_config.shoulder_pid[0],
                                              share * controller_config.shoulder_pid[2]))
    # Read where the controller's estimate has the arm, the robot applies its volts.
    estimate = core.sensing.state
    first = profile.at(start_s)
    volts = [ff + kp * (q - qe) + kd * (qd - qde) for ff, (kp, kd), q, qe, qd, qde in zip(
        first.feedforward_v, profile.gains, first.position_rad, estimate[:2],
        first.velocity_rad_s, estimate[2:])]
    assert volts == pytest.approx(list(core.voltage), abs=1e-9)


def test_a_held_profile_is_the_one_a_moving_arm_would_get(arm, controller_config,
                                                          monkeypatch):
    """At rest the profile is built from the hold alone (no sampling of the motion, the
    holding volts kept once per angle): exactly the profile the general rule gives."""
    loop = _held_core(arm, controller_config)
    core = loop.core
    start_s = loop.clock.acting_at(loop.now_s)
    core.step(start_s, loop.plant.read(), loop.now_s)
    assert robot_command._held_q(core.setpoints, start_s) is not None
    held = [profile_ahead(core, start_s, PERIOD_S) for _ in range(2)]
    monkeypatch.setattr(robot_command, '_held_q', lambda setpoints, t_s: None)
    assert held[0] == held[1] == profile_ahead(core, start_s, PERIOD_S)


def test_a_profile_mid_move_stops_along_the_path_and_holds(arm, controller_config, planner):
    """Cut off mid-move, the robot plays the last profile to its end: the arm comes to rest
    and stays, above the floor."""
    loop = RobotLoop(arm, controller_config, planner, start=(1.5708, -1.5708), seed=3)
    loop.run(0.3)
    loop.submit_goal(-1.0, 1.0)
    assert loop.run(2.0, lambda: np.max(np.abs(loop.plant.state[2:])) > 2.0)
    loop._tick = lambda now_ms: None                        # the controller is gone
    loop.run(3.0)
    states = np.array([s for t, s in loop.history if t > loop.now_s - 1.0])
    assert np.max(np.abs(states[:, 2:])) < 0.05
    assert np.max(np.ptp(states[:, :2], axis=0)) < math.radians(0.5)
    assert loop.lowest_m > 0.0


@pytest.mark.parametrize('phase_ms', [0, 5, 10, 15, 19])
def test_on_the_robot_loop_the_hold_is_still_at_every_phase(arm, controller_config, phase_ms):
    loop = RobotLoop(arm, controller_config, start=(0.0, 1.75), mode='profile', seed=1,
                     phase_s=phase_ms / 1000.0)
    loop.run(3.0)
    states = np.array([s for t, s in loop.history if t > 1.0])
    assert np.max(np.abs(states[:, 2:])) < 0.1
    assert np.max(np.ptp(states[:, :2], axis=0)) < math.radians(0.5)


def _move_s(arm, controller_config, planner, mode, phase_ms, robot_loop=True):
    loop = RobotLoop(arm, controller_config, planner, start=(0.2, 0.05), mode=mode, seed=5,
                     phase_s=phase_ms / 1000.0, robot_loop=robot_loop)
    loop.run(0.5)
    goal_s = loop.now_s
    loop.submit_goal(-1.2, 0.3)
    loop.run(4.0)
    times = np.array([t for t, _ in loop.history])
    q = np.array([s[:2] for _, s in loop.history])
    away = np.flatnonzero(np.any(np.abs(q - q[-1]) > math.radians(1.0), axis=1))
    return times[away[-1] + 1] - goal_s


@pytest.mark.parametrize('phase_ms', [0, 19])
def test_on_the_robot_loop_a_move_takes_as_long_as_with_commands_on_arrival(
        arm, controller_config, planner, phase_ms):
    """Profiles for the robot's instants: the move as fast as commands applied on arrival
    (plain volts computed for their arrival, as before, fail this at both phases)."""
    reference = _move_s(arm, controller_config, planner, 'volts', 0, robot_loop=False)
    assert _move_s(arm, controller_config, planner, 'profile', phase_ms) < 1.05 * reference
