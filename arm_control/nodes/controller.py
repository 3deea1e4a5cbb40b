"""The ``controller`` node: goals in, motor voltages out -- a shell around ArmController.

Subscribes ``joint_states``, ``motor_encoders`` (JointState), ``battery_state`` (bus volts
and current, for the estimate and the feedforward), ``goal_point`` (PointStamped: queued),
``goal_preset`` (String: replaces the queue and the motion, as a driver's button) and
``driver_velocity`` (TwistStamped: tool velocity in arm_base). Publishes ``voltage_command``
every period, ``arm_state`` (latched), ``~/setpoint``, ``~/estimate``, ``~/goal_queue``
(latched), ``~/events`` ("kind (cause): sentence"), ``/diagnostics`` and
``voltage_command_claim`` (its claim to the arm: of two controllers the first keeps it, the
other yields and sends nothing: ``claim_link``). Client of
``plan_path``; serves ``~/estop``, ``~/reset``, ``~/cancel`` (Trigger), ``~/enable``
(SetBool). Gains, reserves, tolerances, dwell and presets change at run time (``TUNABLE``).

Three threads of work: the control loop (``ControlLoop``) steps the core and commands the
motors; the executor takes messages and services (at ``EXECUTOR_PRIORITY``, below the loop,
as is the thread that hands the core its timed plans); a worker process times plans, and
its keeper keeps fine trajectories (``PlanLink``). The
core is shared under a lock held only for quick calls and the publishing of a command
(a write that DDS blocks holds Python's own lock too: the process waits either way). On
exit: its last profile again (a stop to rest, held), or 0 V sending volts or unpowered.
"""

import math
import signal
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped, TwistStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import uninstall_signal_handlers
from rclpy.time import Time
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import SetBool, Trigger

from arm_control import realtime
from arm_control.control.controller import ArmController
from arm_control.control.events import EventKind as Kind
from arm_control.control.health import diagnostics, health, loop_values, trust_values
from arm_control.control.input_gate import InputGate
from arm_control.control.latency import CommandDelay
from arm_control.control.live_settings import changed_names, controller_settings, TUNABLE
from arm_control.control.robot_command import Commander
from arm_control.control.sensing import SensorReading
from arm_control.control.state_machine import ArmState
from arm_control.control.trust import GraphCounts, TrustWatch
from arm_control.nodes import messages
from arm_control.nodes.claim_link import ClaimLink
from arm_control.nodes.common import (COMMANDS, declare_parameters, Drained, guarded,
                                      interrupt, LATCHED, log_at, loop_statistics, output,
                                      PLANNER_AVAILABLE, run, STATE_STREAM, status, take_all)
from arm_control.nodes.control_loop import ControlLoop
from arm_control.nodes.plan_link import PlanLink
from arm_control.nodes.trajectory_server import TrajectoryServer
from arm_control.parameters import ParameterError

PLANNER_POLL_S = 0.05             # how often to look whether the planner is there ...
PLANNER_SETTLED_POLL_S = 0.5      # ... once it is, with nothing asked of it and no goal
GRAPH_WATCH_S = 0.5               # how often to count who else publishes its topics
# The executor's thread (messages, services) at SCHED_FIFO this low when the loop is at real
# time: above every normal process, below the loop. At normal priority a busy machine can
# preempt it while it holds Python's lock, and the loop would then wait for the lock.
EXECUTOR_PRIORITY = 1
SHUTDOWN_ACK_S = 0.5              # at most this long on exit for the 0 V command to arrive
# A reading is timed at its stamp when that is at most this long before its arrival, and
# not after it (the stamp on this host's clock); else at its arrival.
STAMP_TRUSTED_S = 0.05
READINGS_KEPT = 4                 # joint_states kept for the next tick, the latest last
# Goals, presets, driver commands kept until taken: answered or counted (``InputGate``).
GOALS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
EVENTS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
MAX_ANGLE_RAD = 4.0 * math.pi     # no sensor of this arm reads beyond two turns
LEVELS = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN,
          'error': DiagnosticStatus.ERROR}


