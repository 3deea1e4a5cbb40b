"""What the controller cannot trust: a clock that jumps, a second source of joint_states,
sensors that disagree with each other or with physics. Each is said, and the arm is held
where the trusted estimate says."""

import dataclasses
import math

from controller_rig import DEG, kinds, Rig, START
import numpy as np
import pytest

from arm_control.control.clock_guard import ClockGuard
from arm_control.control.events import EventKind as Kind
from arm_control.control.sensing import Sensing, SensorReading
from arm_control.control.state_machine import ArmState
from arm_control.control.trust import GraphCounts, TrustWatch

ROGUE_OFFSET_RAD = -20 * DEG              # the second publisher's shoulder, 20 deg low


class FakeClock:
    """(clock s, wall s) as a test sets them."""

    def __init__(self, clock_s=100.0, wall_s=0.0):
        self.clock_s, self.wall_s = clock_s, wall_s

    def __call__(self):
        return self.clock_s, self.wall_s

    def advance(self, seconds, rate=1.0):
        self.wall_s += seconds
        self.clock_s += rate * seconds


@pytest.mark.parametrize('jump_s', [100.0, -10.0])
def test_a_jump_of_the_clock_is_taken_out_of_control_time(jump_s):
    source = FakeClock()
    guard = ClockGuard(source)
    times = []
    for _ in range(50):
        times.append(guard.now_s())
        source.advance(0.02)
    source.clock_s += jump_s                      # a rogue /clock, or a restarted sim
    for _ in range(50):
        times.append(guard.now_s())
        source.advance(0.02)
    steps = np.diff(times)
    assert np.all(steps >= 0.0) and np.max(steps) <= 0.02 + 1e-9
    assert guard.take() == [pytest.approx(jump_s + 0.02)] and guard.take() == []   # its step
    # A stamp of the clock after the jump is put on control time with it.
    assert guard.to_control_s(source.clock_s) == pytest.approx(times[-1] + 0.02)


def test_one_rogue_clock_message_ahead_then_the_sim_again_loses_nothing_but_its_step():
    source = FakeClock()
    guard = ClockGuard(source)
    before = guard.now_s()
    source.clock_s += 100.0
    assert guard.now_s() == pytest.approx(before)     # the rogue's: stands still
    source.clock_s -= 100.0 - 0.02                     # the sim's next step
    source.wall_s += 0.02
    assert guard.now_s() == pytest.approx(before)     # its step spent on the way back
    source.advance(0.02)
    assert guard.now_s() == pytest.approx(before + 0.02)
    assert len(guard.take()) == 2


@pytest.mark.parametrize('rate', [1.0, 4.0, 100.0])
def test_a_fast_clock_or_a_stalled_reader_is_no_jump(rate):
    source = FakeClock()
    guard = ClockGuard(source)
    guard.now_s()
    for _ in range(100):
        source.advance(0.001, rate)                     # read every millisecond of wall
        guard.now_s()
    source.advance(3.0, rate)                           # the reader stalled 3 s of wall
    guard.now_s()
    assert guard.take() == []


def rogue(reading):
    """The reading as a second publisher of joint_states gives it: the shoulder 20 deg low,
    at rest; the encoders are the sim's (motor_encoders has one publisher)."""
    pot = (reading.potentiometer_rad[0] + ROGUE_OFFSET_RAD, reading.potentiometer_rad[1])
    return dataclasses.replace(reading, potentiometer_rad=pot, velocity_rad_s=(0.0, 0.0)) \
        if dataclasses.is_dataclass(reading) else type('Rogue', (), dict(
            potentiometer_rad=pot, velocity_rad_s=(0.0, 0.0), encoder_rad=reading.encoder_rad,
            bus_voltage=reading.bus_voltage, supply_current_a=reading.supply_current_a))()


def held_beside_a_second_publisher(rig, seconds=4.0, every=2, encoders=True):
    """Every ``every``-th reading the loop takes is the second publisher's."""
    rig.run(0.5)
    for k in range(round(seconds / rig.period_s)):
        reading = rig.plant.read()
        if not encoders:
            reading = type('NoEncoders', (), dict(
                potentiometer_rad=reading.potentiometer_rad,
                velocity_rad_s=reading.velocity_rad_s, encoder_rad=(math.nan, math.nan),
                bus_voltage=reading.bus_voltage, supply_current_a=reading.supply_current_a))()
        rig.step(rogue(reading) if k % every == every - 1 else reading)


def test_a_second_joint_states_publisher_is_refused_by_the_encoders_no_ratchet(
        arm, controller_config, planner):
    """Away from where the encoders were zeroed (encoders near zero may have restarted)."""
    rig = Rig(arm, controller_config, planner)
    watch = TrustWatch(rig.core)
    rig.observers.append(lambda loop, reading, voltage: watch.step(loop.now))
    rig.core.submit_preset(0.0, 'mid_score')
    assert rig.run(5.0, lambda: rig.core.goals.counts['reached'] == 1)
    held_at = rig.true_q
    held_beside_a_second_publisher(rig)
    assert np.max(np.abs(rig.true_q - held_at)) < 2 * DEG      # held where it was
    assert Kind.ARM_MOVED not in kinds(rig.core)
    assert Kind.SENSORS_DISAGREE in kinds(rig.core)
    assert rig.core.sensing.refused >= 90                       # every one of the 100
    said = [e for e in rig.core.events.history if e.kind == Kind.SENSORS_DISAGREE]
    assert 1 < len(said) <= 6 and said[0].cause == 'encoders'  # the first, then per second


