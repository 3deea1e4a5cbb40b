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
from pathlib import Path
import signal
import subprocess
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped
import ntcore
import numpy as np
import pytest
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, String

from arm_control import config
from arm_control.frc import contract as nt
from arm_control.frc.codec import decode_command, decode_reading, VoltageCommand
from arm_control.frc.tables import free_port, LOOPBACK, now_us, RECEIVE
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.nodes.common import COMMANDS, controller_sees_planner, LATCHED

ARM = config.load('sim')[0]
KINEMATICS = TwoLinkKinematics(ARM.shoulder.length_m, ARM.elbow.length_m)
# The presets the tour visits first (config/arm.yaml), goals of bench/bench_trajectory.py's
# suite: mid_score, then high_score.
GOALS = [(1.1, 0.9), (0.9, 1.5)]


class RobotWatch:
    """The test's own NT client of the robot: its truth, its readings (what it applied,
    whether it is enabled), what it was sent, and the Driver Station's enable."""

    def __init__(self, port: int):
        self.instance = ntcore.NetworkTableInstance.create()
        self.every = every = ntcore.PubSubOptions(sendAll=True, keepDuplicates=True,
                                                  pollStorage=2000, periodic=0.005)
        self.truth = self.instance.getDoubleArrayTopic(nt.TRUE_STATE.name).subscribe([], every)
        self.reading = self.instance.getDoubleArrayTopic(nt.READING.name).subscribe([], every)
        self.command = self.instance.getDoubleArrayTopic(nt.COMMAND.name).subscribe([], every)
        self.enable = self.instance.getBooleanTopic(nt.SIM_ENABLE.name).publish()
        self.mechanism = ntcore.MultiSubscriber(self.instance, [nt.MECHANISM_TABLE + '/'],
                                                RECEIVE)
        self.instance.startClient4('test watch')
        self.instance.setServer(LOOPBACK, port)
        self.samples = {'truth': [], 'applied': [], 'commands': [], 'enabled': [],
                        'profiles': []}

    def poll(self) -> None:
        """Move what arrived into ``samples``: (time on the robot's clock in s, values)."""
        self.samples['truth'] += [(v.value[0] * 1e-6, v.value[1:])
                                  for v in self.truth.readQueue()]
        for value in self.reading.readQueue():
            try:
                reading = decode_reading(value.value)
            except ValueError:          # the test's own bad readings
                continue
            t = reading.time_us * 1e-6
            self.samples['applied'].append((t, list(reading.applied_voltage_v)))
            self.samples['enabled'].append((t, reading.enabled))
        for value in self.command.readQueue():
            command = decode_command(value.value)
            kind = 'commands' if isinstance(command, VoltageCommand) else 'profiles'
            self.samples[kind].append((command.time_us * 1e-6, list(
                command.voltage_v) if kind == 'commands' else command))

    def true_q(self) -> np.ndarray:
        self.poll()
        return np.array(self.samples['truth'][-1][1][:2])

    def close(self) -> None:
        self.instance.stopClient()
        ntcore.NetworkTableInstance.destroy(self.instance)


