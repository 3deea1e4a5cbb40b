"""The ``controller`` node: goals in, motor voltages out -- a shell around ArmController.

Subscribes ``joint_states``, ``motor_encoders`` (JointState), ``battery_state`` (BatteryState:
the bus voltage the feedforward and the estimate use), ``goal_point`` (PointStamped: queued),
``goal_preset`` (String: replaces the queue and the motion, as a driver's button) and
``driver_velocity`` (TwistStamped: tool velocity in arm_base). Publishes ``voltage_command``
every period, ``arm_state`` (latched), ``~/setpoint``, ``~/estimate``, ``~/goal_queue``
(latched), ``~/events`` ("kind: sentence") and ``/diagnostics``. Client of ``plan_path``;
serves ``~/estop``, ``~/reset``, ``~/cancel`` (Trigger) and ``~/enable`` (SetBool).

Three threads of work: the control loop (``ControlLoop``) steps the core and commands the
motors; the executor takes messages and services; a worker process times plans
(``PlanWorker``). The core is shared under a lock held only for quick calls. 0 V on exit.
"""

import math
import signal
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped, TwistStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import uninstall_signal_handlers
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import SetBool, Trigger

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.controller import ArmController
from arm_control.control.events import EventKind as Kind
from arm_control.control.plans import PathPlan, TimedPlan
from arm_control.control.sensing import SensorReading
from arm_control.control.state_machine import ArmState
from arm_control.nodes import messages
from arm_control.nodes.common import (COMMANDS, declare_parameters, guarded, LATCHED,
                                      loop_statistics, PLANNER_AVAILABLE, run, STATE_STREAM,
                                      status)
from arm_control.nodes.control_loop import ControlLoop
from arm_control.nodes.plan_worker import PlanWorker
from arm_control.parameters import ParameterError
from arm_control.planning.planner import waypoints_from_poses

SHUTDOWN_ACK_S = 0.5              # at most this long on exit for the 0 V command to arrive
# What may change at run time (``ros2 param set``): gains, reserves, tolerances, dwell and the
# presets. The arm's physics, its world and the loop's rate are read once.
TUNABLE = ('shoulder_pid', 'elbow_pid', 'integrator_limit_v', 'feedback_voltage_reserve',
           'driving_voltage_reserve', 'goal_tolerance_rad', 'settled_velocity_rad_s',
           'dwell_s', 'presets.')
# Goals are kept until taken: a burst (a script, a flood) is answered, not dropped.
GOALS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
EVENTS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