def test_without_encoders_the_graph_makes_the_leaps_refused(arm, controller_config):
    rig = Rig(arm, controller_config)
    watch = TrustWatch(rig.core)
    watch.graph(0.0, GraphCounts(joint_states=2, clock=0, voltage_command=1, same_name=1))
    assert [e.cause for e in rig.core.events.history] == ['joint_states']
    held_beside_a_second_publisher(rig, encoders=False)
    assert np.max(np.abs(rig.true_q - START)) < 2 * DEG
    assert Kind.ARM_MOVED not in kinds(rig.core)
    watch.graph(5.0, GraphCounts(joint_states=1, clock=0, voltage_command=1, same_name=1))
    assert kinds(rig.core)[-1] == Kind.TRUSTED and not rig.core.sensing.refuse_leaps


def test_a_sim_reset_is_still_the_arm_moved(arm, controller_config):
    """Potentiometers and encoders leap together (the encoders restart at the new pose): not
    a disagreement; the arm is held where it now is."""
    rig = Rig(arm, controller_config)
    rig.run(0.5)
    rig.plant.reset((1.2, -0.6))
    rig.run(1.0)
    assert Kind.ARM_MOVED in kinds(rig.core) and rig.core.sensing.refused == 0
    assert rig.core.state == ArmState.WAITING
    assert np.max(np.abs(rig.true_q - (1.2, -0.6))) < 2 * DEG     # held where it was put


def test_each_count_above_one_is_named_once_and_its_end_said():
    class Core:
        class sensing:
            refuse_leaps, refused = False, 0
        events = type('Events', (), {'said': [], 'say': lambda self, *a: self.said.append(a)})()
    watch = TrustWatch(Core)
    watch.graph(0.0, GraphCounts(1, 1, 2, 2))
    watch.graph(0.5, GraphCounts(1, 1, 2, 2))               # still: not said again
    watch.graph(1.0, GraphCounts(1, 1, 1, 2))
    said = [(kind, cause) for _, kind, _, _, cause in Core.events.said]
    assert said == [(Kind.UNTRUSTED, 'voltage_command'), (Kind.UNTRUSTED, 'node name'),
                    (Kind.TRUSTED, 'voltage_command')]
    assert watch.level == 'error' and not Core.sensing.refuse_leaps


def test_each_jump_of_the_clock_is_said(arm, controller_config):
    rig = Rig(arm, controller_config)
    watch = TrustWatch(rig.core)
    rig.run(0.2)
    watch.step(rig.now, [100.02, -99.98])
    said = [e for e in rig.core.events.history if e.kind == Kind.CLOCK_JUMPED]
    assert len(said) == 2 and watch.clock_jumps == 2
    assert rig.core.state == ArmState.WAITING                  # nothing else changes


@pytest.mark.parametrize('gap_periods', [1, 2, 4])
def test_beside_a_second_publisher_a_reading_away_from_the_prediction_is_refused(
        arm, controller_config, gap_periods):
    """The robot's readings 20 ms apart, some missed (lost, or more than the loop keeps on a
    slow tick); the second publisher's 20 deg off in between, up to 75 ms after the last
    reading taken. In that time the arm could move 20 deg at three times its free speed, so
    the leap from the last reading tells nothing: the filter's prediction does. Upright at
    0 V (no gravity torque), the arm stays where it is."""
    sensing = Sensing(arm, controller_config.process_noise_rad_s2)
    sensing.refuse_leaps = True
    upright = (math.pi / 2, 0.0)
    true = SensorReading(upright, (0.0, 0.0))
    stray = SensorReading((upright[0] + ROGUE_OFFSET_RAD, upright[1]), (0.0, 0.0))
    for block in range(5):
        for j in range(10):
            t = 0.2 * block + 0.02 * j
            if not 0 < j < gap_periods:                 # those missed
                sensing.update(t, true, t, (0.0, 0.0))
            if j == 0:                                  # the stray, 5 ms before a reading
                t_stray = t + 0.02 * gap_periods - 0.005
                sensing.update(t_stray, stray, t_stray, (0.0, 0.0))
    assert sensing.refused == 5
    assert np.max(np.abs(sensing.state[:2] - upright)) < 0.1 * DEG


def test_beside_a_second_publisher_its_reading_first_after_a_stall_is_refused(
        arm, controller_config):
    """The robot's readings stop for 0.22 s (more than the trusted source may be quiet), and
    the second publisher's comes first when they resume: refused (the robot held the arm
    meanwhile, near the last reading taken), and the robot's taken again. Taken whatever its
    source, it was re-held and the robot's refused from it: the arm followed the other."""
    sensing = Sensing(arm, controller_config.process_noise_rad_s2)
    sensing.refuse_leaps = True
    upright = (math.pi / 2, 0.0)
    true = SensorReading(upright, (0.0, 0.0))
    stray = SensorReading((upright[0] + ROGUE_OFFSET_RAD, upright[1]), (0.0, 0.0))
    for k in range(25):
        sensing.update(0.02 * k, true, 0.02 * k, (0.0, 0.0))
    resumed_s = 0.48 + 0.22
    for k in range(10):
        t = resumed_s + 0.02 * k
        sensing.update(t, stray, t, (0.0, 0.0))
        sensing.update(t + 0.01, true, t + 0.01, (0.0, 0.0))
    assert sensing.refused == 10 and sensing.refusal[0] == 'publishers'
    assert np.max(np.abs(sensing.state[:2] - upright)) < 0.1 * DEG
