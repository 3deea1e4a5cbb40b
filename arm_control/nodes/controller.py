"""The ``controller`` node: goals in, motor voltages out -- a shell around ArmController.

Readings in ``sensor_inputs``; goals, presets, driver commands and services in
``command_inputs``. Publishes ``voltage_command`` every period, ``arm_state`` (latched),
``~/setpoint``, ``~/estimate``, ``~/goal_queue`` (latched), ``~/events`` ("kind (cause):
sentence"), ``/diagnostics`` and ``voltage_command_claim`` (``claim_link``). Client of
``plan_path``. Gains, reserves, tolerances, dwell and presets change at run time (``TUNABLE``).

Three threads of work: the control loop (``ControlLoop``) steps the core and commands the
motors; the executor (``QuietExecutor``) takes messages and services (at
``EXECUTOR_PRIORITY``, below the loop, as is the thread that hands the core its timed plans);
a worker process times plans, and its keeper keeps fine trajectories (``PlanLink``). The core
is shared under a lock held only for quick calls and the publishing of a command (a write
that DDS blocks holds Python's own lock too: the process waits either way). On exit: its
last profile again (a stop to rest, held), or 0 V sending volts or unpowered.
"""

import signal
import sys
import threading
import time

from nav_msgs.msg import Path
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import uninstall_signal_handlers
from rclpy.time import Time
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from arm_control import realtime
from arm_control.control.controller import ArmController
from arm_control.control.events import EventKind as Kind
from arm_control.control.input_gate import InputGate
from arm_control.control.latency import CommandDelay
from arm_control.control.live_settings import changed_names, controller_settings, TUNABLE
from arm_control.control.robot_command import Commander
from arm_control.control.state_machine import ArmState
from arm_control.control.trust import TrustWatch
from arm_control.nodes import messages
from arm_control.nodes.claim_link import ClaimLink
from arm_control.nodes.command_inputs import CommandInputs
from arm_control.nodes.common import (COMMANDS, declare_parameters, interrupt, LATCHED,
                                      log_at, output, run, STATE_STREAM)
from arm_control.nodes.control_loop import ControlLoop
from arm_control.nodes.controller_watch import ControllerWatch
from arm_control.nodes.plan_link import PlanLink
from arm_control.nodes.quiet_executor import QuietExecutor
from arm_control.nodes.sensor_inputs import SensorInputs
from arm_control.nodes.trajectory_server import TrajectoryServer
from arm_control.parameters import ParameterError

PLANNER_POLL_S = 0.05             # how often to look whether the planner is there ...
PLANNER_SETTLED_POLL_S = 0.5      # ... once it is, with nothing asked of it and no goal
# The executor's thread (messages, services) at SCHED_FIFO this low when the loop is at real
# time: above every normal process, below the loop. At normal priority a busy machine can
# preempt it while it holds Python's lock, and the loop would then wait for the lock.
EXECUTOR_PRIORITY = 1
SHUTDOWN_ACK_S = 0.5              # at most this long on exit for the 0 V command to arrive
EVENTS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