class ControllerNode(Node):

    def __init__(self):
        super().__init__('controller')
        self.core = None
        params = declare_parameters(self, 'controller', TUNABLE, self.on_parameters)
        self.settings = controller_settings(params)         # as every change is checked
        self.arm, self.config = self.settings.arm, self.settings.config
        self.lock = threading.Lock()                # the core, between the threads
        self.plans = PlanLink(self, self.arm, self.config, self.on_timed_plan)
        self.core = ArmController(self.arm, self.config)
        self.trajectories = TrajectoryServer(self, params)     # FollowJointTrajectory, topic
        self.trust, self.gate = TrustWatch(self.core), InputGate()
        self.claims = ClaimLink(self)                       # who keeps the arm
        # The latest reading for the loop, and the encoders and bus: (value, received at).
        self.readings, self.encoders, self.bus = [], None, None
        self.bad_inputs = self.bad_inputs_said = 0
        self.last_state = self.last_queue_version = None
        self.loop_periods_s, self.loop_compute_s, self.last_tick_s = [], [], None
        self.reading_ages_s = []            # arrival minus stamp of each joint_states
        self.command_delay = CommandDelay(self.config.period_s)
        self.commander = Commander(self.config)     # what to send, for the robot's instants
        self.last_command = None                    # the last sent: a pair or a Profile
        sys.setswitchinterval(0.001)   # another thread waits 1 ms for Python, not 5

        self.voltage_pub = output(self, Float64MultiArray, 'voltage_command', COMMANDS)
        self.setpoint_pub = output(self, JointState, '~/setpoint', STATE_STREAM)
        self.estimate_pub = output(self, JointState, '~/estimate', STATE_STREAM)
        self.state_pub = output(self, String, 'arm_state', LATCHED)
        self.queue_pub = output(self, Path, '~/goal_queue', LATCHED)
        self.events_pub = output(self, String, '~/events', EVENTS)
        self.diagnostics_pub = output(self, DiagnosticArray, '/diagnostics', 10)
        for topic, kind, handler, qos in (
                ('joint_states', JointState, self.on_joint_states, STATE_STREAM),
                ('goal_point', PointStamped, self.on_goal_point, GOALS),
                ('goal_preset', String, self.on_goal_preset, GOALS),
                ('driver_velocity', TwistStamped, self.on_driver, GOALS)):
            self.create_subscription(kind, topic, handler, qos)
        # Taken as each joint_states arrives (a robot sends them first): ``Drained``.
        self.beside = [(self.create_subscription(kind, topic, handler, STATE_STREAM,
                                                 callback_group=Drained()), handler)
                       for topic, kind, handler in (
                           ('motor_encoders', JointState, self.on_encoders),
                           ('battery_state', BatteryState, self.on_battery))]
        for name, call in (('~/estop', self.core.estop), ('~/reset', self.core.reset),
                           ('~/cancel', self.core.cancel)):
            self.create_service(Trigger, name, lambda request, response, call=call:
                                self.on_service(response, call))
        self.create_service(SetBool, '~/enable', lambda request, response: self.on_service(
            response, self.core.enable, bool(request.data)))
        self.outputs = self.create_guard_condition(self.publish_outputs)
        self.planner_ready = None
        self.planner_timer = self.create_timer(PLANNER_POLL_S, self.watch_planner)
        self.create_timer(1.0, self.publish_diagnostics)
        self.create_timer(GRAPH_WATCH_S, self.watch_graph)
        priority = self.config.realtime_priority
        self.loop = ControlLoop(self.get_clock(), self.config.period_s, self.tick, priority,
                                self.get_logger().warning, self.has_reading, self.plans.busy,
                                self.commander.tick_due)
        # Not looked for yet: a goal that comes before the first look waits in the queue too.
        self.planner_ready = False
        self.command(self.core.on_planner_available, False)
        self.loop.start()
        if priority:         # this thread spins the executor (where refused, the loop said so)
            realtime.raise_this_thread(EXECUTOR_PRIORITY)
            realtime.raise_dds_threads(EXECUTOR_PRIORITY)   # which receive what it takes
            realtime.raise_thread(self.plans.worker.results_thread_id, EXECUTOR_PRIORITY)
        self.get_logger().info(f'controlling the arm at {self.config.loop_rate_hz:g} Hz'
                               f'{f" at real-time priority {priority}" if priority else ""}; '
                               'waiting for joint_states')

    def now_s(self) -> float:
        return self.loop.now_s()

    def lag_s(self) -> float:
        """How long after now a command sent now acts (``CommandDelay``); in simulated time
        none: the sim applies a step's command from the step's start."""
        return 0.0 if self.loop.simulated() else self.command_delay.delay_s

    def acts_s(self, sent_s: float) -> float:
        """When a command sent at ``sent_s`` acts (``Commander.acts_s``)."""
        return self.commander.acts_s(sent_s + self.lag_s())

    def core_now_s(self) -> float:
        """The core's clock: the instant the command it computes now will act."""
        return self.acts_s(self.now_s())

    def command(self, call, *args):
        """Call the core under the lock, then say what it said. A call that cuts the power
        (e-stop, disable) sends 0 V now, not at the next tick: under the same lock as the
        tick's own command, so none computed before the call goes out after it. (Not in
        simulated time, where the sim takes one command per step: the next tick's.)"""
        with self.lock:
            began = time.perf_counter()
            powered = not self.core.unpowered
            result = call(self.core_now_s(), *args)
            self.gate.spent(time.perf_counter() - began)     # inputs' share of the core
            if powered and self.core.unpowered and not self.loop.simulated() \
                    and not self.claims.yielding:
                self.last_command = (0.0, 0.0)
                self.voltage_pub.publish(Float64MultiArray(data=[0.0, 0.0]))
        self.publish_outputs()
        return result

    # ------------------------------------------------------------------ messages in

    @guarded
    def on_joint_states(self, msg: JointState) -> None:
        for subscription, handler in self.beside:
            take_all(subscription, handler)
        if not self.loop.started():
            return                                  # the sim's clock is not there yet
        self.core.sensing.refuse_leaps |= self.count_publishers('joint_states') > 1
        pair = messages.joint_readings(msg, MAX_ANGLE_RAD, self.core.sensing.max_leap_speed_rad_s)
        if isinstance(pair, str):
            return self.warn_bad(f'ignored joint_states: {pair}')
        position, velocity = pair
        now, stamp = self.now_s(), self.loop.guard.to_control_s(messages.stamp_s(msg.header))
        age_s = now - stamp
        if math.isfinite(age_s):
            self.reading_ages_s.append(age_s)

        def fresh(latest, missing):
            return latest[0] if latest is not None and \
                now - latest[1] <= self.config.joint_state_timeout_s else missing
        encoder = fresh(self.encoders, (math.nan, math.nan))
        bus, supply_current = fresh(self.bus, (math.nan, math.nan))
        # Taken at its stamp, when the sensors were read: timed at its arrival the estimate
        # would lag the arm by the motion of the transit, and the feedback push it ahead. In
        # simulated time the stamp is the clock's, which may not have reached it yet, or have
        # jumped since.
        trusted = 0.0 <= age_s <= STAMP_TRUSTED_S or (
            self.loop.simulated() and abs(age_s) <= self.config.joint_state_timeout_s)
        taken = stamp if trusted else now
        # All since the last tick: beside a second publisher the latest was often its.
        self.readings = self.readings[-(READINGS_KEPT - 1):] + [(SensorReading(
            tuple(position), tuple(velocity), tuple(encoder), stamp, bus, supply_current), taken)]

    @guarded
    def on_encoders(self, msg: JointState) -> None:
        position = messages.joint_pair(msg, 'position')
        if position is None or not messages.within(position, MAX_ANGLE_RAD):
            return self.warn_bad('ignored motor_encoders: expected finite positions of '
                                 '[shoulder, elbow] within two turns')
        self.encoders = (position, self.now_s())

    @guarded
    def on_battery(self, msg: BatteryState) -> None:
        if not 0.0 < msg.voltage <= 2.0 * self.arm.battery.nominal_voltage:   # NaN too
            return self.warn_bad(f'ignored battery_state: voltage {msg.voltage} V')
        # BatteryState's current is negative while discharging; NaN when not reported.
        self.bus = ((float(msg.voltage), -float(msg.current)), self.now_s())

    @guarded
    def on_goal_point(self, msg: PointStamped) -> None:
        if not self.refused('goal_point', msg.header.frame_id, 'frame_id', 'goal'):
            p = msg.point
            self.command(self.core.submit_goal, p.x, p.y, p.z, msg.header.frame_id)

    @guarded
    def on_goal_preset(self, msg: String) -> None:
        if not self.refused('goal_preset', msg.data, 'preset name', 'preset'):
            self.command(self.core.submit_preset, msg.data.strip())

    @guarded
    def on_driver(self, msg: TwistStamped) -> None:
        if not self.refused('driver_velocity', msg.header.frame_id, 'frame_id',
                            'driver command'):
            linear = msg.twist.linear
            self.command(self.core.driver_command, linear.x, linear.y, msg.header.frame_id)

    def refused(self, topic: str, text: str, what: str, whose: str) -> bool:
        """An input beyond its topic's rate is dropped and counted (``InputGate``); text too
        long to be a name is refused before anything formats it."""
        if not self.gate.admit(topic, time.monotonic()):
            return True
        if self.claims.yielding:
            self.command(self.core.goals.reject, f'{whose} rejected: another controller '
                         'has the arm (this one yielded)', 'yielded')
            return True
        problem = messages.name_problem(text, what)
        if problem:
            self.command(self.core.goals.reject, f'{whose} rejected: {problem}', 'oversized')
        return problem is not None

    @guarded
    def on_service(self, response, call, *args):
        if self.claims.yielding:
            response.success, response.message = False, 'another controller has the arm: ' \
                'this one yielded and commands nothing'
            return response
        response.success, response.message = self.command(call, *args)
        return response

    def on_parameters(self, params):
        """A run-time change: checked whole as at start (``controller_settings``), taken
        from the next period, or refused with the reason (the old values kept)."""
        if self.core is None:
            return None                             # the overrides at start: read below
        if self.claims.yielding:                    # the change is meant for the one in charge
            return ('another controller has the arm: this one yielded and takes no settings '
                    '(two nodes share the name: set them on the one commanding)')
        try:
            settings = controller_settings(params, self.settings)
        except ParameterError as error:
            return str(error)
        changed = changed_names(self.settings, settings)
        self.plans.retune(settings.arm, settings.config)
        with self.lock:
            self.core.retune(settings.arm, settings.config, settings)
            self.core.events.say(self.core_now_s(), Kind.PARAMETERS, 'info',
                                 f'changed at run time: {", ".join(changed) or "nothing"}')
        self.settings, self.arm, self.config = settings, settings.arm, settings.config
        self.outputs.trigger()
        return None

    def has_reading(self, now_s: float) -> bool:
        """The joint states of ``now_s`` (simulated time: the sim's step) are in."""
        return any(taken >= now_s - 1e-6 for _, taken in self.readings)

    def watch_planner(self) -> None:
        """Tell the core when the planner (and the timing worker) comes or goes; with no
        goal, have the next path between presets kept; the keeper works only while the arm
        is not moved along a trajectory."""
        ready = self.plans.ready()
        if ready != self.planner_ready:
            self.planner_ready = ready
            self.command(self.core.on_planner_available, ready)
        with self.lock:
            idle = not self.core.pending_goals()
            moving = self.core.state in (ArmState.PLANNING, ArmState.TRACKING, ArmState.DRIVER)
        self.plans.let_keeper_work(idle and not moving)
        self.plans.keep_presets(idle)
        self.poll_planner(ready and idle and not moving and self.plans.settled())

    def poll_planner(self, settled: bool) -> None:
        """Look at the planner every PLANNER_SETTLED_POLL_S when settled, else PLANNER_POLL_S."""
        period_ns = round(1e9 * (PLANNER_SETTLED_POLL_S if settled else PLANNER_POLL_S))
        if self.planner_timer.timer_period_ns != period_ns:
            self.planner_timer.timer_period_ns = period_ns

    @guarded
    def watch_graph(self) -> None:
        """Who else publishes what it reads or writes, or takes its name (``TrustWatch``)."""
        me = (self.get_name(), self.get_namespace())
        counts = GraphCounts(*(self.count_publishers(topic) if topic else 0 for topic in (
            'joint_states', '/clock' if self.loop.simulated() else '', 'voltage_command')),
            self.get_node_names_and_namespaces().count(me))
        with self.lock:
            self.trust.graph(self.core_now_s(), counts)
        self.outputs.trigger()

    def warn_bad(self, message: str) -> None:
        self.bad_inputs += 1
        self.get_logger().warning(message, throttle_duration_sec=1.0)

    # ------------------------------------------------------------------ the loop's thread

    def tick(self) -> None:
        began, now = time.perf_counter(), self.now_s()
        readings, self.readings = self.readings, []
        for reading, _ in readings:
            self.commander.clock.observe(reading.sampled_s)
        if readings:
            self.claims.ready()
        yields = self.claims.yields()
        acts_s = self.acts_s(now)
        with self.lock:
            if yields != self.claims.yielding:
                self.claims.change(self, acts_s, yields)
            try:
                voltage = self.core.step(acts_s, *(readings[-1] if readings else (None, None)),
                                         earlier=readings[:-1])
            except Exception as error:              # a bug must stop the arm, not the node
                self.core.estop(acts_s, f'internal error in the control step: {error!r}',
                                cut_power=True)
                voltage = np.zeros(2)
            self.trust.step(acts_s, self.loop.guard.take())
            estimate, setpoint = self.core.estimate, self.core.setpoint
            said = (self.core.events.waiting or self.core.goals.plans.waiting
                    or self.core.state != self.last_state
                    or self.core.goals.queue.version != self.last_queue_version)
            commanding = estimate is not None and not yields    # nothing before a reading
            if commanding:
                self.last_command = self.commander.command(self.core, voltage, acts_s)
                self.voltage_pub.publish(messages.voltage_command(self.last_command))
        if commanding:
            self.command_delay.sent(time.perf_counter() - began)
            stamp = Time(nanoseconds=round(acts_s * 1e9)).to_msg()     # what they are for
            self.setpoint_pub.publish(messages.joint_state(stamp, setpoint[0], setpoint[1]))
            self.estimate_pub.publish(messages.joint_state(stamp, estimate[:2], estimate[2:]))
        if said:                                    # the executor publishes what changed
            self.outputs.trigger()
        if self.last_tick_s is not None:
            self.loop_periods_s.append(now - self.last_tick_s)
        self.last_tick_s = now
        self.loop_compute_s.append(time.perf_counter() - began)

    def on_timed_plan(self, timed) -> None:
        """From the worker's result thread: the plan to the core, from when the next command
        acts (in simulated time the next step, if this one's went out), and the loop runs."""
        with self.lock:
            self.core.on_timed_plan(self.acts_s(self.loop.next_command_s()), timed)
        self.loop.poke()

    # ------------------------------------------------------------------ outputs

    def publish_outputs(self) -> None:
        """In the executor: plan requests out first (the arm waits for them, and a log line
        and messages sent before them delay every goal), then events, state and queue as
        they changed."""
        with self.lock:
            events = self.core.events.take()
            state, pending = self.core.state, self.core.pending_goals()
            version = self.core.goals.queue.version
            requests = self.core.take_plan_requests()
        if requests:
            self.plans.let_keeper_work(False)      # a goal to plan: not while it moves
            self.plans.send(requests)
            self.poll_planner(False)
        for event in events:
            self.events_pub.publish(String(data=str(event)))
            log_at(self.get_logger(), event.level, str(event))
        if state != self.last_state and not self.claims.yielding:
            self.last_state = state
            self.state_pub.publish(String(data=str(state)))
        if version != self.last_queue_version:
            self.last_queue_version = version
            path = Path(header=messages.header(self.get_clock().now().to_msg()))
            path.poses = [messages.pose_stamped(g.x_m, g.y_m, 0.0, path.header)
                          for g in pending]
            self.queue_pub.publish(path)

    @guarded
    def publish_diagnostics(self) -> None:
        periods, self.loop_periods_s = self.loop_periods_s, []
        compute, self.loop_compute_s = self.loop_compute_s, []
        ages, self.reading_ages_s = self.reading_ages_s, []
        stats = loop_statistics(periods, compute)
        malformed, self.bad_inputs_said = self.bad_inputs - self.bad_inputs_said, self.bad_inputs
        problems = [text for bad, text in (
            (not self.plans.worker.alive, 'the plan worker process is gone: goals will fail'),
            (malformed, f'{malformed} malformed messages ignored (the log says which)')) if bad]
        with self.lock:
            self.gate.flush(self.core, self.core_now_s(), time.monotonic())
            values, planner = diagnostics(self.core, self.now_s()), self.core.planner_available
            level, message = health(self.core, stats['worst'], problems,
                                    self.trust.problems.values())
            values.update(trust_values(self.trust))
        values.update(loop_values(stats, ages, self.loop))
        values.update({'bad inputs ignored': self.bad_inputs, PLANNER_AVAILABLE: bool(planner),
                       'trajectories kept': self.plans.worker.kept,
                       **{f'{kind} dropped': n for kind, n in self.gate.dropped.items()},
                       'inputs dropped beyond the work share': self.gate.busy})
        diagnostic = DiagnosticArray()
        diagnostic.header.stamp = self.get_clock().now().to_msg()
        diagnostic.status = [status(self, LEVELS[level], message, values)]
        self.diagnostics_pub.publish(diagnostic)

    def on_shutdown(self) -> None:
        """The last word: sending profiles and powered, the last profile again (it ends at
        rest with its holding volts, so the robot holds the arm until a newer command);
        else 0 V. Not 0 V on exit as a rule: a hand-over must never drop the arm."""
        self.loop.stop()
        with self.lock:
            last = self.last_command
            if self.claims.yielding:
                last = None                         # another controller has the arm
            elif not self.commander.profiles:
                last = (0.0, 0.0)
            elif last is not None and self.core.unpowered and not self.core.held_by_robot \
                    and self.core.state != ArmState.NO_SENSORS:     # lost: its profile holds
                last = (0.0, 0.0)
        if last is None:           # a profile controller that never commanded: leave the arm
            self.plans.close()
            return
        try:
            for _ in range(3):
                self.voltage_pub.publish(messages.voltage_command(last))
            # Reliable: make sure the sim has it before the process goes away.
            self.voltage_pub.wait_for_all_acked(Duration(seconds=SHUTDOWN_ACK_S))
        except Exception as error:              # the context may already be gone
            self.get_logger().warning(f'could not send the last command on shutdown: {error}')
        self.plans.close()


def controller_node() -> ControllerNode:
    """The node, with SIGINT and SIGTERM handed back to Python: rclpy's own handlers shut
    the context down before ``on_shutdown`` runs, so the last command could not go out."""
    uninstall_signal_handlers()
    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    return ControllerNode()


def main(args=None):
    sys.exit(run(controller_node, args))


if __name__ == '__main__':
    main()
