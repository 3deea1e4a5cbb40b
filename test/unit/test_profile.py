"""The profile on voltage_command: its format round trip, what is refused, and the robot's
player (tracks a setpoint, holds at the end)."""

import math

import numpy as np
import pytest

from arm_control.config import load
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.plant import ArmPlant
from arm_control.model.profile import (DATA_OFFSET, decode, decode_command, encode,
                                       FIELDS_LABEL, Profile, ProfileError, ProfilePlayer,
                                       Setpoint, SETPOINT_LABEL)

GAINS = ((90.0, 4.0), (75.0, 3.0))


def profile(start_s=10.0, step_s=0.02, count=4, seed=0):
    rng = np.random.default_rng(seed)
    return Profile(start_s, step_s, GAINS, tuple(
        Setpoint(tuple(rng.uniform(-3, 3, 2)), tuple(rng.uniform(-2, 2, 2)),
                 tuple(rng.uniform(-12, 12, 2))) for _ in range(count)))


@pytest.mark.parametrize('count', [1, 3, 40])
def test_encode_then_decode_gives_the_profile_back(count):
    sent = profile(count=count, seed=count)
    dims, offset, data = encode(sent)
    assert dims == [(SETPOINT_LABEL, count, 6 * count), (FIELDS_LABEL, 6, 6)]
    assert offset == DATA_OFFSET and len(data) == DATA_OFFSET + 6 * count
    assert decode(data, dims, offset) == sent
    assert decode_command(data, dims, offset) == sent


def test_two_values_stay_a_voltage_pair_whatever_the_layout():
    dims, offset, _ = encode(profile())
    assert decode_command([1.5, -2.0]) == (1.5, -2.0)
    assert decode_command([1.5, -2.0], dims, offset) == (1.5, -2.0)


def _corrupt(change):
    dims, offset, data = encode(profile())
    dims, data = [list(d) for d in dims], list(data)
    offset = change(dims, data) or offset
    return data, dims, offset


@pytest.mark.parametrize('change', [
    lambda dims, data: data.pop(),                                  # a value short
    lambda dims, data: data.append(0.0),                            # a value too many
    lambda dims, data: dims.pop(),                                  # no fields dim
    lambda dims, data: dims[1].__setitem__(0, 'q,qd,v'),            # fields renamed
    lambda dims, data: dims[0].__setitem__(1, 5),                   # count disagrees
    lambda dims, data: dims[0].__setitem__(2, 7),                   # stride wrong
    lambda dims, data: 2,                                           # the old offset
    lambda dims, data: data.__setitem__(1, 0.0),                    # no step
    lambda dims, data: data.__setitem__(1, 0.5),                    # not a robot loop
    lambda dims, data: data.__setitem__(2, -1.0),                   # negative gain
    lambda dims, data: data.__setitem__(7, math.nan),               # NaN angle
    lambda dims, data: data.__setitem__(10, math.inf),              # infinite volts
    lambda dims, data: data.__setitem__(6, 100.0),                  # beyond two turns
])
def test_malformed_profiles_are_refused(change):
    with pytest.raises(ProfileError):
        decode_command(*_corrupt(change))


def test_other_lengths_without_a_layout_are_refused():
    for data in ([], [1.0], [1.0, 2.0, 3.0], [math.nan, 0.0]):
        with pytest.raises(ProfileError):
            decode_command(data)


def test_the_setpoint_at_the_instants_aimed_at_is_exact_and_late_ones_skip_ahead():
    sent = profile()
    for k, setpoint in enumerate(sent.setpoints):
        t = sent.start_s + k * sent.step_s
        assert sent.at(t) == setpoint
        assert sent.at(t + 0.004).feedforward_v == setpoint.feedforward_v
    early = sent.at(sent.start_s - 0.004)         # before its start: setpoint 0, moved back
    assert early.position_rad == pytest.approx(
        np.array(sent.setpoints[0].position_rad) - 0.004 * np.array(
            sent.setpoints[0].velocity_rad_s))