class ControllerNode(Node):

    def __init__(self):
        super().__init__('controller')
        self.core = None
        params = declare_parameters(self, 'controller', TUNABLE, self.on_parameters)
        self.settings = controller_settings(params)         # as every change is checked
        self.arm, self.config = self.settings.arm, self.settings.config
        self.lock = threading.Lock()                # the core, between the threads
        self.plans = PlanLink(self, self.arm, self.config, self.on_timed_plan,
                              lambda: self.poll_planner(False))
        self.core = ArmController(self.arm, self.config, self.plans)
        self.trajectories = TrajectoryServer(self, params)     # FollowJointTrajectory, topic
        self.trust, self.gate = TrustWatch(self.core), InputGate()
        self.claims = ClaimLink(self)                       # who keeps the arm
        self.bad_inputs = 0
        self.last_state = self.last_queue_version = None
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
        self.sensors = SensorInputs(self)  # joint states, encoders, bus: taken at a tick
        self.inputs = CommandInputs(self)   # goals, presets, driver commands, services
        self.outputs = self.create_guard_condition(self.publish_outputs)
        self.planner_ready = None
        self.planner_timer = self.create_timer(PLANNER_POLL_S, self.watch_planner)
        self.watch = ControllerWatch(self)      # /diagnostics, who else is on the graph
        priority = self.config.realtime_priority
        self.holding_still = False                  # at the last tick
        self.loop = ControlLoop(self.get_clock(), self.config.period_s, self.tick, priority,
                                self.get_logger().warning, self.sensors.has_reading,
                                self.plans.busy, self.commander.tick_due,
                                lambda: self.config.holding_periods if self.holding_still else 1)
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
            if self.core.requests_waiting:
                self.loop.poke()            # a goal is planned from the step it asks in
            if powered and self.core.unpowered and not self.loop.simulated() \
                    and not self.claims.yielding:
                self.last_command = (0.0, 0.0)
                self.voltage_pub.publish(Float64MultiArray(data=[0.0, 0.0]))
        self.publish_outputs()
        return result

    # ------------------------------------------------------------------ messages in

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
            self.core.say(self.core_now_s(), Kind.PARAMETERS, 'info',
                          f'changed at run time: {", ".join(changed) or "nothing"}')
        self.settings, self.arm, self.config = settings, settings.arm, settings.config
        self.outputs.trigger()
        return None

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

    def warn_bad(self, message: str) -> None:
        self.bad_inputs += 1
        self.get_logger().warning(message, throttle_duration_sec=1.0)

    # ------------------------------------------------------------------ the loop's thread

    def tick(self) -> None:
        began = time.perf_counter()
        readings = self.sensors.take_new()
        now = self.now_s()
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
                step = self.core.step(acts_s, *(readings[-1] if readings else (None, None)),
                                      earlier=readings[:-1])
            except Exception as error:              # a bug must stop the arm, not the node
                self.core.estop(acts_s, f'internal error in the control step: {error!r}',
                                cut_power=True)
                step = None
            voltage = np.zeros(2) if step is None else step.volts
            self.holding_still = step is not None and self.core.holding_still
            self.trust.step(acts_s, self.loop.guard.take())
            last = self.core.last_step              # this period's, or before an error
            estimate = self.core.estimate
            setpoint = last.setpoint if last else (np.zeros(2), np.zeros(2), np.zeros(2))
            said = self.core.news_waiting or step is None or (
                step.state, step.queue_version) != (self.last_state, self.last_queue_version)
            commanding = estimate is not None and not yields \
                and not self.claims.listening()     # nothing before a reading or a claim
            if commanding:
                self.last_command = self.commander.command(self.core, voltage, acts_s)
                self.voltage_pub.publish(messages.voltage_command(self.last_command))
        if commanding:
            self.command_delay.sent(time.perf_counter() - began)
            self.publish_states(acts_s, setpoint, estimate)
        if said:                                    # the executor publishes what changed
            self.outputs.trigger()
        self.watch.ticked(now, time.perf_counter() - began)

    def publish_states(self, acts_s: float, setpoint, estimate) -> None:
        """~/setpoint and ~/estimate, stamped with the instant they are for; built only for
        a subscriber (each costs the loop a message a period)."""
        stamp = None
        for publisher, position, velocity in (
                (self.setpoint_pub, setpoint[0], setpoint[1]),
                (self.estimate_pub, estimate[:2], estimate[2:])):
            if publisher.get_subscription_count():
                stamp = stamp or Time(nanoseconds=round(acts_s * 1e9)).to_msg()
                publisher.publish(messages.joint_state(stamp, position, velocity))

    def on_timed_plan(self, timed) -> None:
        """From the worker's result thread: the plan to the core, from when the next command
        acts (in simulated time the next step, if this one's went out), and the loop runs."""
        with self.lock:
            self.core.on_timed_plan(self.acts_s(self.loop.next_command_s()), timed)
        self.loop.poke()

    # ------------------------------------------------------------------ outputs

    def publish_outputs(self) -> None:
        """In the executor: events, state and queue as they changed (the plan calls of the
        same step went out before: ``PlanLink``)."""
        with self.lock:
            news = self.core.take_news()
        events, state, pending = news.events, news.state, news.goals
        version = news.queue_version
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
    sys.exit(run(controller_node, args, QuietExecutor))


if __name__ == '__main__':
    main()
