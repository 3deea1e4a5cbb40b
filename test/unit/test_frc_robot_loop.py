"""The robot's loop as the contract tells a robot to run it, and the layouts that carry it:
deterministic, no network (``robot_loop``, ``codec``), and the bridge's rule for "lost"."""

import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from arm_control.frc import codec, contract as nt, rules
from arm_control.frc.robot_loop import loop_instants, RobotLoop
from arm_control.frc.tables import now_us
from arm_control.model.plant import ArmPlant
from arm_control.model.profile import Profile, Setpoint

PERIOD_S = nt.LOOP_PERIOD_S
GAINS = ((90.0, 4.0), (75.0, 3.0))
TIMEOUT_S = 0.1
START = (0.9, -0.6)


def robot(arm, seed=3):
    """A robot loop over a plant that starts off its support (so 0 V lets it fall)."""
    plant = ArmPlant(arm, START, 0.001, seed)
    return RobotLoop(plant, arm.battery.nominal_voltage, TIMEOUT_S)


def run(loop, instants, arrivals, enabled=True):
    """Step ``loop`` at ``instants``; ``arrivals``: (arrival s, command), delivered at the
    first loop at or after their arrival, as a robot's subscriber holds them."""
    pending = sorted(arrivals, key=lambda a: a[0])
    out = []
    for t in instants:
        arrived = [command for when, command in pending if when <= t]
        pending = [(when, command) for when, command in pending if when > t]
        out.append(loop.step(t, enabled, arrived))
    return out


# ---------------------------------------------------------------------- a command's instant


@settings(max_examples=25, deadline=None)
@given(phase_s=st.floats(0.0, PERIOD_S, exclude_max=True),
       arrival_s=st.floats(0.001, 0.1))
def test_a_command_never_acts_before_it_arrives(arm, phase_s, arrival_s):
    """Whatever the loop's phase and the arrival: the arm's true motion is the same as with
    no command at all up to the first loop at or after the arrival, and differs after."""
    instants = [phase_s + 1.0 + k * PERIOD_S for k in range(12)]
    arrived_s = 1.0 + arrival_s
    command = codec.VoltageCommand(round((arrived_s - 0.002) * 1e6), (8.0, -6.0))
    with_command = run(robot(arm), instants, [(arrived_s, command)])
    without = run(robot(arm), instants, [])
    acting_s = min(t for t in instants if t >= arrived_s)
    for t, (reading, truth), (_, truth_without) in zip(instants, with_command, without):
        if t <= acting_s:
            assert truth == truth_without, f'the arm moved differently at {t - arrived_s:+.4f}'
        driving = acting_s <= t < command.time_us * 1e-6 + TIMEOUT_S
        assert (reading.applied_voltage_v == (8.0, -6.0)) == driving
    assert with_command[-1][1] != without[-1][1]


def test_a_command_drives_until_its_instant_plus_the_timeout_then_0v(arm):
    loop = robot(arm)
    sent_s = 1.003
    command = codec.VoltageCommand(round(sent_s * 1e6), (4.0, 2.0))
    instants = [1.01 + k * PERIOD_S for k in range(10)]
    readings = run(loop, instants, [(1.005, command)])
    driving = [t for t, (r, _) in zip(instants, readings) if r.applied_voltage_v != (0.0, 0.0)]
    assert driving[0] == instants[0] and max(driving) < sent_s + TIMEOUT_S
    assert readings[-1][0].applied_voltage_v == (0.0, 0.0)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 0.2), st.floats(0.001, 0.3)), min_size=1,
                max_size=20))
def test_no_pair_ever_drives_past_its_timeout(arm, loops):
    """Pairs sent with random delays, loops run at random (late) times: a pair is applied
    only at loops before its time_us + timeout, and the arm never runs under it after."""
    loop = robot(arm)
    now_s = 1.0
    expires_s = {}
    for k, (delay_s, late_s) in enumerate(loops):
        now_s += late_s
        command = codec.VoltageCommand(round((now_s - delay_s) * 1e6), (0.1 * (k + 1), 0.0))
        expires_s[command.voltage_v] = command.time_us * 1e-6 + TIMEOUT_S
        reading, _ = loop.step(now_s, True, [command])
        if reading.applied_voltage_v != (0.0, 0.0):
            assert now_s < expires_s[reading.applied_voltage_v]
            assert loop.voltage_until_s <= expires_s[reading.applied_voltage_v] + 1e-9


def test_a_command_past_its_expiry_on_arrival_is_refused(arm):
    loop = robot(arm)
    stale = codec.VoltageCommand(round(0.5e6), (6.0, 6.0))
    readings = run(loop, [1.0, 1.02], [(0.99, stale)])
    assert all(r.applied_voltage_v == (0.0, 0.0) for r, _ in readings)
    assert [command for _, command in loop.refused] == [stale]