class ControllerNode(Node):

    def __init__(self):
        super().__init__('controller')
        self.core = None
        params = declare_parameters(self, 'controller', TUNABLE, self.on_parameters)
        self.arm = ArmConfig.from_parameters(params)
        self.config = ControllerConfig.from_parameters(params)
        self.config.check_against(self.arm)
        self.core = ArmController(self.arm, self.config)
        self.lock = threading.Lock()                # the core, between the threads
        # Reading, encoders, bus: (value, received at); the loop takes the reading.
        self.reading = self.encoders = self.bus = None
        self.bad_inputs = self.bad_inputs_said = 0
        self.plan_calls = {}                        # unanswered planner calls -> sent at
        self.last_state = self.last_queue_version = None
        self.loop_periods_s, self.loop_compute_s, self.last_tick_s = [], [], None
        # Fast loops want the interpreter back soon: 1 ms, not 5, for another thread.
        sys.setswitchinterval(0.001)

        self.voltage_pub = self.create_publisher(Float64MultiArray, 'voltage_command', COMMANDS)
        self.setpoint_pub = self.create_publisher(JointState, '~/setpoint', STATE_STREAM)
        self.estimate_pub = self.create_publisher(JointState, '~/estimate', STATE_STREAM)
        self.state_pub = self.create_publisher(String, 'arm_state', LATCHED)
        self.queue_pub = self.create_publisher(Path, '~/goal_queue', LATCHED)
        self.events_pub = self.create_publisher(String, '~/events', EVENTS)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(JointState, 'joint_states', self.on_joint_states, STATE_STREAM)
        self.create_subscription(JointState, 'motor_encoders', self.on_encoders, STATE_STREAM)
        self.create_subscription(BatteryState, 'battery_state', self.on_battery, STATE_STREAM)
        self.create_subscription(PointStamped, 'goal_point', self.on_goal_point, GOALS)
        self.create_subscription(String, 'goal_preset', self.on_goal_preset, COMMANDS)
        self.create_subscription(TwistStamped, 'driver_velocity', self.on_driver, COMMANDS)
        self.plan_client = self.create_client(GetPlan, 'plan_path')
        for name, kind, handler in (('~/estop', Trigger, self.on_estop),
                                    ('~/reset', Trigger, self.on_reset),
                                    ('~/cancel', Trigger, self.on_cancel),
                                    ('~/enable', SetBool, self.on_enable)):
            self.create_service(kind, name, handler)
        self.outputs = self.create_guard_condition(self.publish_outputs)
        self.create_timer(0.2, self.watch_planner)
        self.create_timer(1.0, self.publish_diagnostics)
        self.worker = PlanWorker(self.arm, self.config, self.on_timed_plan)
        self.loop = ControlLoop(self.get_clock(), self.config.period_s, self.tick)
        self.publish_outputs()
        self.loop.start()
        self.get_logger().info(f'controlling the arm at {self.config.loop_rate_hz:g} Hz; '
                               'waiting for joint_states')

    def now_s(self) -> float:
        return self.loop.now_s()

    def command(self, call, *args):
        """Call the core under the lock, then say what it said."""
        with self.lock:
            result = call(self.now_s(), *args)
        self.publish_outputs()
        return result

    # ------------------------------------------------------------------ messages in

    @guarded
    def on_joint_states(self, msg: JointState) -> None:
        position = messages.joint_pair(msg, 'position')
        velocity = messages.joint_pair(msg, 'velocity') or [math.nan, math.nan]
        if position is None or not messages.within(position, 4.0 * math.pi):
            return self.warn_bad(f'ignored joint_states: expected finite positions of '
                                 f'[shoulder, elbow] within two turns, got {len(msg.name)} '
                                 f'names and {len(msg.position)} positions')
        now, fresh = self.now_s(), self.config.joint_state_timeout_s
        encoder = self.encoders[0] if self.encoders and now - self.encoders[1] <= fresh \
            else (math.nan, math.nan)
        bus = self.bus[0] if self.bus and now - self.bus[1] <= fresh else math.nan
        self.reading = (SensorReading(tuple(position), tuple(velocity), tuple(encoder),
                                      messages.stamp_s(msg.header), bus), now)

    @guarded
    def on_encoders(self, msg: JointState) -> None:
        position = messages.joint_pair(msg, 'position')
        if position is None or not messages.within(position, 4.0 * math.pi):
            return self.warn_bad('ignored motor_encoders: expected finite positions of '
                                 '[shoulder, elbow] within two turns')
        self.encoders = (position, self.now_s())

    @guarded
    def on_battery(self, msg: BatteryState) -> None:
        if not (math.isfinite(msg.voltage) and 0.0 < msg.voltage <= 2.0 *
                self.arm.battery.nominal_voltage):
            return self.warn_bad(f'ignored battery_state: voltage {msg.voltage} V')
        self.bus = (float(msg.voltage), self.now_s())

    @guarded
    def on_goal_point(self, msg: PointStamped) -> None:
        problem = messages.name_problem(msg.header.frame_id, 'frame_id')
        if problem:
            return self.command(self.core.goals.reject, f'goal rejected: {problem}',
                                'oversized')
        p = msg.point
        self.command(self.core.submit_goal, p.x, p.y, p.z, msg.header.frame_id)

    @guarded
    def on_goal_preset(self, msg: String) -> None:
        problem = messages.name_problem(msg.data, 'preset name')
        if problem:
            return self.command(self.core.goals.reject, f'preset rejected: {problem}',
                                'oversized')
        self.command(self.core.submit_preset, msg.data.strip())

    @guarded
    def on_driver(self, msg: TwistStamped) -> None:
        problem = messages.name_problem(msg.header.frame_id, 'frame_id')
        if problem:
            return self.command(self.core.goals.reject, f'driver command rejected: {problem}',
                                'oversized')
        linear = msg.twist.linear
        self.command(self.core.driver_command, linear.x, linear.y, msg.header.frame_id)

    @guarded
    def on_estop(self, request, response):
        response.success, response.message = self.command(self.core.estop,
                                                          'e-stop requested by service')
        return response

    @guarded
    def on_reset(self, request, response):
        response.success, response.message = self.command(self.core.reset)
        return response

    @guarded
    def on_cancel(self, request, response):
        response.success, response.message = self.command(self.core.cancel)
        return response

    @guarded
    def on_enable(self, request, response):
        response.success, response.message = self.command(self.core.enable, bool(request.data))
        return response

    def on_parameters(self, params):
        """A run-time change: validated whole, taken from the next period, or refused with
        the reason (the old values kept)."""
        if self.core is None:
            return None                             # the overrides at start: read below
        try:
            arm = ArmConfig.from_parameters(params)
            config = ControllerConfig.from_parameters(params)
            config.check_against(arm)
        except ParameterError as error:
            return str(error)
        changed = [name for name in TUNABLE if getattr(config, name, None) !=
                   getattr(self.config, name, None)] + (
            ['presets'] if arm.presets != self.arm.presets else [])
        self.worker.retune(arm, config)
        with self.lock:
            self.core.retune(arm, config)
            self.core.events.say(self.now_s(), Kind.PARAMETERS, 'info',
                                 f'changed at run time: {", ".join(changed) or "nothing"}')
        self.arm, self.config = arm, config
        self.outputs.trigger()
        return None

    def warn_bad(self, message: str) -> None:
        self.bad_inputs += 1
        self.get_logger().warning(message, throttle_duration_sec=1.0)

    # ------------------------------------------------------------------ the loop's thread

    def tick(self) -> None:
        began, now = time.perf_counter(), self.now_s()
        reading, self.reading = self.reading, None
        with self.lock:
            try:
                voltage = self.core.step(now, *(reading or (None, None)))
            except Exception as error:              # a bug must stop the arm, not the node
                self.core.estop(now, f'internal error in the control step: {error!r}',
                                cut_power=True)
                voltage = np.zeros(2)
            estimate, setpoint = self.core.estimate, self.core.setpoint
        if estimate is not None:     # before the first reading there is nothing to command
            self.voltage_pub.publish(Float64MultiArray(data=[float(v) for v in voltage]))
            stamp = self.get_clock().now().to_msg()
            self.setpoint_pub.publish(messages.joint_state(stamp, setpoint[0], setpoint[1]))
            self.estimate_pub.publish(messages.joint_state(stamp, estimate[:2], estimate[2:]))
        self.outputs.trigger()
        if self.last_tick_s is not None:
            self.loop_periods_s.append(now - self.last_tick_s)
        self.last_tick_s = now
        self.loop_compute_s.append(time.perf_counter() - began)

    # ------------------------------------------------------------------ planning

    def on_timed_plan(self, timed: TimedPlan) -> None:
        """From the worker's thread: hand the plan to the core, and run the loop now."""
        with self.lock:
            self.core.on_timed_plan(self.now_s(), timed)
        self.loop.poke()

    def send_plan_requests(self, requests) -> None:
        for request in requests:
            message = GetPlan.Request()
            stamp = self.get_clock().now().to_msg()
            message.start = messages.pose_stamped(
                *self.core.kinematics.tool_pose(request.start_q), messages.header(stamp))
            message.goal = messages.pose_stamped(*request.goal.xy, 0.0,
                                                 messages.header(stamp))
            future = self.plan_client.call_async(message)
            self.plan_calls[future] = self.now_s()
            future.add_done_callback(lambda done, r=request: self.on_plan_response(r, done))

    @guarded
    def on_plan_response(self, request, future) -> None:
        """The planner's path as joint waypoints, to the worker for timing."""
        self.plan_calls.pop(future, None)
        try:
            poses = messages.poses_of(future.result().plan)
        except Exception as error:                  # a broken answer must not stop the node
            return self.on_timed_plan(TimedPlan(request, None, f'the planner call failed: '
                                                               f'{error!r}'))
        if not poses:
            return self.on_timed_plan(TimedPlan(request, None, 'no plan to '
                                                f'{request.goal.label}: the planner found no '
                                                'path (its log says why)'))
        self.worker.submit(request, PathPlan(waypoints_from_poses(
            self.core.kinematics, poses, request.start_q, self.core.forbidden)))

    def watch_planner(self) -> None:
        """Whether goals can be planned -- the client reaches the planner and the worker is
        up (said by the core when it changes) -- and calls a restarted planner will never
        answer, forgotten after twice the timeout."""
        ready = self.plan_client.service_is_ready() and self.worker.ready.is_set()
        now = self.now_s()
        for future, sent_s in list(self.plan_calls.items()):
            if now - sent_s > 2.0 * self.config.planner_timeout_s:
                self.plan_client.remove_pending_request(future)
                del self.plan_calls[future]
        self.command(self.core.on_planner_available, ready)

    # ------------------------------------------------------------------ outputs

    def publish_outputs(self) -> None:
        """In the executor: events, state and queue as they changed; plan requests out."""
        with self.lock:
            events = self.core.events.take()
            state, pending = self.core.state, self.core.pending_goals()
            version = self.core.goals.queue.version
            requests = self.core.take_plan_requests()
        log = self.get_logger()
        for event in events:
            self.events_pub.publish(String(data=str(event)))
            # rclpy ties a severity to its call site: one call per level.
            if event.level == 'info':
                log.info(str(event))
            elif event.level == 'warning':
                log.warning(str(event))
            else:
                log.error(str(event))
        if state != self.last_state:
            self.last_state = state
            self.state_pub.publish(String(data=str(state)))
        if version != self.last_queue_version:
            self.last_queue_version = version
            path = Path(header=messages.header(self.get_clock().now().to_msg()))
            path.poses = [messages.pose_stamped(g.x_m, g.y_m, 0.0, path.header)
                          for g in pending]
            self.queue_pub.publish(path)
        if requests:
            self.send_plan_requests(requests)

    @guarded
    def publish_diagnostics(self) -> None:
        now = self.now_s()
        periods, self.loop_periods_s = self.loop_periods_s, []
        compute, self.loop_compute_s = self.loop_compute_s, []
        with self.lock:
            state, last_error = self.core.state, self.core.last_error
            values = dict(self.core.diagnostics(now))
            planner = self.core.planner_available
        level, message = DiagnosticStatus.OK, str(state)
        if state in (ArmState.ERROR, ArmState.NO_SENSORS, ArmState.ESTOPPED):
            level = DiagnosticStatus.ERROR if state == ArmState.ESTOPPED else DiagnosticStatus.WARN
            message = f'{state}: {last_error}'
        stats = loop_statistics(periods, compute)
        problems = [f'control loop stalled for {stats["worst"]:.3f} s'] \
            if stats['worst'] > 3 * self.config.period_s else []
        if planner is False:
            problems.append('the planner (plan_path) is not available: goals will fail')
        if not self.worker.alive:
            problems.append('the plan worker process is gone: goals will fail')
        malformed, self.bad_inputs_said = self.bad_inputs - self.bad_inputs_said, self.bad_inputs
        if malformed:
            problems.append(f'{malformed} malformed messages ignored (the log says which)')
        if problems:
            level = max(level, DiagnosticStatus.WARN)
            message = '; '.join([message] + problems)
        values.update({
            'loop period mean (s)': f'{stats["mean"]:.4f}',
            'loop period worst (s)': f'{stats["worst"]:.4f}',
            'compute per cycle median (ms)': f'{1000 * stats["compute median"]:.3f}',
            'compute per cycle worst (ms)': f'{1000 * stats["compute worst"]:.3f}',
            'bad inputs ignored': self.bad_inputs, PLANNER_AVAILABLE: bool(planner),
        })
        diagnostic = DiagnosticArray()
        diagnostic.header.stamp = self.get_clock().now().to_msg()
        diagnostic.status = [status(self, level, message, values)]
        self.diagnostics_pub.publish(diagnostic)

    def on_shutdown(self) -> None:
        """0 V on the way out: the arm must not keep the last command."""
        self.loop.stop()
        self.worker.close()
        try:
            for _ in range(3):
                self.voltage_pub.publish(Float64MultiArray(data=[0.0, 0.0]))
            # Reliable: make sure the sim has it before the process goes away.
            self.voltage_pub.wait_for_all_acked(Duration(seconds=SHUTDOWN_ACK_S))
        except Exception as error:              # the context may already be gone
            self.get_logger().warning(f'could not send 0 V on shutdown: {error}')


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def controller_node() -> ControllerNode:
    """The node, with SIGINT and SIGTERM handed back to Python: rclpy's own handlers shut
    the context down before ``on_shutdown`` runs, so the last 0 V could not go out."""
    uninstall_signal_handlers()
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _interrupt)
    return ControllerNode()


def main(args=None):
    sys.exit(run(controller_node, args))


if __name__ == '__main__':
    main()
