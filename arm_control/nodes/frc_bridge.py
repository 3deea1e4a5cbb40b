"""The ``frc_bridge`` node: a real FRC robot (or ``frc_robot_sim``) in the sim's place.

An NT4 client (pyntcore) of the roboRIO, found by team number or address. Each of the
robot's readings (one NT value per robot loop) becomes ``joint_states``, ``motor_encoders``
(JointState), ``battery_state`` (BatteryState) and ``motor_currents`` (Float64MultiArray),
all stamped with the instant the robot read its sensors. ``voltage_command`` goes to the
robot, flushed at once: a voltage pair as a command for the instant it is sent, a profile
(``model.profile``) with its start on the robot's clock; in mode ``setpoint``, instead of
the controller's voltages, its ``controller/setpoint`` with the model's feedforward as a
one-setpoint profile for its stamp. A disabled robot gets 0 V; a dropped connection, or
readings stopped for ``reading_timeout_s`` (an error), no commands (a link that only stalled
would deliver them late): the robot stops by its own rule. The controller is
disabled and enabled with the robot (``controller/enable``); when the robot is lost, its
joint states stop, and it stops commanding on its own. Draws the arm as a Mechanism2d on NT
(its own connection, at most 25 Hz),
``~/events`` (String) and ``/diagnostics``; logs the run as a .wpilog when ``wpilog_path``
is set. The rules live in ``arm_control.frc``; this shell only wires ROS to them.
"""

from collections import deque
import math
import sys
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import ntcore
from rclpy.node import Node
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, Header, String
from std_srvs.srv import SetBool

from arm_control import realtime
from arm_control.config import ArmConfig
from arm_control.frc import contract as nt
from arm_control.frc.codec import decode_reading, encode_profile, encode_voltage, profile_command
from arm_control.frc.conversions import (clamp_voltage, commanding, joint_pair, ros_stamp_ns,
                                         SetpointFeedforward)
from arm_control.frc.mechanism import Mechanism2dPublisher
from arm_control.frc.rules import LinkState, RobotLink, ZERO_V
from arm_control.frc.settings import FrcBridgeConfig
from arm_control.frc.tables import BridgeTables, DRAW_PERIOD_S, now_us
from arm_control.frc.wpilog import (BRIDGE_EVENTS, CONTROLLER_SETPOINT,
                                    CONTROLLER_SETPOINT_VELOCITY, CONTROLLER_VOLTAGE, RunLog)
from arm_control.model import profile as profiles
from arm_control.model.dynamics import ArmDynamics
from arm_control.nodes.common import (COMMANDS, declare_parameters, LATCHED, run,
                                      STATE_STREAM, status)
from arm_control.nodes.frc_messages import age_summary, reading_messages
from arm_control.nodes.messages import command_of
from arm_control.parameters import ParameterError

IDENTITY = 'frc_bridge'             # how the robot's NT server sees this client
SETPOINT_MAX_AGE_S = 0.1            # mode setpoint: an older setpoint is not sent
ENABLE_RETRY_S = 0.5                # controller/enable not there: ask again this often
REDIAL_PERIOD_S = 0.2               # disconnected: try the robot again this often
SHUTDOWN_SEND_S = 0.05              # on exit, the last 0 V gets this long to leave
REFUSAL_LOG_PERIOD_S = 1.0          # bad input from one source is said at most this often
LEVELS = {'info': DiagnosticStatus.OK, 'warning': DiagnosticStatus.WARN,
          'error': DiagnosticStatus.ERROR}
STATE_STATUS = {
    LinkState.ENABLED: (DiagnosticStatus.OK, 'robot enabled'),
    LinkState.DISABLED: (DiagnosticStatus.WARN, 'robot disabled: 0 V'),
    LinkState.CONNECTING: (DiagnosticStatus.WARN, 'waiting for the robot at {server}'),
    LinkState.LOST: (DiagnosticStatus.ERROR, 'lost the robot: no commands')}


def stamp_s(header: Header) -> float:
    return header.stamp.sec + 1e-9 * header.stamp.nanosec


