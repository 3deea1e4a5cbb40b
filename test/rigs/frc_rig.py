"""The FRC rig: frc_robot_sim (a real ntcore NT4 server) standing in for the roboRIO, with
frc_bridge, controller and planner as installed processes on their own ROS domain, and the
robot's truth read by an NT client of the test's own."""

import math
from pathlib import Path
import signal
import subprocess
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import ntcore
import numpy as np
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, String

from arm_control import config
from arm_control.frc import contract as nt
from arm_control.frc.codec import decode_command, decode_reading, VoltageCommand
from arm_control.frc.tables import free_port, LOOPBACK, RECEIVE
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
