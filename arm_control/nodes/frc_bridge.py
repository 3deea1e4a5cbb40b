"""The ``frc_bridge`` node: a real FRC robot (or ``frc_robot_sim``) in the sim's place.

An NT4 client (pyntcore) of the roboRIO, found by team number or address. The robot's
readings become ``joint_states``, ``motor_encoders`` (JointState), ``battery_state``
(BatteryState) and ``motor_currents`` (Float64MultiArray), stamped when the robot took
them. ``voltage_command`` goes to the robot with its NT timestamp (mode ``voltage``), or
the controller's ``controller/setpoint`` with the model's feedforward (mode ``setpoint``),
for a loop on the roboRIO. A disabled robot, or one whose readings stop for
``reading_timeout_s`` (an error), gets 0 V. The controller is disabled and enabled with the
robot (``controller/enable``); when the robot is lost, its joint states stop, and it stops
commanding on its own. Publishes the arm as a Mechanism2d on NT,
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

from arm_control.config import ArmConfig, JOINT_NAMES
from arm_control.frc import contract as nt
from arm_control.frc.conversions import (battery_state_current_a, clamp_voltage, commanding,
                                         finite_number, joint_effort_nm, joint_pair,
                                         ros_stamp_ns, SetpointFeedforward)
from arm_control.frc.mechanism import Mechanism2dPublisher
from arm_control.frc.rules import LinkState, RobotLink, ZERO_V
from arm_control.frc.settings import FrcBridgeConfig
from arm_control.frc.tables import BridgeTables, now_us
from arm_control.frc.wpilog import (BRIDGE_EVENTS, CONTROLLER_SETPOINT,
                                    CONTROLLER_SETPOINT_VELOCITY, CONTROLLER_VOLTAGE, RunLog)
from arm_control.model.dynamics import ArmDynamics
from arm_control.nodes.common import (COMMANDS, declare_parameters, LATCHED, run,
                                      STATE_STREAM, status)
from arm_control.parameters import ParameterError

IDENTITY = 'frc_bridge'             # how the robot's NT server sees this client
SETPOINT_MAX_AGE_S = 0.1            # mode setpoint: an older setpoint is not sent
ENABLE_RETRY_S = 0.5                # controller/enable not there: ask again this often
SHUTDOWN_SEND_S = 0.05              # on exit, the last 0 V gets this long to leave
REFUSAL_LOG_PERIOD_S = 1.0          # bad input from one source is said at most this often
LEVELS = {'info': DiagnosticStatus.OK, 'warning': DiagnosticStatus.WARN,
          'error': DiagnosticStatus.ERROR}


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
        self.setpoint = None            # (position, velocity, feedforward_v, received at)
        self.velocity = None            # the robot's latest velocity, effort and supply current
        self.effort = []
        self.supply_current_a = math.nan
        self.counts = {'readings': 0, 'commands sent': 0, 'inputs refused': 0}
        self.counts_said = dict(self.counts)
        self.refused_said_s = {}        # when bad input from each source was last said
        self.enable_wanted = None       # what the controller should be told, until it answers
        self.enable_call = None
        self.enable_asked_s = -math.inf
        self.connection_news = deque()  # from ntcore's listener thread

        self.joint_states_pub = self.create_publisher(JointState, 'joint_states', STATE_STREAM)
        self.encoders_pub = self.create_publisher(JointState, 'motor_encoders', STATE_STREAM)
        self.battery_pub = self.create_publisher(BatteryState, 'battery_state', STATE_STREAM)
        self.currents_pub = self.create_publisher(Float64MultiArray, 'motor_currents',
                                                  STATE_STREAM)
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
        self.mechanism = Mechanism2dPublisher(self.instance, self.arm)
        # ntcore calls listeners on its own thread: they only wake the executor, which
        # reads the values on this node's thread. The robot sets the position last in each
        # loop, so that one wakes it for all the loop's readings.
        self.nt_wake = self.create_guard_condition(self.on_nt)
        self.listeners = [
            self.instance.addListener(self.tables.readings[nt.POSITION],
                                      ntcore.EventFlags.kValueRemote, lambda _: self.wake()),
            self.instance.addConnectionListener(False, self.on_connection)]

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
        nt_now, ros_now = now_us(), self.get_clock().now().nanoseconds
        readings = self.tables.readings

        def header(value) -> Header:
            stamp_ns = ros_stamp_ns(value.time, nt_now, ros_now)
            return Header(stamp=Time(sec=stamp_ns // 1_000_000_000,
                                     nanosec=stamp_ns % 1_000_000_000), frame_id='')

        for value in readings[nt.ENABLED].readQueue():
            self.record(nt.ENABLED, bool(value.value), value.time)
        for value in readings[nt.APPLIED_VOLTAGE].readQueue():
            self.record(nt.APPLIED_VOLTAGE, value.value, value.time)
        for value in readings[nt.VELOCITY].readQueue():
            velocity = self.checked(joint_pair, value, nt.VELOCITY)
            if velocity is not None:
                self.velocity = velocity
        for value in readings[nt.MOTOR_CURRENT].readQueue():
            current = self.checked(joint_pair, value, nt.MOTOR_CURRENT)
            if current is not None:
                self.effort = list(joint_effort_nm(current, self.dynamics))
                self.currents_pub.publish(Float64MultiArray(data=list(current)))
        for value in readings[nt.SUPPLY_CURRENT].readQueue():
            supply_a = self.checked(finite_number, value, nt.SUPPLY_CURRENT)
            if supply_a is not None:
                self.supply_current_a = supply_a
        for value in readings[nt.BUS_VOLTAGE].readQueue():
            bus_v = self.checked(finite_number, value, nt.BUS_VOLTAGE)
            if bus_v is not None:
                self.battery_pub.publish(battery_state(
                    header(value), bus_v, battery_state_current_a(self.supply_current_a)))
        for value in readings[nt.ENCODER].readQueue():
            encoder = self.checked(joint_pair, value, nt.ENCODER)
            if encoder is not None:
                self.encoders_pub.publish(JointState(header=header(value),
                                                     name=list(JOINT_NAMES),
                                                     position=list(encoder)))
        for value in readings[nt.POSITION].readQueue():
            position = self.checked(joint_pair, value, nt.POSITION)
            if position is None:
                continue
            self.counts['readings'] += 1
            self.joint_states_pub.publish(JointState(
                header=header(value), name=list(JOINT_NAMES), position=list(position),
                velocity=list(self.velocity or ()), effort=self.effort))
            self.mechanism.show('arm', position)
            enabled = readings[nt.ENABLED].getAtomic()
            if enabled.time:                # a reading counts once the robot said its mode
                self.on_link_event(self.link.on_reading(self.now_s(), enabled.value))

    def checked(self, convert, value, topic: nt.NtTopic):
        """``convert(value)``, logged; None (and a warning) if the robot sent nonsense."""
        try:
            converted = convert(value.value, topic.name)
        except ValueError as error:
            self.refuse(topic.name, f'ignored a reading: {error}')
            return None
        self.record(topic, converted, value.time)
        return converted

    # ------------------------------------------------------------------ ROS -> robot

    def on_voltage(self, msg: Float64MultiArray) -> None:
        try:
            voltage = clamp_voltage(joint_pair(msg.data, 'voltage_command'),
                                    self.arm.battery.nominal_voltage)
        except ValueError as error:
            self.refuse('voltage_command',
                        f'ignored {error}; the robot stops on its own when commands stop')
            return
        self.record(CONTROLLER_VOLTAGE, voltage)
        outgoing = self.link.outgoing(voltage)
        if self.config.mode == 'voltage' or not commanding(outgoing):
            self.tables.send_voltage(outgoing)
            self.record(nt.VOLTAGE_COMMAND, outgoing)
        elif self.setpoint is not None and \
                self.now_s() - self.setpoint[3] <= SETPOINT_MAX_AGE_S:
            self.tables.send_setpoint(*self.setpoint[:3])
            for topic, values in zip(nt.SETPOINT_COMMAND, self.setpoint[:3]):
                self.record(topic, values)
        else:
            return      # no fresh setpoint: nothing, and the robot's own timeout stops it
        self.counts['commands sent'] += 1

    def on_setpoint(self, msg: JointState) -> None:
        try:
            position = joint_pair(msg.position, 'controller/setpoint position')
            velocity = joint_pair(msg.velocity, 'controller/setpoint velocity')
        except ValueError as error:
            self.refuse('controller/setpoint', f'ignored {error}')
            return
        if self.config.mode == 'setpoint':
            feedforward_v = self.feedforward(stamp_s(msg.header), position, velocity)
            self.setpoint = (position, velocity, feedforward_v, self.now_s())
        self.mechanism.show('setpoint', position)
        self.record(CONTROLLER_SETPOINT, position)
        self.record(CONTROLLER_SETPOINT_VELOCITY, velocity)

    def on_arm_state(self, msg: String) -> None:
        self.tables.send_state(msg.data)
        self.record(nt.ARM_STATE, msg.data)

    # ------------------------------------------------------------------ the link

    def check_link(self) -> None:
        if self.now_s() - self.link.last_reading_s > self.config.reading_timeout_s:
            self.on_nt()        # what arrived while this process was busy is not lost time
        self.on_link_event(self.link.check(self.now_s(), self.tables.connected()))
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
        if not self.link.may_command:
            self.tables.send_voltage(ZERO_V)
            self.record(nt.VOLTAGE_COMMAND, ZERO_V)
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
        level, message = {
            LinkState.ENABLED: (DiagnosticStatus.OK, 'robot enabled'),
            LinkState.DISABLED: (DiagnosticStatus.WARN, 'robot disabled: 0 V'),
            LinkState.CONNECTING: (DiagnosticStatus.WARN,
                                   f'waiting for the robot at {self.config.server}'),
            LinkState.LOST: (DiagnosticStatus.ERROR, 'lost the robot: 0 V'),
        }[state]
        if event is not None:
            level, message = LEVELS[event.level], event.message
        counts = {f'{name} (last s)': self.counts[name] - self.counts_said[name]
                  for name in self.counts}
        if event is None:
            self.counts_said = dict(self.counts)
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
            self.tables.send_voltage(ZERO_V)
            time.sleep(SHUTDOWN_SEND_S)     # NT4 has no acknowledgement: give it time to go
        finally:
            for listener in self.listeners:
                self.instance.removeListener(listener)
            self.tables.close()
            if self.run_log is not None:
                self.run_log.close()


def battery_state(header: Header, bus_voltage_v: float, current_a: float) -> BatteryState:
    """BatteryState with what the robot measures; the rest NaN, as the message asks."""
    return BatteryState(header=header, voltage=bus_voltage_v, current=current_a,
                        temperature=math.nan, charge=math.nan, capacity=math.nan,
                        design_capacity=math.nan, percentage=math.nan, present=True,
                        power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
                        power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_UNKNOWN)


def main(args=None):
    sys.exit(run(FrcBridgeNode, args))


if __name__ == '__main__':
    main()
