"""The bridge end to end on one machine: frc_robot_sim (a real ntcore NT4 server, its robot
loop at a phase of 7 ms) stands in for the roboRIO; frc_bridge, controller and planner run
as installed processes on their own ROS domain.

Where the arm went is measured on the stand-in's truth (``/arm/sim/true_state``), read by
an NT client of the test's own, straight from the robot: never through the bridge. A lost
connection is each side going silent (SIGSTOP), as the other side sees a pulled cable: the
robot must hold the arm where its last profile ends on its own, the bridge must say it lost
the robot, and the controller must stop as its joint states do.
"""

import math
import os
import signal
import time

from diagnostic_msgs.msg import DiagnosticStatus
from frc_rig import ARM, GOALS, reach, running_rig
import numpy as np
import pytest
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from arm_control.frc import contract as nt
from arm_control.frc.tables import now_us
from arm_control.model.dynamics import ArmDynamics
from arm_control.nodes.common import COMMANDS


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    yield from running_rig(tmp_path_factory, 'voltage')


def test_the_arm_reaches_benchmark_goals_through_the_robot(rig):
    reach(rig, GOALS)


def test_the_robot_s_readings_reach_ros_stamped_and_consistent(rig):
    """Held still, the effort the bridge derives from the robot's motor currents is the
    torque that holds the arm against gravity; the battery is being discharged."""
    since = time.monotonic()
    assert rig.spin_until(lambda: len([1 for t, _ in rig.heard['battery'] if t > since]) > 100,
                          10.0)
    states = [m for t, m in rig.heard['joint_states'] if t > since]
    assert all(list(m.name) == ['shoulder', 'elbow'] for m in states)
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in states]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert abs(stamps[-1] - time.time()) < 0.5             # the robot's time, on ROS's clock
    q = rig.watch.true_q()
    gravity = np.array(ArmDynamics(ARM).gravity_torque(q))
    # At rest the motors' torque is gravity's. The median of the still samples (within 3
    # sigmas of the velocity noise): on a loaded machine a late command lets a loop or two
    # run at 0 V, and the arm sags and is taken back (effort 8 % above gravity, moving).
    still = [m.effort for m in states[-100:] if np.max(np.abs(m.velocity)) < 0.06]
    assert len(still) >= 10, f'{len(still)} still samples of the last 100'
    effort = np.median(still, axis=0)
    assert effort == pytest.approx(gravity, rel=0.05, abs=2.0)
    battery = [m for t, m in rig.heard['battery'] if t > since][-1]
    # Holding against gravity draws from the battery: the bus just below its 12 V.
    assert 11.0 < battery.voltage < ARM.battery.nominal_voltage and battery.current < 0.0
    assert len(rig.heard['currents'][-1][1].data) == 2
    assert rig.heard['encoders'] and len(rig.heard['encoders'][-1][1].position) == 2
    # The Mechanism2d on NT draws the arm where the robot reads it.
    upper = rig.watch.instance.getDoubleTopic(f'{nt.MECHANISM_TABLE}/arm/upper_arm/angle')
    fore = rig.watch.instance.getDoubleTopic(f'{nt.MECHANISM_TABLE}/arm/upper_arm/forearm/angle')
    drawn = np.radians([upper.subscribe(math.nan).get(), fore.subscribe(math.nan).get()])
    assert np.max(np.abs(drawn - q)) < math.radians(1.5)