def test_past_its_end_a_profile_holds_its_last_position_at_rest():
    sent = profile()
    last = sent.setpoints[-1]
    held = sent.at(sent.end_s + 5.0)
    assert held.position_rad == last.position_rad and held.velocity_rad_s == (0.0, 0.0)
    assert held.feedforward_v == last.feedforward_v


def test_the_player_takes_a_profile_from_its_start_and_not_before():
    player = ProfilePlayer(12.0)
    first, second = profile(10.0, seed=1), profile(10.06, seed=2)
    assert player.volts(10.0, (0, 0), (0, 0)) is None
    player.offer(first)
    player.offer(second)
    assert player.in_force(10.02) is first
    assert player.in_force(10.049) is first            # 10.06 less half a step: not yet
    assert player.in_force(10.051) is second
    assert player.in_force(10.2) is second and player.profiles == [second]   # first: gone


def test_the_player_closes_pd_on_the_reading_within_the_volts():
    player = ProfilePlayer(12.0)
    hold = Profile(0.0, 0.02, GAINS, (Setpoint((1.0, -1.0), (0.0, 0.0), (2.0, 1.0)),))
    player.offer(hold)
    assert player.volts(0.0, (1.0, -1.0), (0.0, 0.0)) == (2.0, 1.0)
    volts = player.volts(0.0, (0.99, -1.01), (0.1, -0.1))
    assert volts == pytest.approx((2.0 + 90 * 0.01 - 4 * 0.1, 1.0 + 75 * 0.01 + 3 * 0.1))
    assert player.volts(0.0, (0.0, -1.0), (0.0, 0.0)) == (12.0, 1.0)     # clamped


def _play(plant, player, seconds, period_s=0.02):
    """The robot's loop: read, play, hold the volts for a period."""
    for _ in range(round(seconds / period_s)):
        reading = plant.read()
        volts = player.volts(plant.time_s, reading.potentiometer_rad, reading.velocity_rad_s)
        plant.set_voltage(volts)
        plant.advance(period_s)


def test_a_profile_played_to_its_end_leaves_the_arm_held_where_it_ends():
    """A hold profile of one setpoint with the gravity volts, then nothing: the arm stays."""
    arm, _ = load('sim')
    plant = ArmPlant(arm, (0.3, 1.2), seed=3)
    holding = tuple(ArmDynamics(arm).voltages(np.array([0.3, 1.2]), np.zeros(2), np.zeros(2)))
    player = ProfilePlayer(arm.battery.nominal_voltage)
    player.offer(Profile(0.0, 0.02, GAINS, (Setpoint((0.3, 1.2), (0.0, 0.0), holding),)))
    _play(plant, player, 3.0)
    assert np.max(np.abs(np.array(plant.state[:2]) - (0.3, 1.2))) < math.radians(0.5)
    assert np.max(np.abs(plant.state[2:])) < 0.05


def test_the_player_tracks_a_moving_setpoint():
    """A slow ramp of the elbow with no feedforward but gravity's: PD alone follows it."""
    arm, _ = load('sim')
    dynamics = ArmDynamics(arm)
    plant = ArmPlant(arm, (0.5, 0.0), seed=4)
    speed, step = 0.5, 0.02
    times = np.arange(0.0, 1.0 + step / 2, step)
    points = [(0.5, 0.0 + speed * min(t, 0.8)) for t in times]
    gravity = [tuple(dynamics.voltages(np.array(q), np.zeros(2), np.zeros(2))) for q in points]
    setpoints = tuple(Setpoint(q, (0.0, speed if t < 0.8 else 0.0), v)
                      for q, t, v in zip(points, times, gravity))
    player = ProfilePlayer(arm.battery.nominal_voltage)
    player.offer(Profile(0.0, step, GAINS, setpoints))
    _play(plant, player, 0.4)
    assert abs(plant.state[1] - speed * plant.time_s) < math.radians(3.0)
    _play(plant, player, 1.6)
    assert abs(plant.state[1] - 0.4) < math.radians(0.5)