def test_the_latest_to_arrive_is_in_charge(arm):
    loop = robot(arm)
    first = codec.VoltageCommand(round(1.000e6), (2.0, 2.0))
    second = codec.VoltageCommand(round(1.005e6), (5.0, 5.0))
    readings = run(loop, [1.01, 1.03], [(1.001, first), (1.02, second)])
    assert [r.applied_voltage_v for r, _ in readings] == [(2.0, 2.0), (5.0, 5.0)]


def test_disabled_is_0v_at_the_next_loop_and_says_so(arm):
    loop = robot(arm)
    command = codec.VoltageCommand(round(1.0e6), (6.0, 1.0))
    run(loop, [1.005], [(1.001, command)])
    reading, _ = loop.step(1.025, False, [codec.VoltageCommand(round(1.02e6), (6.0, 1.0))])
    assert reading.enabled is False and reading.applied_voltage_v == (0.0, 0.0)


# ---------------------------------------------------------------------- one reading, whole


@pytest.mark.parametrize('phase_s', [0.0, 0.007, 0.0135, 0.0199])
def test_a_reading_comes_whole_from_one_instant(arm, phase_s):
    """Every field of a reading is the plant at the reading's instant: the true state there
    explains its position and velocity (within the sensors' noise) and its currents are the
    motors' at that velocity under the voltage applied just before it."""
    loop = robot(arm, seed=11)
    instants = [phase_s + 2.0 + k * PERIOD_S for k in range(40)]
    drive = [(t - 0.004, codec.VoltageCommand(round((t - 0.005) * 1e6),
                                              (6.0 * math.sin(7 * t), -4.0 * math.cos(5 * t))))
             for t in instants]
    results = run(loop, instants, drive)
    motors = loop.plant.dynamics.motors
    limits_a = [joint.current_limit_a for joint in arm.joints]
    for (previous, _), (reading, truth) in zip(results, results[1:]):
        assert reading.time_us == round(instants[results.index((reading, truth))] * 1e6)
        assert np.allclose(reading.position_rad, truth[:2], atol=math.radians(1.0))
        assert np.allclose(reading.velocity_rad_s, truth[2:], atol=0.3)
        expected_a = [np.clip(m.current_a(v, w), -limit_a, limit_a) for m, v, w, limit_a in
                      zip(motors, previous.applied_voltage_v, truth[2:], limits_a)]
        assert np.allclose(reading.motor_current_a, expected_a, rtol=0.05, atol=1.0)


def test_a_reading_round_trips_through_its_layout():
    reading = codec.Reading(time_us=1_796_427_912_734_707, enabled=True,
                            position_rad=(0.5, -1.25), velocity_rad_s=(0.1, -0.2),
                            encoder_rad=(0.4, -1.2), motor_current_a=(3.0, -1.5),
                            bus_voltage_v=11.9, supply_current_a=4.5,
                            applied_voltage_v=(2.0, -1.0))
    values = codec.encode_reading(reading)
    assert len(values) == nt.READING_SIZE
    assert values[nt.READING_FIELD['position_rad'].indices] == [0.5, -1.25]
    assert codec.decode_reading(values) == reading


@pytest.mark.parametrize('values', [[1.0] * 13, [math.nan] + [0.0] * 13,
                                    [0.0, 1.0, math.inf] + [0.0] * 11])
def test_a_malformed_reading_is_refused_naming_the_topic(values):
    with pytest.raises(ValueError, match=nt.READING.name):
        codec.decode_reading(values)


def profile(time_us, setpoints, step_s=PERIOD_S):
    return codec.profile_command(time_us, Profile(0.0, step_s, GAINS, tuple(
        Setpoint(q, qd, ff) for q, qd, ff in setpoints)))


def test_commands_round_trip_and_a_three_value_command_is_a_voltage():
    assert codec.decode_command(codec.encode_voltage(5_000_000, (1.5, -2.0))) == \
        codec.VoltageCommand(5_000_000, (1.5, -2.0))
    sent = profile(5_000_000, [((0.1, 0.2), (1.0, 2.0), (5.0, 6.0)),
                               ((0.3, 0.4), (3.0, 4.0), (7.0, 8.0))])
    values = codec.encode_profile(sent)
    assert len(values) == nt.PROFILE_HEAD_SIZE + 2 * nt.PROFILE_POINT_SIZE
    assert values[0] == 5_000_000 and values[2:6] == [90.0, 4.0, 75.0, 3.0]
    assert codec.decode_command(values) == sent
    assert sent.end_us == 5_020_000
    for bad in ([1.0, 2.0], [1.0, 0.02] + [1.0] * 5, [1.0, 0.0] + [1.0] * 10,
                [math.nan, 1.0, 2.0]):
        with pytest.raises(ValueError, match=nt.COMMAND.name):
            codec.decode_command(bad)


