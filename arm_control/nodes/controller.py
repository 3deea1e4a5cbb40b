"""The ``controller`` node: goals in, motor voltages out -- a thin shell around ArmController.

Subscribes ``joint_states`` and ``motor_encoders`` (JointState), ``goal_point``
(PointStamped: queued), ``goal_preset`` (String: a preset's name; it replaces the queue and
the current motion, as a driver's button) and ``driver_velocity`` (TwistStamped: tool
velocity x, y in m/s in arm_base). Publishes ``voltage_command`` (Float64MultiArray) every
control period, ``arm_state`` (String, latched), ``~/setpoint`` and ``~/estimate``
(JointState), ``~/goal_queue`` (Path, latched: the current goal first, then the queued
ones), ``~/events`` (String: each rejection, failure, e-stop with its reason) and
``/diagnostics``. Client of ``plan_path`` (GetPlan); serves ``~/estop``, ``~/reset``,
``~/cancel`` (Trigger) and ``~/enable`` (SetBool).

The control loop never waits for the planner: requests go out asynchronously, and the
answer is checked and timed on a worker thread, then handed to the loop. Sends 0 V on exit.
"""

from collections import deque
from concurrent.futures import ThreadPoolExecutor
import functools
import math
import signal
import statistics
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped, PoseStamped, Quaternion, TwistStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import uninstall_signal_handlers
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, String
from std_srvs.srv import SetBool, Trigger

from arm_control.config import ArmConfig, ControllerConfig, JOINT_NAMES
from arm_control.control.arm_controller import ArmController, SensorReading
from arm_control.control.state_machine import ArmState
from arm_control.nodes.common import (COMMANDS, declare_parameters, LATCHED,
                                      PLANNER_AVAILABLE, run, STATE_STREAM, status)
from arm_control.planning.planner import waypoints_from_poses

FRAME = 'arm_base'
EVENT_QOS_DEPTH = 1000           # every event of a burst (a flood of goals) reaches listeners
SHUTDOWN_ACK_S = 0.5              # at most this long on exit for the 0 V command to arrive
# No sensor of this arm reads an angle beyond two turns either way, nor a joint speed beyond
# this (the motors' free speed through the gearbox is about 3.5 rad/s): such a value is a
# malformed message, not a reading. A joint a little past its limit is real: it e-stops.
MAX_SENSOR_ANGLE_RAD = 4.0 * math.pi
MAX_SENSOR_SPEED_RAD_S = 100.0
# Events logged at most this many per window (errors always): the rest are counted.
LOG_LINES_PER_WINDOW = 20
LOG_WINDOW_S = 1.0
# Goals wait in DDS this many deep: a burst (a script, a flood) is answered, not dropped.
GOALS = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)


class ServicePlan:
    """The planner service's answer as the core takes it (ok, reason, waypoints_rad)."""

    def __init__(self, waypoints_rad, reason=''):
        self.waypoints_rad = waypoints_rad
        self.reason = reason
        self.ok = not reason


def joint_pair(msg: JointState, field: str):
    """(shoulder, elbow) of ``field`` by joint name (or in order without names), or None."""
    values = list(getattr(msg, field))
    names = list(msg.name)
    if names:
        if not all(name in names for name in JOINT_NAMES) or len(values) != len(names):
            return None
        values = [values[names.index(name)] for name in JOINT_NAMES]
    if len(values) != 2:
        return None
    return values


class LogBudget:
    """At most ``lines`` log lines per window of ``window_s``; the rest are counted."""

    def __init__(self, lines: int, window_s: float):
        self.lines, self.window_s = lines, window_s
        self.window_start_s = -math.inf
        self.used = self.left_out = 0

    def roll(self, now_s: float) -> int:
        """Start a new window if this one is over; return how many the old one left out."""
        if now_s - self.window_start_s < self.window_s:
            return 0
        left_out, self.left_out = self.left_out, 0
        self.window_start_s, self.used = now_s, 0
        return left_out

    def take(self) -> bool:
        """One more line in this window: may it be logged?"""
        self.used += 1
        if self.used > self.lines:
            self.left_out += 1
            return False
        return True