def test_a_disabled_robot_means_0v_and_a_disabled_controller(rig):
    since, since_nt = time.monotonic(), now_us() * 1e-6
    rig.watch.enable.set(False)
    assert rig.spin_until(lambda: rig.said('robot disabled: 0 V', since) and
                          rig.state == 'disabled', 3.0), rig.said('', since)
    rig.probe.spin_for(0.2)
    rig.watch.poll()
    disabled_at = rig.said('robot disabled', since)[0][0]
    # From the loop that saw the robot disabled on, 0 V; the bridge sends 0 V once it knows.
    disabled_s = min(t for t, v in rig.watch.samples['enabled'] if t > since_nt and not v)
    assert all(v == [0.0, 0.0] for t, v in rig.watch.samples['applied'] if t >= disabled_s)
    late = [v for t, v in rig.watch.samples['commands'] if t > disabled_s + 0.1]
    assert late and all(v == [0.0, 0.0] for v in late)
    rig.watch.enable.set(True)
    assert rig.spin_until(lambda: rig.said('robot enabled', disabled_at) and
                          rig.state == 'waiting', 3.0), rig.said('', since)
    rig.probe.spin_for(0.5)
    rig.watch.poll()
    recent = rig.watch.samples['applied'][-5:]
    assert any(abs(x) > 0.3 for _, v in recent for x in v)   # holding it against gravity


def paused(process, seconds: float, rig) -> None:
    """SIGSTOP ``process`` for ``seconds`` (the probe keeps listening), then SIGCONT."""
    os.kill(process.pid, signal.SIGSTOP)
    try:
        rig.spin_until(lambda: False, seconds)
    finally:
        os.kill(process.pid, signal.SIGCONT)


def test_the_robot_holds_the_arm_where_its_profile_ends_when_the_bridge_goes_silent(rig):
    """The controller sends profiles that end at rest with their holding volts: with the
    bridge silent for half a second, the robot plays the last to its end and holds the arm
    there (never a stale voltage, never a fall); then the controller carries on."""
    # From an arm held still (at start it may still be settling): where the last profile ends.
    assert rig.spin_until(lambda: rig.state in ('waiting', 'holding') and
                          rig.held_at(rig.watch.true_q(), math.radians(0.3)), 10.0)
    assert rig.watch.samples['profiles'], 'the controller sends no profiles'
    held_q = rig.watch.true_q()
    stopped_s = now_us() * 1e-6
    paused(rig.nodes['frc_bridge'].process, 0.5, rig)
    rig.watch.poll()
    during = [(t, s) for t, s in rig.watch.samples['truth'] if stopped_s < t < stopped_s + 0.5]
    assert len(during) > 15
    moved = max(np.max(np.abs(np.array(s[:2]) - held_q)) for _, s in during)
    print(f'the bridge silent 0.5 s: the arm within {math.degrees(moved):.2f} deg of its hold')
    assert moved < math.radians(1.0)
    applied = [v for t, v in rig.watch.samples['applied'] if stopped_s < t < stopped_s + 0.5]
    assert all(any(abs(x) > 0.3 for x in v) for v in applied)     # holding against gravity
    since = time.monotonic()
    assert rig.spin_until(lambda: rig.state in ('waiting', 'holding') and
                          rig.held_at(rig.watch.true_q(), math.radians(1.0)), 10.0), \
        rig.said('', since, 'controller_events')


def test_the_bridge_says_it_lost_the_robot_and_the_controller_stops(rig):
    """The robot goes silent for half a second: the bridge says so at once (log, event,
    diagnostics ERROR); the controller, its joint states gone, stops commanding, and holds
    the arm again when the robot is back."""
    assert rig.spin_until(lambda: rig.state in ('waiting', 'holding'), 5.0)
    since, since_nt = time.monotonic(), now_us() * 1e-6
    paused(rig.robot, 0.5, rig)
    resumed_nt = now_us() * 1e-6
    lost = rig.said('lost the robot', since)
    assert lost, rig.said('', since)
    said_at, message = lost[0]
    assert said_at - since < 0.3, f'said after {said_at - since:.3f} s'
    assert 'no readings for 0.1' in message
    # Lost, the bridge sends nothing, not even 0 V: into a link that only stalled, that
    # would arrive late and drop the arm the robot holds at its last profile's end.
    lost_nt = since_nt + (said_at - since)
    rig.probe.spin_for(0.2)
    rig.watch.poll()
    sent = [t for kind in ('commands', 'profiles') for t, _ in rig.watch.samples[kind]]
    assert not [t for t in sent if lost_nt + 0.05 < t < resumed_nt - 0.01], \
        [round(t - lost_nt, 3) for t in sent if t > lost_nt]
    errors = [status for t, m in rig.heard['diagnostics'] if t >= since for status in m.status
              if status.name == '/frc_bridge' and status.level == DiagnosticStatus.ERROR]
    assert errors and 'lost the robot' in errors[0].message
    assert 'lost the robot' in rig.output('frc_bridge')
    assert rig.spin_until(lambda: rig.said('robot back', since), 5.0), rig.said('', since)
    assert rig.said('no joint states', since, 'controller_events')
    assert 'no_sensors' in [m.data for t, m in rig.heard['states'] if t >= since]
    assert rig.spin_until(lambda: rig.state == 'waiting', 5.0)


