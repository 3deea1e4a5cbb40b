"""The installed ``sim`` executable, as its own process, seen from another over DDS."""

import math
from pathlib import Path
import time

import pytest
from ros_harness import stamp_s
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger


def wait_for_messages(probe, received, count, timeout_s=20.0):
    assert probe.spin_until(lambda: len(received) >= count, timeout_s), \
        f'only {len(received)} of {count} messages arrived in {timeout_s} s'


def test_joint_states_at_the_configured_rate(launch, probe):
    sim = launch('sim', '-p', 'publish_rate_hz:=40.0')
    received = probe.collect(JointState, '/joint_states')
    wait_for_messages(probe, received, 5)
    first, start = len(received), time.monotonic()
    probe.spin_for(3.0)
    rate_hz = (len(received) - first) / (time.monotonic() - start)
    assert 30.0 < rate_hz < 50.0, f'{rate_hz:.1f} Hz, expected about 40'
    message = received[-1]
    assert list(message.name) == ['shoulder', 'elbow']
    assert len(message.position) == len(message.velocity) == len(message.effort) == 2
    assert sim.alive()


def test_ground_truth_samples_the_physics_between_readings_in_order(launch, probe):
    launch('sim', '-p', 'ground_truth_rate_hz:=250.0')
    readings = probe.collect(JointState, '/joint_states')
    truth = probe.collect(JointState, '/sim/ground_truth')
    wait_for_messages(probe, readings, 5)
    first, first_reading = len(truth), len(readings)
    probe.spin_for(1.0)
    stamps = [stamp_s(m) for m in truth[first:]]
    gaps_ms = [(b - a) * 1e3 for a, b in zip(stamps, stamps[1:])]
    assert min(gaps_ms) > 0.0                               # each instant once, in order
    assert sorted(gaps_ms)[len(gaps_ms) // 2] == pytest.approx(4.0, abs=0.5)   # 250 Hz
    assert 35 <= len(readings) - first_reading <= 60        # the readings stay at 50 Hz


def test_under_localhost_discovery_it_talks_over_udp_not_shared_memory(launch, probe):
    """Jazzy's LOCALHOST range adds Fast DDS shared memory, whose port checks can freeze a
    process for 333 ms; the node keeps the range and drops the shared memory."""
    sim = launch('sim', environment={'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
                                     'FASTRTPS_DEFAULT_PROFILES_FILE': None})
    received = probe.collect(JointState, '/joint_states')
    wait_for_messages(probe, received, 3)
    mapped = Path(f'/proc/{sim.process.pid}/maps').read_text()
    assert '/dev/shm/fastrtps' not in mapped


def test_arm_rests_then_falls_from_horizontal_at_zero_volts(launch, probe):
    launch('sim', '-p', 'initial_position:=[0.0, 0.0]')
    truth = probe.collect(JointState, '/sim/ground_truth')
    wait_for_messages(probe, truth, 1)
    probe.spin_for(0.5)
    assert truth[-1].position[0] == pytest.approx(0.0, abs=1e-9)   # resting, at horizontal
    publisher = probe.node.create_publisher(Float64MultiArray, '/voltage_command', 10)
    probe.spin_until(lambda: publisher.get_subscription_count() > 0, 10.0)
    released = len(truth)
    publisher.publish(Float64MultiArray(data=[0.0, 0.0]))  # 0 V: released, and it falls
    probe.spin_for(1.5)
    falling = truth[released:]
    assert min(m.velocity[0] for m in falling) < -0.5      # swinging down under gravity
    assert falling[-1].position[0] < -0.3                  # onto its hard stop ...
    assert min(m.position[0] for m in falling) >= -0.349 - 1e-9    # ... and not through it


def test_malformed_commands_do_not_stop_it(launch, probe):
    sim = launch('sim', '-p', 'initial_position:=[0.0, 0.0]')
    states = probe.collect(JointState, '/joint_states')
    truth = probe.collect(JointState, '/sim/ground_truth')
    wait_for_messages(probe, states, 1)
    publisher = probe.node.create_publisher(Float64MultiArray, '/voltage_command', 10)
    probe.spin_until(lambda: publisher.get_subscription_count() > 0, 10.0)
    for bad in ([1.0], [1.0, 2.0, 3.0], [math.nan, 0.0], [0.0, math.inf], []):
        publisher.publish(Float64MultiArray(data=bad))
        probe.spin_for(0.05)
    count = len(states)
    probe.spin_for(1.0)
    assert sim.alive()
    assert len(states) > count + 20
    assert 'rejected a voltage_command' in sim.output()
    assert all(math.isfinite(p) for m in truth[-10:] for p in m.position)


def test_voltage_drives_the_arm_and_reset_restores_it(launch, probe):
    launch('sim')
    truth = probe.collect(JointState, '/sim/ground_truth')
    wait_for_messages(probe, truth, 1)
    publisher = probe.node.create_publisher(Float64MultiArray, '/voltage_command', 10)
    probe.spin_until(lambda: publisher.get_subscription_count() > 0, 10.0)
    for _ in range(25):                                    # 0.5 s of +12 V on the elbow
        publisher.publish(Float64MultiArray(data=[0.0, 12.0]))
        probe.spin_for(0.02)
    assert truth[-1].position[1] > -1.5708 + 0.2
    response = probe.call(Trigger, '/sim/reset', Trigger.Request())
    assert response.success
    reset_s = probe.node.get_clock().now().nanoseconds * 1e-9   # the samples before go out too

    def after_reset():
        return [m for m in truth if stamp_s(m) > reset_s]
    probe.spin_until(after_reset, 5.0)
    assert after_reset()[0].position[1] == pytest.approx(-1.5708, abs=0.03)


def test_set_state_maps_positions_by_joint_name_and_refuses_unknown_names(launch, probe):
    sim = launch('sim', '-p', 'initial_position:=[1.0, -1.0]')
    truth = probe.collect(JointState, '/sim/ground_truth')
    wait_for_messages(probe, truth, 1)
    publisher = probe.node.create_publisher(JointState, '/sim/set_state', 10)
    probe.spin_until(lambda: publisher.get_subscription_count() > 0, 10.0)
    publisher.publish(JointState(name=['elbow', 'shoulder'], position=[-0.5, 1.2]))
    assert probe.spin_until(lambda: truth[-1].position[0] == pytest.approx(1.2, abs=1e-6), 5.0)
    assert truth[-1].position[1] == pytest.approx(-0.5, abs=1e-6)       # by name, not order
    publisher.publish(JointState(name=['shoulder', 'wrist'], position=[0.3, 0.3]))
    probe.spin_for(0.5)
    assert truth[-1].position[0] == pytest.approx(1.2, abs=1e-6)        # refused: unchanged
    assert 'rejected set_state' in sim.output()


def test_battery_and_motor_currents_follow_the_load(launch, probe):
    """At rest the bus is at the battery's 12 V and no current flows; full voltage on both
    joints from rest draws the current limits and sags the bus (BatteryState's sign: the
    current is negative while the battery discharges)."""
    launch('sim', '-p', 'initial_position:=[0.0, 0.0]')
    battery = probe.collect(BatteryState, '/battery_state')
    currents = probe.collect(Float64MultiArray, '/motor_currents')
    wait_for_messages(probe, battery, 2)
    assert battery[-1].voltage == pytest.approx(12.0) and battery[-1].current == 0.0
    publisher = probe.node.create_publisher(Float64MultiArray, '/voltage_command', 10)
    probe.spin_until(lambda: publisher.get_subscription_count() > 0, 10.0)
    began = len(battery)
    for _ in range(5):
        publisher.publish(Float64MultiArray(data=[12.0, 12.0]))
        probe.spin_for(0.02)
    drawn = battery[began:]
    assert drawn and min(m.voltage for m in drawn) < 10.5
    assert min(m.current for m in drawn) < -20.0
    assert max(abs(m.data[1]) for m in currents[began:]) <= 80.0 + 1e-6