class FrcBridgeNode(Node):

    def __init__(self):
        super().__init__('frc_bridge')
        params = declare_parameters(self, 'frc_bridge')
        self.arm = ArmConfig.from_parameters(params)
        self.config = FrcBridgeConfig.from_parameters(params)
        self.dynamics = ArmDynamics(self.arm)
        self.feedforward = SetpointFeedforward(self.dynamics, self.arm.battery.nominal_voltage)
        self.link = RobotLink(self.config.reading_timeout_s)
        self.run_log = None
        if self.config.wpilog_path:
            try:
                self.run_log = RunLog(self.config.wpilog_path)
            except OSError as error:
                raise ParameterError(
                    f"parameter 'wpilog_path' = {self.config.wpilog_path!r}: {error}") from error
        self.started = time.monotonic()
        self.setpoint = None            # (position, velocity, feedforward_v, received at, stamp)
        self.drawn_s = {'arm': -math.inf, 'setpoint': -math.inf}
        self.reading_ages_ms = []       # sensors' instant -> taken here, since the last report
        self.counts = {'readings': 0, 'commands sent': 0, 'inputs refused': 0}
        self.counts_said = dict(self.counts)
        self.refused_said_s = {}        # when bad input from each source was last said
        self.enable_wanted = None       # what the controller should be told, until it answers
        self.enable_call = None
        self.enable_asked_s = -math.inf
        self.connection_news = deque()  # from ntcore's listener thread
        self.dialled_s = 0.0            # when the robot was last tried (or seen connected)

        self.reading_pubs = {name: self.create_publisher(kind, name, STATE_STREAM)
                             for name, kind in (('joint_states', JointState),
                                                ('motor_encoders', JointState),
                                                ('battery_state', BatteryState),
                                                ('motor_currents', Float64MultiArray))}
        self.events_pub = self.create_publisher(String, '~/events', 100)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Float64MultiArray, 'voltage_command', self.on_voltage, COMMANDS)
        self.create_subscription(JointState, 'controller/setpoint', self.on_setpoint,
                                 STATE_STREAM)
        self.create_subscription(String, 'arm_state', self.on_arm_state, LATCHED)
        self.enable_client = self.create_client(SetBool, 'controller/enable')

        self.instance = ntcore.NetworkTableInstance.create()
        self.tables = BridgeTables(self.instance, IDENTITY, self.config.team_number,
                                   self.config.server_address, self.config.nt_port)
        self.mechanism = Mechanism2dPublisher(self.tables.drawing, self.arm)
        # ntcore calls listeners on its own thread: they only wake the executor, which
        # reads the values on this node's thread.
        self.nt_wake = self.create_guard_condition(self.on_nt)
        self.listeners = [
            self.instance.addListener(self.tables.reading,
                                      ntcore.EventFlags.kValueRemote, lambda _: self.wake()),
            self.instance.addConnectionListener(False, self.on_connection)]

        # Every thread there is now (ntcore's, DDS's, this one) at real-time priority.
        problem = realtime.raise_process(self.config.realtime_priority)
        if problem:
            self.get_logger().warning(problem)
        self.create_timer(nt.LOOP_PERIOD_S, self.check_link)
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f'bridging to the robot at {self.config.server} over NT4, mode '
            f'{self.config.mode}' + (f', logging to {self.run_log.path}' if self.run_log else ''))

    def now_s(self) -> float:
        return time.monotonic() - self.started

    def refuse(self, source: str, message: str) -> None:
        """Warn about bad input from ``source``, at most once a second for each source."""
        self.counts['inputs refused'] += 1
        if self.now_s() - self.refused_said_s.get(source, -math.inf) >= REFUSAL_LOG_PERIOD_S:
            self.refused_said_s[source] = self.now_s()
            self.get_logger().warning(message)

    def record(self, topic: nt.NtTopic, value, time_us: int = 0) -> None:
        if self.run_log is not None:
            self.run_log.append(topic.name, value, time_us)

    # ------------------------------------------------------------------ robot -> ROS

    def wake(self) -> None:
        """ntcore's thread: wake the executor (not once it is shutting down)."""
        try:
            self.nt_wake.trigger()
        except Exception:           # the guard condition is gone: the node is closing
            pass

    def on_connection(self, event) -> None:
        """ntcore's thread: note it, wake the executor."""
        connected = bool(event.flags & ntcore.EventFlags.kConnected)
        self.connection_news.append((connected, event.data.remote_ip, event.data.remote_port))
        self.wake()

    def on_nt(self) -> None:
        while self.connection_news:
            connected, ip, port = self.connection_news.popleft()
            if connected:
                self.get_logger().info(f'NT4 connected to {ip}:{port}')
            else:
                self.get_logger().warning(f'NT4 disconnected from {ip}:{port}')
        if not self.tables.connected():
            self.on_link_event(self.link.check(self.now_s(), False))    # dropped: say so now
        for value in self.tables.reading.readQueue():
            try:
                reading = decode_reading(value.value)
            except ValueError as error:
                self.refuse(nt.READING.name, f'ignored a reading: {error}')
                continue
            self.record(nt.READING, value.value, reading.time_us - self.tables.server_offset_us())
            self.publish_reading(reading)
            self.on_link_event(self.link.on_reading(self.now_s(), reading.enabled))

    def ros_stamp(self, server_time_us: int) -> Header:
        """A time on the NT server's clock as a ROS header stamp (ntcore's offset to the
        server, then this process's NT clock against ROS's)."""
        local_us = server_time_us - self.tables.server_offset_us()
        stamp_ns = ros_stamp_ns(local_us, now_us(), self.get_clock().now().nanoseconds)
        return Header(stamp=Time(sec=stamp_ns // 1_000_000_000,
                                 nanosec=stamp_ns % 1_000_000_000), frame_id='')

    def publish_reading(self, reading) -> None:
        """One robot loop's reading, whole: every message gets its one stamp."""
        self.counts['readings'] += 1
        self.reading_ages_ms.append(1e-3 * (self.tables.server_now_us() - reading.time_us))
        for name, message in reading_messages(reading, self.ros_stamp(reading.time_us),
                                              self.dynamics).items():
            self.reading_pubs[name].publish(message)
        self.draw('arm', reading.position_rad)

    def draw(self, root: str, position) -> None:
        """The Mechanism2d, at most every DRAW_PERIOD_S: its own connection, never flushed."""
        if self.now_s() - self.drawn_s[root] >= DRAW_PERIOD_S:
            self.drawn_s[root] = self.now_s()
            self.mechanism.show(root, position)

    # ------------------------------------------------------------------ ROS -> robot

    def on_voltage(self, msg: Float64MultiArray) -> None:
        """A voltage pair or a profile (``model.profile``): to the robot, for its instant."""
        try:
            command = command_of(msg)
        except profiles.ProfileError as error:
            self.refuse('voltage_command',
                        f'ignored voltage_command: {error}; the robot stops on its own when '
                        'commands stop')
            return
        if isinstance(command, profiles.Profile):
            if self.link.may_command:
                start_us = self.server_time_us(round(command.start_s * 1e9))
                self.send(encode_profile(profile_command(start_us, command)))
            elif self.link.outgoing(ZERO_V) is not None:
                self.send(encode_voltage(self.tables.server_now_us(), ZERO_V))
            self.record(CONTROLLER_VOLTAGE, list(msg.data))
            return
        voltage = clamp_voltage(command, self.arm.battery.nominal_voltage)
        outgoing = self.link.outgoing(voltage)
        if outgoing is None:
            pass                # lost: nothing, the robot stops by its own rule
        elif self.config.mode == 'voltage' or not commanding(outgoing):
            self.send(encode_voltage(self.tables.server_now_us(), outgoing))
        elif self.setpoint is not None and \
                self.now_s() - self.setpoint[3] <= SETPOINT_MAX_AGE_S:
            position, velocity, feedforward_v, _, stamp_ns = self.setpoint
            self.send(encode_profile(profile_command(
                self.server_time_us(stamp_ns), profiles.Profile(
                    0.0, nt.LOOP_PERIOD_S, self.config.setpoint_gains,
                    (profiles.Setpoint(position, velocity, feedforward_v),)))))
        # else nothing: no fresh setpoint, and the robot's own timeout stops it
        self.record(CONTROLLER_VOLTAGE, voltage)

    def send(self, command) -> None:
        """A command to the robot, flushed at once; logged after it has gone."""
        self.tables.send_command(command)
        self.counts['commands sent'] += 1
        self.record(nt.COMMAND, command)

    def server_time_us(self, ros_stamp_ns: int) -> int:
        """A ROS stamp on the NT server's clock: its age on the ROS clock, back from now."""
        age_us = (self.get_clock().now().nanoseconds - ros_stamp_ns) // 1000
        return self.tables.server_now_us() - age_us

    def on_setpoint(self, msg: JointState) -> None:
        try:
            position = joint_pair(msg.position, 'controller/setpoint position')
            velocity = joint_pair(msg.velocity, 'controller/setpoint velocity')
        except ValueError as error:
            self.refuse('controller/setpoint', f'ignored {error}')
            return
        if self.config.mode == 'setpoint':
            feedforward_v = self.feedforward(stamp_s(msg.header), position, velocity)
            stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            self.setpoint = (position, velocity, feedforward_v, self.now_s(), stamp_ns)
        self.draw('setpoint', position)
        self.record(CONTROLLER_SETPOINT, position)
        self.record(CONTROLLER_SETPOINT_VELOCITY, velocity)

    def on_arm_state(self, msg: String) -> None:
        self.tables.send_state(msg.data)
        self.record(nt.ARM_STATE, msg.data)

    # ------------------------------------------------------------------ the link

    def check_link(self) -> None:
        if self.link.silent_s > 0.5 * self.config.reading_timeout_s:
            self.on_nt()        # what arrived while this process was busy is not lost time
        connected = self.tables.connected()
        self.on_link_event(self.link.check(self.now_s(), connected))
        if connected:
            self.dialled_s = self.now_s()
        elif self.now_s() - self.dialled_s >= REDIAL_PERIOD_S:
            self.dialled_s = self.now_s()
            self.tables.redial()
        self.tell_controller()

    def on_link_event(self, event) -> None:
        """Say a change of the link, stop the robot if it may not move, tell the controller."""
        if event is None:
            return
        if event.level == 'error':
            self.get_logger().error(event.message)
        elif event.level == 'warning':
            self.get_logger().warning(event.message)
        else:
            self.get_logger().info(event.message)
        self.events_pub.publish(String(data=event.message))
        self.record(BRIDGE_EVENTS, event.message)
        if not self.link.may_command and self.link.outgoing(ZERO_V) is not None:
            self.send(encode_voltage(self.tables.server_now_us(), ZERO_V))
        if event.controller_enabled is not None:
            self.enable_wanted = event.controller_enabled
            self.enable_asked_s = -math.inf
            self.tell_controller()
        self.publish_diagnostics(event)

    def tell_controller(self) -> None:
        """Ask controller/enable for what the link wants, once it answers; again if it is
        not there yet."""
        wanted = self.enable_wanted
        if wanted is None or self.enable_call is not None or \
                self.now_s() - self.enable_asked_s < ENABLE_RETRY_S:
            return
        self.enable_asked_s = self.now_s()
        if not self.enable_client.service_is_ready():
            self.get_logger().warning(
                f"controller/enable is not there: cannot {'enable' if wanted else 'disable'} "
                'the controller yet', throttle_duration_sec=5.0)
            return
        self.enable_call = self.enable_client.call_async(SetBool.Request(data=wanted))
        self.enable_call.add_done_callback(lambda future: self.on_enable_answer(wanted, future))

    def on_enable_answer(self, wanted: bool, future) -> None:
        self.enable_call = None
        response = future.result()
        if self.enable_wanted == wanted:
            self.enable_wanted = None
        if response is None or not response.success:
            why = response.message if response is not None else 'no answer'
            self.get_logger().warning(
                f"the controller did not {'enable' if wanted else 'disable'}: {why}; the "
                f"bridge sends {'its voltages' if wanted else '0 V'} regardless")

    # ------------------------------------------------------------------ health

    def publish_diagnostics(self, event=None) -> None:
        state = self.link.state
        level, message = STATE_STATUS[state]
        message = message.format(server=self.config.server)
        if event is not None:
            level, message = LEVELS[event.level], event.message
        counts = {f'{name} (last s)': self.counts[name] - self.counts_said[name]
                  for name in self.counts}
        if event is None:
            counts.update(age_summary(self.reading_ages_ms))
            self.counts_said = dict(self.counts)
            self.reading_ages_ms = []
        self.refused_said_s = {}        # when bad input from each source was last said
        diagnostic = DiagnosticArray()
        diagnostic.header.stamp = self.get_clock().now().to_msg()
        diagnostic.status = [status(self, level, message, {
            'link': str(state), 'robot': self.config.server, 'mode': self.config.mode,
            'NT connected': self.tables.connected(),
            'last reading age (s)': f'{self.now_s() - self.link.last_reading_s:.3f}',
            **counts, 'wpilog': str(self.run_log.path) if self.run_log else '',
        })]
        self.diagnostics_pub.publish(diagnostic)

    def on_shutdown(self) -> None:
        """0 V on the way out; then ntcore's threads stopped before Python's go away."""
        try:
            self.tables.send_command(encode_voltage(self.tables.server_now_us(), ZERO_V))
            time.sleep(SHUTDOWN_SEND_S)     # NT4 has no acknowledgement: give it time to go
        finally:
            for listener in self.listeners:
                self.instance.removeListener(listener)
            self.tables.close()
            if self.run_log is not None:
                self.run_log.close()


def main(args=None):
    sys.exit(run(FrcBridgeNode, args))


if __name__ == '__main__':
    main()
