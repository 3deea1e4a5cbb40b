"""Sensors lost, in one process on the robot's clock: sending profiles, the controller sends
what is left of its last one and the robot holds the arm on its own readings; plain 0 V (the
controller sending volts) drops it. Deterministic (seeded, 1 ms physics)."""

import dataclasses
import math

import numpy as np
import pytest

from arm_control.control.robot_command import rest_of
from arm_control.control.robot_loop import RobotLoop
from arm_control.control.state_machine import ArmState
from arm_control.model.profile import Profile, ProfilePlayer, Setpoint

LOST_S = 1.0                    # five times the controller's joint_state_timeout_s


def _lose_sensors(loop, seconds):
    """Run ``seconds`` with every reading lost on its way; the states the controller was in
    and whether a profile was in charge on the robot at each millisecond."""
    states, playing = set(), []

    def lost():
        loop.readings.clear()
        states.add(loop.core.state)
        playing.append(loop.playing)
    loop.run(seconds, lost)
    return states, playing


def _config(controller_config, mode):
    return dataclasses.replace(controller_config, command_mode=mode)


@pytest.mark.parametrize('q', [(0.0, 0.0), (0.3, 1.2)])
def test_held_arm_stays_held_while_its_sensors_are_lost(arm, controller_config, q):
    loop = RobotLoop(arm, _config(controller_config, 'profile'), start=q, seed=4)
    loop.run(1.0)
    held = np.array(loop.plant.state[:2])
    began = loop.now_s
    states, playing = _lose_sensors(loop, LOST_S)
    assert ArmState.NO_SENSORS in states and all(playing)      # never a 0 V pair
    lost = max(np.max(np.abs(s[:2] - held)) for t, s in loop.history if t > began)
    loop.run(1.0)                                                # they return
    assert loop.core.state in (ArmState.HOLDING, ArmState.WAITING)
    back = max(np.max(np.abs(s[:2] - held)) for t, s in loop.history if t > began)
    # Lost: the robot's own feedback on its readings. Back: the controller takes the arm
    # from an estimate begun afresh (the potentiometers' noise, the gears' lash).
    assert lost < math.radians(0.5) and back < math.radians(1.0)


@pytest.mark.parametrize('q', [(0.0, 0.0), (0.3, 1.2)])
def test_sending_volts_the_same_loss_drops_the_arm(arm, controller_config, q):
    """The known answer the profiles are measured against: 0 V under gravity."""
    loop = RobotLoop(arm, _config(controller_config, 'volts'), start=q, seed=4, mode='volts')
    loop.run(1.0)
    held = np.array(loop.plant.state[:2])
    _lose_sensors(loop, LOST_S)
    assert np.max(np.abs(loop.plant.state[:2] - held)) > math.radians(10.0)


def test_sensors_lost_mid_move_the_arm_stops_along_its_path_and_is_held(
        arm, controller_config, planner):
    loop = RobotLoop(arm, _config(controller_config, 'profile'), planner,
                     start=(1.5708, -1.5708), seed=3)
    loop.run(0.3)
    loop.submit_goal(-1.0, 1.0)
    assert loop.run(2.0, lambda: np.max(np.abs(loop.plant.state[2:])) > 2.0)
    states, playing = _lose_sensors(loop, 2.0 * LOST_S)       # the stop takes about 1 s
    assert ArmState.NO_SENSORS in states and all(playing)
    last = np.array([s for t, s in loop.history if t > loop.now_s - 0.5])
    assert np.max(np.abs(last[:, 2:])) < 0.05                    # at rest, held
    assert np.max(np.ptp(last[:, :2], axis=0)) < math.radians(0.5)
    assert loop.lowest_m > 0.0


def test_the_rest_of_a_profile_plays_as_the_profile_would():
    gains = ((20.0, 1.0), (15.0, 0.5))
    setpoints = tuple(Setpoint((0.1 * k, -0.05 * k), (5.0, -2.5) if k < 3 else (0.0, 0.0),
                               (1.0 + k, -1.0)) for k in range(4))
    profile = Profile(10.0, 0.02, gains, setpoints)
    rng = np.random.default_rng(7)
    for from_s in (9.98, 10.0, 10.04, 10.06, 10.5):
        rest = rest_of(profile, from_s)
        assert rest.start_s >= min(from_s, profile.start_s) - 1e-9     # never late
        for t in from_s + 0.02 * np.arange(10):
            q, qd = tuple(rng.uniform(-1, 1, 2)), tuple(rng.uniform(-1, 1, 2))
            whole, alone = ProfilePlayer(12.0), ProfilePlayer(12.0)
            whole.offer(profile)
            alone.offer(rest)
            assert alone.volts(t, q, qd) == pytest.approx(whole.volts(t, q, qd), abs=1e-9)


def test_e_stopped_holding_then_sensors_lost_the_robot_holds_until_e_stopped_again(
        arm, controller_config):
    """E-stopped, the arm braked and held; the sensors lost: the robot plays the rest of the
    last profile (0 V dropped it). An e-stop again is the user's 0 V."""
    loop = RobotLoop(arm, _config(controller_config, 'profile'), start=(0.3, 1.2), seed=4)
    loop.run(1.0)
    loop.core.estop(loop.now_s)
    loop.run(0.5)
    held = np.array(loop.plant.state[:2])
    began = loop.now_s
    states, playing = _lose_sensors(loop, LOST_S)
    assert states == {ArmState.ESTOPPED} and all(playing) and loop.core.held_by_robot
    moved = max(np.max(np.abs(s[:2] - held)) for t, s in loop.history if t > began)
    assert moved < math.radians(0.5)
    loop.core.estop(loop.now_s)
    _, playing = _lose_sensors(loop, 0.2)
    assert not playing[-1]                                       # a plain pair: 0 V