def test_a_profile_is_played_at_the_robot_s_instant_and_held_past_its_end(arm):
    """The loop plays a profile with its own gains at the loop's instant (the nearest
    setpoint, extrapolated along its velocity); past its end, its last setpoint held at
    rest, however long no command comes."""
    loop = robot(arm)
    sent = profile(1_000_000, [((0.9, -0.6), (0.0, 0.0), (1.0, 1.0)),
                               ((0.9, -0.6), (1.0, 1.0), (2.0, 3.0))])
    reading, _ = loop.step(1.021, True, [sent])
    q, qd = reading.position_rad, reading.velocity_rad_s
    expected = [ff + kp * (0.9 + 0.001 - q[0] if j == 0 else -0.6 + 0.001 - q[1])
                + kd * (1.0 - qd[j]) for j, (ff, (kp, kd)) in enumerate(zip((2.0, 3.0), GAINS))]
    assert reading.applied_voltage_v == pytest.approx(expected)
    late, _ = loop.step(1.08, True)
    q, qd = late.position_rad, late.velocity_rad_s
    held = [ff + kp * (target - q[j]) - kd * qd[j] for j, (ff, (kp, kd), target) in
            enumerate(zip((2.0, 3.0), GAINS, (0.9, -0.6)))]
    assert late.applied_voltage_v == pytest.approx(held)
    much_later, _ = loop.step(1.5, True)
    q, qd = much_later.position_rad, much_later.velocity_rad_s
    assert much_later.applied_voltage_v == pytest.approx(np.clip(
        [ff + kp * (target - q[j]) - kd * qd[j] for j, (ff, (kp, kd), target) in
         enumerate(zip((2.0, 3.0), GAINS, (0.9, -0.6)))], -12.0, 12.0))


def test_the_loop_s_instants_keep_their_phase():
    assert loop_instants(0.007, 0.02, 10.0) == pytest.approx(10.007)
    assert loop_instants(0.007, 0.02, 10.007) == pytest.approx(10.027)


def test_nt_s_clock_is_read_through_public_api_and_moves_on():
    first = now_us()
    assert now_us() >= first and now_us() - first < 1_000_000


# ---------------------------------------------------------------------- the bridge's "lost"


def checked(link, start_s, end_s, step_s=PERIOD_S, connected=True):
    events = []
    t = start_s
    while t <= end_s + 1e-9:
        event = link.check(t, connected)
        if event is not None:
            events.append((t, event))
        t += step_s
    return events


def test_readings_stopping_is_lost_after_the_timeout_of_awake_time():
    link = rules.RobotLink(0.1)
    checked(link, 0.0, 1.0)
    link.on_reading(1.0, robot_enabled=True)
    events = checked(link, 1.02, 1.5)
    (t, lost), = events
    assert 1.1 < t <= 1.13 and lost.state == rules.LinkState.LOST
    assert lost.controller_enabled is None and not link.may_command


def test_a_starved_bridge_does_not_blame_the_robot():
    """The bridge itself sleeps 0.3 s (two busy processes on both cores): its readings wait
    in its socket; the sleep counts as one period, and the robot is not lost."""
    link = rules.RobotLink(0.1)
    checked(link, 0.0, 1.0)
    link.on_reading(1.0, robot_enabled=True)
    assert link.check(1.02, True) is None
    assert link.check(1.32, True) is None           # woke late
    link.on_reading(1.32, robot_enabled=True)       # what waited in the socket
    assert checked(link, 1.34, 1.4) == []


def test_a_dropped_connection_is_lost_at_once():
    link = rules.RobotLink(0.1)
    checked(link, 0.0, 0.1)
    link.on_reading(0.1, robot_enabled=True)
    lost = link.check(0.11, nt_connected=False)
    assert lost.state == rules.LinkState.LOST and lost.nt_connected is False
    back = link.on_reading(1.0, robot_enabled=True)
    assert (back.previous, back.state) == (rules.LinkState.LOST, rules.LinkState.ENABLED)


def test_the_on_arrival_reference_acts_at_arrival_not_at_the_next_loop(arm):
    """The bench's reference row: applied on arrival, the command moves the arm before the
    next loop instant, where a robot's loop would not yet."""
    on_arrival, at_loop = robot(arm), robot(arm)
    command = codec.VoltageCommand(round(1.004e6), (8.0, -6.0))
    for loop in (on_arrival, at_loop):
        loop.step(1.0, True)
    on_arrival.apply_on_arrival(1.005, True, [command])
    _, moved = on_arrival.step(1.02, True)
    _, waited = at_loop.step(1.02, True, [command])
    assert moved != waited
    assert on_arrival.voltage == at_loop.voltage == (8.0, -6.0)