class Rig:
    def __init__(self, domain, probe, log_dir: Path, mode: str = 'voltage', phase_s=0.007):
        from ros_harness import install_prefix, NodeProcess, ros_environment
        self.probe, self.log_dir = probe, log_dir
        robot_port = free_port()
        self.robot_log = open(log_dir / 'frc_robot_sim.log', 'w')
        self.robot = subprocess.Popen(
            [str(install_prefix() / 'lib' / 'arm_control' / 'frc_robot_sim'), '--port',
             str(robot_port), '--phase-s', str(phase_s)], env=ros_environment(domain),
            stdout=self.robot_log, stderr=subprocess.STDOUT)
        self.watch = RobotWatch(robot_port)
        self.wpilog = log_dir / 'run.wpilog'
        self.nodes = {
            'frc_bridge': NodeProcess('frc_bridge', domain, [
                '-p', f'nt_port:={robot_port}', '-p', f'wpilog_path:={self.wpilog}',
                '-p', f'mode:={mode}'],
                log_dir),
            'planner': NodeProcess('planner', domain, (), log_dir),
            'controller': NodeProcess('controller', domain, (), log_dir)}
        node = probe.node
        self.heard = {}
        for name, msg_type, topic, qos in (
                ('states', String, '/arm_state', LATCHED),
                ('events', String, '/frc_bridge/events', 100),
                ('controller_events', String, '/controller/events', 100),
                ('diagnostics', DiagnosticArray, '/diagnostics', 50),
                ('joint_states', JointState, '/joint_states', 10),
                ('encoders', JointState, '/motor_encoders', 10),
                ('battery', BatteryState, '/battery_state', 10),
                ('currents', Float64MultiArray, '/motor_currents', 10)):
            self.heard[name] = []
            node.create_subscription(msg_type, topic, self._keep(self.heard[name]), qos)
        self.goal_pub = node.create_publisher(PointStamped, '/goal_point', COMMANDS)

    @staticmethod
    def _keep(into):
        return lambda message: into.append((time.monotonic(), message))

    def spin_until(self, condition, timeout_s: float) -> bool:
        def polled():
            self.watch.poll()
            return condition()
        return self.probe.spin_until(polled, timeout_s)

    @property
    def state(self) -> str:
        return self.heard['states'][-1][1].data if self.heard['states'] else ''

    def said(self, words: str, since_s=-math.inf, name='events') -> list:
        return [(t, m.data) for t, m in self.heard[name] if t >= since_s and words in m.data]

    def held_at(self, q, tolerance_rad, samples=25) -> bool:
        """The last ``samples`` true positions (half a second) all within tolerance of q."""
        recent = self.watch.samples['truth'][-samples:]
        return len(recent) == samples and all(
            np.max(np.abs(np.array(s[:2]) - q)) < tolerance_rad for _, s in recent)

    def ready(self) -> None:
        def controller_ready():
            seen = [controller_sees_planner(m) for _, m in self.heard['diagnostics']]
            seen = [s for s in seen if s is not None]
            return seen and seen[-1] and self.state == 'waiting' and \
                self.goal_pub.get_subscription_count() > 0
        assert self.spin_until(controller_ready, 40.0), \
            f'not ready: arm_state {self.state!r}, bridge {self.output("frc_bridge")}'

    def output(self, name: str) -> str:
        if name == 'frc_robot_sim':
            self.robot_log.flush()
            return (self.log_dir / 'frc_robot_sim.log').read_text()
        return self.nodes[name].output()

    def close(self) -> None:
        for process in self.nodes.values():
            process.stop()
        self.robot.send_signal(signal.SIGINT)
        try:
            self.robot.wait(10)
        except subprocess.TimeoutExpired:
            self.robot.kill()
            self.robot.wait()
        self.robot_log.close()
        self.watch.close()


def running_rig(tmp_path_factory, mode: str, phase_s: float = 0.007):
    """A ready Rig with the bridge in ``mode``, the robot's loop at ``phase_s``, closed after
    the ``yield``."""
    from ros_harness import Probe, ros_domain
    with ros_domain() as domain:
        probe = Probe(domain)
        rig = Rig(domain, probe, tmp_path_factory.mktemp('frc'), mode, phase_s)
        try:
            rig.ready()
            yield rig
        finally:
            rig.close()
            probe.close()


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    yield from running_rig(tmp_path_factory, 'voltage')


def send_goal(rig, x, y) -> None:
    message = PointStamped()
    message.header.frame_id = 'arm_base'
    message.point.x, message.point.y = float(x), float(y)
    rig.goal_pub.publish(message)


def ik(x, y):
    """The branch the arm is on at the end is the controller's choice: both are accepted."""
    return [np.array(q) for q in KINEMATICS.inverse(x, y)]


def reach(rig, goals) -> None:
    """Each goal in turn: reached (the controller says so), then held for half a second
    within 1° on both joints on the robot's own truth."""
    for goal in goals:
        since = time.monotonic()
        send_goal(rig, *goal)
        assert rig.spin_until(lambda: rig.said('reached', since, 'controller_events'), 15.0), \
            [m for _, m in rig.said('', since, 'controller_events')]
        # Held within 1° on both joints, on the robot's own truth.
        assert rig.spin_until(lambda: any(rig.held_at(q, math.radians(1.0))
                                          for q in ik(*goal)), 5.0), \
            f"goal {goal}: the robot's arm is at {rig.watch.true_q()} rad"
        # 1° on each joint moves the tool at most (La + Lb)·1° = 3.1 cm.
        tool = np.array(KINEMATICS.forward(rig.watch.true_q()))
        assert np.linalg.norm(tool - goal) < 0.031, f'goal {goal}: tool at {tool}'


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
    assert rig.spin_until(lambda: rig.state in ('waiting', 'holding'), 5.0)
    rig.probe.spin_for(0.3)
    rig.watch.poll()
    assert rig.watch.samples['profiles'], 'the controller sends no profiles'
    held_q = rig.watch.true_q()
    stopped_s = now_us() * 1e-6
    paused(rig.nodes['frc_bridge'].process, 0.5, rig)
    rig.watch.poll()
    during = [(t, s) for t, s in rig.watch.samples['truth'] if stopped_s < t < stopped_s + 0.5]
    assert len(during) > 15
    assert max(np.max(np.abs(np.array(s[:2]) - held_q)) for _, s in during) < math.radians(1.0)
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