def within(values, bound: float) -> bool:
    """Every value finite and within ±bound."""
    return all(math.isfinite(v) and abs(v) <= bound for v in values)


def yaw_of(q) -> float:
    """Rotation about z of a quaternion: atan2(2(wz + xy), 1 − 2(y² + z²))."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def guarded(callback):
    """A callback that logs what it raises instead of stopping the node: no message, however
    malformed, may take the controller down (a service still answers, unsuccessfully)."""
    @functools.wraps(callback)
    def wrapper(self, *args):
        try:
            return callback(self, *args)
        except Exception as error:
            self.bad_inputs += 1
            self.get_logger().error(f'{callback.__name__} failed on its input: {error!r}',
                                    throttle_duration_sec=1.0)
            if len(args) == 2 and hasattr(args[1], 'success'):
                args[1].success, args[1].message = False, f'failed: {error!r}'
                return args[1]
            return None
    return wrapper


class ControllerNode(Node):

    def __init__(self):
        super().__init__('controller')
        params = declare_parameters(self, 'controller')
        self.arm = ArmConfig.from_parameters(params)
        self.config = ControllerConfig.from_parameters(params)
        self.core = ArmController(self.arm, self.config)
        self.kinematics = self.core.kinematics
        self.started = time.monotonic()

        self.reading = None                 # (SensorReading, received at) not yet stepped
        self.joint_states_s = -math.inf
        self.encoders = None                # (positions, received at)
        self.bad_inputs = 0
        self.bad_inputs_said = 0            # ... up to the last diagnostics
        self.timed_plans = deque()          # from the worker thread to the loop
        self.plan_calls = {}                # planner calls not yet answered: future -> sent at
        self.workers = ThreadPoolExecutor(max_workers=1, thread_name_prefix='timing')
        self.last_state = None
        self.log_budget = LogBudget(LOG_LINES_PER_WINDOW, LOG_WINDOW_S)
        self.estop_message = ''
        self.last_queue_version = -1
        self.tick_periods_s, self.compute_s = [], []
        self.last_tick = None

        self.voltage_pub = self.create_publisher(Float64MultiArray, 'voltage_command', COMMANDS)
        self.state_pub = self.create_publisher(String, 'arm_state', LATCHED)
        self.setpoint_pub = self.create_publisher(JointState, '~/setpoint', STATE_STREAM)
        self.estimate_pub = self.create_publisher(JointState, '~/estimate', STATE_STREAM)
        self.queue_pub = self.create_publisher(Path, '~/goal_queue', LATCHED)
        self.events_pub = self.create_publisher(String, '~/events', EVENT_QOS_DEPTH)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(JointState, 'joint_states', self.on_joint_states, STATE_STREAM)
        self.create_subscription(JointState, 'motor_encoders', self.on_encoders, STATE_STREAM)
        self.create_subscription(PointStamped, 'goal_point', self.on_goal_point, GOALS)
        self.create_subscription(String, 'goal_preset', self.on_goal_preset, COMMANDS)
        self.create_subscription(TwistStamped, 'driver_velocity', self.on_driver, COMMANDS)
        self.plan_client = self.create_client(GetPlan, 'plan_path')
        self.create_service(Trigger, '~/estop', self.on_estop)
        self.create_service(Trigger, '~/reset', self.on_reset)
        self.create_service(Trigger, '~/cancel', self.on_cancel)
        self.create_service(SetBool, '~/enable', self.on_enable)

        self.period_s = 1.0 / self.config.loop_rate_hz
        self.create_timer(self.period_s, self.tick)
        self.create_timer(1.0, self.publish_diagnostics)
        self.publish_state()
        self.publish_queue()
        self.get_logger().info(f'controlling the arm at {self.config.loop_rate_hz:g} Hz; '
                               'waiting for joint_states')

    # ------------------------------------------------------------------ inputs

    def now_s(self) -> float:
        return time.monotonic() - self.started

    def warn_bad(self, message: str) -> None:
        self.bad_inputs += 1
        self.get_logger().warning(message, throttle_duration_sec=1.0)

    @guarded
    def on_joint_states(self, msg: JointState) -> None:
        position = joint_pair(msg, 'position')
        velocity = joint_pair(msg, 'velocity') or [math.nan, math.nan]
        if position is None or not within(position, MAX_SENSOR_ANGLE_RAD) or not within(
                [v for v in velocity if not math.isnan(v)], MAX_SENSOR_SPEED_RAD_S):
            self.warn_bad(f'ignored joint_states: expected finite positions of '
                          f'{list(JOINT_NAMES)} within {MAX_SENSOR_ANGLE_RAD:.1f} rad '
                          f'(velocities, if any, within {MAX_SENSOR_SPEED_RAD_S:g} rad/s), '
                          f'got names={list(msg.name)} position={list(msg.position)} '
                          f'velocity={list(msg.velocity)}')
            return
        now = self.now_s()
        encoder = [math.nan, math.nan]
        if self.encoders is not None and now - self.encoders[1] <= \
                self.config.joint_state_timeout_s:
            encoder = self.encoders[0]
        stamp = msg.header.stamp
        sampled = stamp.sec + 1e-9 * stamp.nanosec if stamp.sec or stamp.nanosec else math.nan
        self.reading = (SensorReading(tuple(position), tuple(velocity), tuple(encoder),
                                      sampled), now)
        self.joint_states_s = now

    @guarded
    def on_encoders(self, msg: JointState) -> None:
        position = joint_pair(msg, 'position')
        if position is None or not within(position, MAX_SENSOR_ANGLE_RAD):
            self.warn_bad(f'ignored motor_encoders: expected finite positions of '
                          f'{list(JOINT_NAMES)} within {MAX_SENSOR_ANGLE_RAD:.1f} rad, '
                          f'got {list(msg.position)}')
            return
        self.encoders = (position, self.now_s())

    @guarded
    def on_goal_point(self, msg: PointStamped) -> None:
        p = msg.point
        self.core.submit_goal(self.now_s(), p.x, p.y, p.z, msg.header.frame_id)
        self.after_command()

    @guarded
    def on_goal_preset(self, msg: String) -> None:
        self.core.submit_preset(self.now_s(), msg.data.strip())
        self.after_command()

    @guarded
    def on_driver(self, msg: TwistStamped) -> None:
        linear = msg.twist.linear
        self.core.driver_command(self.now_s(), linear.x, linear.y, msg.header.frame_id)
        self.after_command()

    @guarded
    def on_estop(self, request, response):
        response.success, response.message = self.core.estop(self.now_s(),
                                                             'e-stop requested by service')
        self.publish_voltage(np.zeros(2))
        self.after_command()
        return response

    @guarded
    def on_reset(self, request, response):
        response.success, response.message = self.core.reset(self.now_s())
        self.after_command()
        return response

    @guarded
    def on_cancel(self, request, response):
        response.success, response.message = self.core.cancel(self.now_s())
        self.after_command()
        return response

    @guarded
    def on_enable(self, request, response):
        response.success, response.message = self.core.enable(self.now_s(), bool(request.data))
        if not request.data:
            self.publish_voltage(np.zeros(2))
        self.after_command()
        return response

    def after_command(self) -> None:
        """Say what the core said, and show a changed state or queue at once."""
        self.publish_events()
        self.publish_state()
        self.publish_queue()

    # ------------------------------------------------------------------ the loop

    def tick(self) -> None:
        began = time.perf_counter()
        now = self.now_s()
        while self.timed_plans:
            self.core.on_timed_plan(now, self.timed_plans.popleft())
        reading, taken = self.reading if self.reading is not None else (None, None)
        self.reading = None
        try:
            voltage = self.core.step(now, reading, taken)
        except Exception as error:              # a bug must stop the arm, not the node
            self.get_logger().error(f'control step failed: {error!r}',
                                    throttle_duration_sec=1.0)
            self.core.estop(now, f'internal error in the control step: {error!r}',
                            cut_power=True)
            voltage = np.zeros(2)
        self.publish_voltage(voltage)
        self.send_plan_requests()
        self.publish_setpoint_and_estimate()
        self.after_command()
        if self.last_tick is not None:
            self.tick_periods_s.append(now - self.last_tick)
        self.last_tick = now
        self.compute_s.append(time.perf_counter() - began)

    def publish_voltage(self, voltage) -> None:
        """Command the motors -- once the arm is ours: before the first joint state there is
        nothing to say, and a 0 V command would release a sim that rests the arm until the
        first command arrives (``rest_until_first_command``), dropping it at bring-up."""
        if self.core.estimate is None:
            return
        self.voltage_pub.publish(Float64MultiArray(data=[float(v) for v in voltage]))

    def send_plan_requests(self) -> None:
        self.forget_unanswered_plans()
        ready = self.plan_client.service_is_ready()
        self.core.on_planner_available(self.now_s(), ready)
        if not ready:
            return                              # the core rejects the goal at its timeout
        for request in self.core.take_plan_requests():
            start = self.kinematics.tool_pose(request.start_q)
            message = GetPlan.Request()
            message.start = self.pose(*start)
            message.goal = self.pose(*request.goal.xy, 0.0)
            future = self.plan_client.call_async(message)
            self.plan_calls[future] = self.now_s()
            future.add_done_callback(
                lambda done, request=request: self.on_plan_response(request, done))

    def forget_unanswered_plans(self) -> None:
        """A call the planner will never answer (restarted with it in flight) would stay in
        the client's pending requests for good. Long after the core gave up on it (its
        planner_timeout_s), the client forgets it; an answer after that is ignored."""
        now = self.now_s()
        for future, sent_s in list(self.plan_calls.items()):
            if now - sent_s > 2.0 * self.config.planner_timeout_s:
                self.plan_client.remove_pending_request(future)
                del self.plan_calls[future]

    def pose(self, x, y, yaw) -> PoseStamped:
        pose = PoseStamped()
        pose.header = Header(stamp=self.get_clock().now().to_msg(), frame_id=FRAME)
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        pose.pose.orientation = Quaternion(z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))
        return pose

    @guarded
    def on_plan_response(self, request, future) -> None:
        """Runs in the executor: turn poses into joint angles, then time them off-loop."""
        self.plan_calls.pop(future, None)
        try:
            path = future.result().plan
            poses = [(p.pose.position.x, p.pose.position.y, yaw_of(p.pose.orientation))
                     for p in path.poses]
        except Exception as error:              # a broken answer must not stop the node
            self.timed_plans.append(self.core.time_plan(
                request, ServicePlan(None, f'the planner call failed: {error}')))
            return
        if not poses:
            plan = ServicePlan(None, 'the planner found no path (its log says why)')
        else:
            plan = ServicePlan(waypoints_from_poses(self.kinematics, poses, request.start_q,
                                                    self.core.forbidden))
        self.workers.submit(self.time_off_loop, request, plan)

    def time_off_loop(self, request, plan) -> None:
        try:
            self.timed_plans.append(self.core.time_plan(request, plan))
        except Exception as error:              # never leave the goal hanging
            self.timed_plans.append(self.core.time_plan(
                request, ServicePlan(None, f'timing the plan failed: {error}')))

    # ------------------------------------------------------------------ outputs

    def joint_state(self, position, velocity) -> JointState:
        return JointState(header=Header(stamp=self.get_clock().now().to_msg(), frame_id=''),
                          name=list(JOINT_NAMES), position=[float(p) for p in position],
                          velocity=[float(v) for v in velocity])

    def publish_setpoint_and_estimate(self) -> None:
        estimate = self.core.estimate
        if estimate is None:
            return
        q, qd, _ = self.core.setpoint
        self.setpoint_pub.publish(self.joint_state(q, qd))
        self.estimate_pub.publish(self.joint_state(estimate[:2], estimate[2:]))

    def publish_events(self) -> None:
        """Every event on ~/events; in the log, errors always, the rest within a budget (a
        flood of goals must not become a flood of lines), with a count of what was left out."""
        log = self.get_logger()
        for event in self.core.take_events():
            self.events_pub.publish(String(data=event.message))
            if event.message.startswith('E-STOP'):      # kept for diagnostics until reset
                self.estop_message = event.message.split(';')[0]
            self.say_left_out()
            if not self.log_budget.take() and event.level != 'error':
                continue
            # rclpy ties a severity to its call site: one call per level.
            if event.level == 'info':
                log.info(event.message)
            elif event.level == 'warning':
                log.warning(event.message)
            else:
                log.error(event.message)

    def say_left_out(self) -> None:
        left_out = self.log_budget.roll(time.monotonic())
        if left_out:
            self.get_logger().warning(
                f'{left_out} more events in the last {LOG_WINDOW_S:g} s not logged (too many '
                'to log; every one is on ~/events)')

    def publish_state(self) -> None:
        if self.core.state != self.last_state:
            self.last_state = self.core.state
            self.state_pub.publish(String(data=str(self.last_state)))

    def publish_queue(self) -> None:
        if self.core.queue_version == self.last_queue_version:
            return
        self.last_queue_version = self.core.queue_version
        path = Path(header=Header(stamp=self.get_clock().now().to_msg(), frame_id=FRAME))
        path.poses = [self.pose(goal.x_m, goal.y_m, 0.0) for goal in self.core.pending_goals()]
        self.queue_pub.publish(path)

    @guarded
    def publish_diagnostics(self) -> None:
        self.say_left_out()
        now = self.now_s()
        periods, self.tick_periods_s = self.tick_periods_s, []
        compute, self.compute_s = self.compute_s, []
        state = self.core.state
        level, message = DiagnosticStatus.OK, str(state)
        if state in (ArmState.ERROR, ArmState.NO_SENSORS):
            level, message = DiagnosticStatus.WARN, f'{state}: {self.core.last_error}'
        elif state == ArmState.ESTOPPED:      # why, even after goals rejected since
            level, message = DiagnosticStatus.ERROR, self.estop_message or self.core.last_error
        worst = max(periods, default=math.nan)
        if worst > 3 * self.period_s:
            level = max(level, DiagnosticStatus.WARN)
            message += f'; control loop stalled for {worst:.3f} s'
        if self.core.planner_available is False:
            level = max(level, DiagnosticStatus.WARN)
            message += '; the planner (plan_path) is not available: goals will fail'
        malformed, self.bad_inputs_said = self.bad_inputs - self.bad_inputs_said, self.bad_inputs
        if malformed:
            level = max(level, DiagnosticStatus.WARN)
            message += f'; {malformed} malformed messages ignored (the log says which)'
        encoders_age = now - self.encoders[1] if self.encoders is not None else math.inf
        values = dict(self.core.diagnostics(now))
        values.update({
            'loop period mean (s)': f'{statistics.fmean(periods):.4f}' if periods else 'nan',
            'loop period worst (s)': f'{worst:.4f}',
            'compute per cycle median (ms)':
                f'{1000 * statistics.median(compute):.3f}' if compute else 'nan',
            'compute per cycle worst (ms)': f'{1000 * max(compute, default=math.nan):.3f}',
            'joint_states stale': now - self.joint_states_s > self.config.joint_state_timeout_s,
            'motor_encoders age (s)': f'{encoders_age:.3f}',
            'bad inputs ignored': self.bad_inputs,
            PLANNER_AVAILABLE: bool(self.core.planner_available),
        })
        diagnostic = DiagnosticArray()
        diagnostic.header.stamp = self.get_clock().now().to_msg()
        diagnostic.status = [status(self, level, message, values)]
        self.diagnostics_pub.publish(diagnostic)

    def on_shutdown(self) -> None:
        """0 V on the way out: the arm must not keep the last command."""
        self.workers.shutdown(wait=False, cancel_futures=True)
        try:
            for _ in range(3):
                self.publish_voltage(np.zeros(2))
            # Reliable: make sure the sim has it before the process goes away.
            self.voltage_pub.wait_for_all_acked(Duration(seconds=SHUTDOWN_ACK_S))
        except Exception as error:              # the context may already be gone
            self.get_logger().warning(f'could not send 0 V on shutdown: {error}')


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def controller_node() -> ControllerNode:
    """The node, with SIGINT and SIGTERM handed back to Python.

    rclpy's own handlers shut the context down before ``on_shutdown`` runs, so the last
    0 V command could not go out; as a KeyboardInterrupt, ``run`` sends it first.
    """
    uninstall_signal_handlers()
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _interrupt)
    return ControllerNode()


def main(args=None):
    sys.exit(run(controller_node, args))


if __name__ == '__main__':
    main()