def test_bad_input_is_named_and_changes_nothing(rig):
    """Malformed commands from ROS and malformed readings from the robot: each ignored with a
    warning naming it; the bridge keeps bridging."""
    node = rig.probe.node
    voltage = node.create_publisher(Float64MultiArray, '/voltage_command', COMMANDS)
    setpoint = node.create_publisher(JointState, '/controller/setpoint', 10)
    reading = rig.watch.instance.getDoubleArrayTopic(nt.READING.name).publish()
    assert rig.spin_until(lambda: voltage.get_subscription_count() > 0 and
                          setpoint.get_subscription_count() > 0, 5.0)
    voltage.publish(Float64MultiArray(data=[1.0, 2.0, 3.0]))
    voltage.publish(Float64MultiArray(data=[math.nan, 0.0]))
    setpoint.publish(JointState(position=[0.5], velocity=[0.0, 0.0]))
    since = time.monotonic()
    warning = 'ignored a reading: /arm/robot/reading: expected 14 values, got 2'

    def bad_reading_named():
        # Set again until named: a new publisher's first value did not reach the bridge
        # once in a fresh clone's run (the robot's own values went on arriving).
        reading.set([math.inf, 0.0])
        rig.watch.instance.flush()
        return warning in rig.output('frc_bridge')
    assert rig.spin_until(bad_reading_named, 5.0)
    assert rig.spin_until(lambda: len([1 for t, _ in rig.heard['joint_states']
                                       if t > since]) > 10, 5.0)
    said = rig.output('frc_bridge')
    assert said.count('ignored voltage_command: ') >= 1
    assert 'ignored controller/setpoint position: expected [shoulder, elbow]' in said
    assert rig.nodes['frc_bridge'].alive()
    assert all(math.isfinite(p) for t, m in rig.heard['joint_states'] if t > since
               for p in m.position)


def test_a_bad_parameter_stops_the_bridge_naming_it(launch):
    bridge = launch('frc_bridge', '-p', 'mode:=torque')
    assert bridge.process.wait(30) == 2
    assert "'mode' = 'torque': expected one of ['voltage', 'setpoint']" in bridge.output()


def test_the_run_is_a_wpilog_that_advantagescope_opens(rig):
    """Stopped, the bridge sends 0 V on its way out and closes the log."""
    from wpilog_reader import read_wpilog
    rig.watch.poll()
    assert rig.nodes['frc_bridge'].stop() == 0
    rig.probe.spin_for(0.3)
    rig.watch.poll()
    assert rig.watch.samples['commands'][-1][1] == [0.0, 0.0]
    entries = read_wpilog(rig.wpilog)
    readings = entries[nt.READING.name][2]
    assert len(readings) > 100 and entries[nt.READING.name][0] == 'double[]'
    times = [t for t, _ in readings]
    assert times == sorted(times)
    states = [v for _, v in entries[nt.ARM_STATE.name][2]]
    assert {'tracking', 'holding', 'disabled', 'no_sensors'} <= set(states)
    events = [v for _, v in entries['/bridge/events'][2]]
    assert any('lost the robot' in e for e in events)
    assert entries[nt.COMMAND.name][2]
