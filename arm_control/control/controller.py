"""The controller's pure core: goals in, one voltage per control period out. No ROS here.

Each period the node (or a test, or a benchmark) calls ``step(now_s, reading)``; the core

1. estimates the state (``sensing.Sensing``: the Kalman filter over the readings);
2. supervises: stale sensors, joint limits, the arm moved under it, then the goals
   (``goal_runner.GoalRunner``: the planner's deadline, arrival, dwell, the next goal);
   ``state_machine.py`` holds every allowed transition;
3. commands V = feedforward + PID, clamped to the battery's volts (``tracking.Tracking``); a
   planned motion the arm is late on waits for it;
4. enforces the safety rules (``safety.py``): control that has failed stops at 0 V (its
   sensors lost, the robot plays the rest of its last profile: ``robot_command``); an
   e-stop by service brakes to rest along the path and holds there (``estop_holds_arm``:
   with no brake, 0 V drops a 45 kg arm); taking control back after 0 V brakes an arm that
   moves, returns it to where it was held, or lifts it clear of forbidden space
   (``recovery.Recovery``).

``step`` returns a ``port.Step`` (the volts, the state, the events, the plan requests it
handed on); ``take_news`` gives the publisher what changed. Callers read those, not the
core's parts.

The core does not plan: starting a goal makes a ``PlanRequest``, handed in the next step to
the core's one ``plans.port.Planning`` (``PlanLink`` in the node, ``InProcessPlanning`` in
tests and benchmarks, else ``HeldRequests``), and the answer comes back as a ``TimedPlan``
through ``on_timed_plan``. No plan within ``planner_timeout_s``: the goal fails with the
reason -- never a blind move.
"""

from dataclasses import replace
import math
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.driver import DriverMode
from arm_control.control.events import EventKind as Kind, EventLog
from arm_control.control.goal_runner import GoalRunner
from arm_control.control.motions import Motion, Setpoints
from arm_control.control.port import News, Step
from arm_control.control.recovery import Recovery
from arm_control.control.safety import SafetyRules, sure_limits
from arm_control.control.sensing import Sensing
from arm_control.control.state_machine import ArmState as S, StateMachine, STOPPED, Trigger as T
from arm_control.control.stops import Stops
from arm_control.control.tracking import Tracking
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.plans.messages import TimedPlan
from arm_control.plans.port import HeldRequests
from arm_control.plans.timer import PlanTimer
from arm_control.text import quote


# The arm holds still once settled at the hold this long (s): the end of its settling, the
# last of the approach, runs at the full rate.
STILL_AFTER_S = 1.0


class ArmController:
    """Estimation, supervision, control and safety; the goals run by a ``GoalRunner``. One
    ``step`` per control period returns the voltage to apply [Va, Vb] in a ``Step``."""

    def __init__(self, arm: ArmConfig, config: ControllerConfig, planning=None):
        self.arm, self.config = arm, config
        self.planning = HeldRequests() if planning is None else planning
        self.handed = ()              # the plan requests handed on in the last step
        self.period_s = config.period_s
        self.plan_timer = PlanTimer(arm, config)
        dynamics, self.forbidden = self.plan_timer.dynamics, self.plan_timer.forbidden
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.max_velocity, self.max_acceleration = sure_limits(dynamics, self.forbidden, arm,
                                                               config)
        self.sensing = Sensing(arm, config.process_noise_rad_s2)
        self.tracking = Tracking(arm, config, dynamics)
        self.safety = SafetyRules(arm, config, self.forbidden, self.max_acceleration,
                                  self.max_velocity)
        self.setpoints = Setpoints(DriverMode(
            self.kinematics, self.forbidden, self.max_velocity, self.max_acceleration,
            self.period_s, config.driver_max_speed_mps, config.driver_command_timeout_s),
            self.max_acceleration)
        self.machine, self.events = StateMachine(), EventLog()
        self.goals = GoalRunner(arm, config, self.machine, self.events, self.setpoints)
        self.recovery = Recovery(config, self.sensing, self.safety, self.setpoints, self.goals,
                                 self.machine, self.events, self.tracking.pid)
        self.last_step_s: Optional[float] = None
        self.still_since_s: Optional[float] = None     # settled at the hold since
        self.last_step: Optional[Step] = None             # what ``step`` returned last
        self.stops = Stops(config, self.machine, self.goals, self.setpoints, self.events,
                           self.recovery, self.tracking.pid)
        self.voltage = np.zeros(2)

    def retune(self, arm: ArmConfig, config: ControllerConfig, settings=None) -> None:
        """Validated settings from the next period (gains, reserves, tolerances, dwell,
        presets; the physics unchanged); ``settings``: their ``ControllerSettings``, built
        outside the node's lock."""
        timer = settings.plan_timer if settings else PlanTimer(arm, config)
        limits = (settings.max_velocity_rad_s, settings.max_acceleration_rad_s2) if settings \
            else sure_limits(timer.dynamics, self.forbidden, arm, config)
        self.arm, self.config = arm, config
        self.goals.arm, self.goals.config = arm, config
        self.safety.config = self.recovery.config = self.stops.config = config
        self.tracking.pid.retune(config)
        self.plan_timer = timer
        self.max_velocity[:], self.max_acceleration[:] = limits     # shared with the others

    @property
    def state(self) -> S:
        return self.machine.state

    @property
    def estimate(self) -> Optional[np.ndarray]:
        """[θa, θb, ωa, ωb], or None before the first reading."""
        return self.sensing.state if self.sensing.started else None

    @property
    def last_error(self) -> str:
        return self.stops.estop_error or self.goals.last_error

    def _rest_q(self) -> np.ndarray:
        return self.sensing.state[:2] if self.sensing.started else np.zeros(2)

    # ------------------------------------------------------------------ commands

    def submit_goal(self, now_s: float, x: float, y: float, z: float = 0.0,
                    frame_id: str = '', label: Optional[str] = None,
                    preempt: bool = False) -> tuple[bool, str]:
        """Queue a goal point, or with ``preempt`` go there now (``GoalRunner.submit``)."""
        return self.goals.submit(now_s, x, y, z, frame_id, label, preempt, self._rest_q())

    def submit_preset(self, now_s: float, name: str, preempt: bool = True) -> tuple[bool, str]:
        """A named goal, as a driver's button: by default it replaces the queue and motion."""
        return self.goals.submit_preset(now_s, name, preempt, self._rest_q())

    def reject(self, now_s: float, message: str, reason: str) -> tuple[bool, str]:
        """A goal refused before it reached the core (``GoalRunner.reject``)."""
        return self.goals.reject(now_s, message, reason)

    def driver_command(self, now_s: float, vx_mps: float, vy_mps: float,
                       frame_id: str = '') -> tuple[bool, str]:
        """End-effector velocity (m/s, arm_base) from a driver; takes over from goals."""
        if not (math.isfinite(vx_mps) and math.isfinite(vy_mps)):
            return self.goals.reject(now_s, f'driver command ({vx_mps}, {vy_mps}) rejected: '
                                            'not finite', 'not finite')
        if frame_id not in ('', 'arm_base'):
            return self.goals.reject(now_s, f'driver command rejected: frame {quote(frame_id)}'
                                            ", expected 'arm_base'", 'wrong frame')
        if self.state != S.DRIVER:
            if not self.machine.can(T.DRIVER_COMMAND):
                return self.goals.reject(now_s, 'driver command ignored in state '
                                                f"'{self.state}'", str(self.state))
            q, qd, _ = self._reference(now_s)
            dropped = self.goals.drop()
            self.machine.fire(T.DRIVER_COMMAND)
            self.setpoints.drive(now_s, q, qd)
            self.say(now_s, Kind.DRIVER, 'info', 'driver velocity mode' +
                     (f': {dropped} goals dropped' if dropped else ''))
        self.setpoints.driver.command(now_s, vx_mps, vy_mps)
        return True, 'driver command accepted'

    def cancel(self, now_s: float) -> tuple[bool, str]:
        """Clear the queue and the current goal; brake to rest along the path and hold."""
        return self.stops.cancel(now_s)

    def estop(self, now_s: float, reason: str = 'e-stop requested',
              cut_power: bool = False) -> tuple[bool, str]:
        """``Stops.estop``: braked to rest and held, or at 0 V (``cut_power``: control
        itself failed) until ``reset``."""
        return self._stopped(self.stops.estop(now_s, reason, cut_power))

    def reset(self, now_s: float) -> tuple[bool, str]:
        """Clear an e-stop or an error; a held arm keeps its hold, one at 0 V is taken back."""
        return self.stops.reset(now_s)

    def enable(self, now_s: float, enabled: bool) -> tuple[bool, str]:
        """Enable (take the arm back) or disable (0 V, goals dropped)."""
        return self._stopped(self.stops.enable(now_s, enabled))

    def _stopped(self, said: tuple[bool, str]) -> tuple[bool, str]:
        if self.unpowered:                      # the estimate's input from now on
            self.voltage = np.zeros(2)
        return said

    @property
    def unpowered(self) -> bool:
        """Stopped at 0 V: e-stopped (and not holding), disabled or in error."""
        return self.stops.unpowered

    @property
    def held_by_robot(self) -> bool:
        """Stopped, its sensors lost while sending profiles: the robot plays the last one."""
        return self.stops.held_by_robot

    # ------------------------------------------------------------------ planning hand-off

    @property
    def requests_waiting(self) -> bool:
        """Plan requests made since the last step, for the next to hand on."""
        return bool(self.goals.plans.requests)

    def on_timed_plan(self, now_s: float, timed: TimedPlan) -> None:
        """Take a timed plan (``PlanTimer.time_plan``); stale answers are ignored."""
        self.goals.on_timed_plan(now_s, timed, self._rest_q())

    def on_planner_available(self, now_s: float, available: bool) -> None:
        """Whether the node's client reaches the planner (``GoalRunner.planner_seen``)."""
        self.goals.planner_seen(now_s, available)

    @property
    def planner_available(self) -> Optional[bool]:
        return self.goals.planner_available

    # ------------------------------------------------------------------ the control period

    def step(self, now_s: float, reading=None, reading_time_s: Optional[float] = None,
             earlier=()) -> Step:
        """One control period: its ``Step``, with [Va, Vb] to apply until the next one.

        ``reading``: the sensors' latest sample since the last step (a ``SensorReading``, or
        a plant's Reading), else None; ``reading_time_s``: when it was taken (default now);
        ``earlier``: (reading, time) of those before it since the last step, folded in first.
        """
        said = self.events.said
        self.voltage = self._volts(now_s, reading, reading_time_s, earlier)
        settled = self._settled_at_the_hold()
        self.still_since_s = (now_s if self.still_since_s is None else self.still_since_s) \
            if settled else None
        tracking = self.tracking
        self.last_step = Step(self.voltage.copy(), self.state, self.unpowered, self.estimate,
                              tracking.setpoint, tracking.tracking_error_rad,
                              tracking.feedforward_v, tracking.feedback_v,
                              self.events.since(said), self.handed,
                              self.goals.queue.version, self.goals.goal_q)
        return self.last_step

    def _volts(self, now_s: float, reading, reading_time_s, earlier) -> np.ndarray:
        dt_s = self.period_s if self.last_step_s is None else max(now_s - self.last_step_s, 0.0)
        self.last_step_s = now_s
        self.handed = ()
        for earlier_reading, earlier_s in earlier:
            self.sensing.update(now_s, earlier_reading, earlier_s, self.voltage)
        self.sensing.update(now_s, reading, reading_time_s, self.voltage)
        self._supervise(now_s)
        if self.goals.plans.requests:
            self.handed = tuple(self.goals.take_requests())
            self.planning.send(self.handed)
        self.events.flush(now_s)
        if self.unpowered:
            self.tracking.stop()
            return np.zeros(2)
        self._wait_for_a_late_arm(now_s)
        voltage = self._control(now_s, dt_s)
        failure = self.safety.tracking_failed(now_s, self.tracking.tracking_error_rad)
        if failure is not None:
            self.estop(now_s, failure, cut_power=True)
            return np.zeros(2)
        if self.recovery.leave_motion(now_s, self.tracking.tracking_error_rad):
            return self._control(now_s, dt_s)
        return voltage

    @property
    def news_waiting(self) -> bool:
        """Events not yet taken (``take_news``)."""
        return self.events.waiting

    def take_news(self) -> News:
        """Events since the last take (each once), the state and the goals: for the node
        to publish."""
        return News(tuple(self.events.take()), self.state, tuple(self.pending_goals()),
                    self.goals.queue.version)

    def _wait_for_a_late_arm(self, now_s: float) -> None:
        """Shift the planned motion in hand later when the arm is behind on it
        (``Tracking.wait_for_a_late_arm``). Not while a plan is awaited (one from the moving
        arm starts where the unshifted motion would be) or another motion follows."""
        timeline = self.setpoints.timeline
        motion = timeline.at(now_s)
        if (self.state != S.TRACKING or type(motion) is not Motion
                or motion is not timeline.last or motion.finished(now_s)
                or self.goals.plans.pending is not None):
            return
        waited_s = self.tracking.wait_for_a_late_arm(now_s, motion, self.sensing.state[:2])
        if waited_s is not None:
            self.goals.latency = replace(self.goals.latency,        # said on arrival
                                         waiting_for_the_arm_s=waited_s)

    def _supervise(self, now_s: float) -> None:
        """Sensors, joint limits, a jump of the sensors, then the goals."""
        # The command sent now holds for a period: stop now if by its end the last reading
        # would be older than the timeout, so commanding ends within joint_state_timeout_s.
        age_s = self.sensing.age_s(now_s)
        fresh = age_s + self.period_s <= self.config.joint_state_timeout_s
        if not fresh and self.machine.can(T.SENSORS_LOST):
            self.recovery.sensors_lost(now_s, age_s)
        if not fresh and self.stops.estop_holding:
            self.stops.lost_while_holding(now_s, age_s)
        if fresh and self.state == S.NO_SENSORS:
            self.recovery.sensors_back(now_s)
        if self.state in STOPPED:
            self.sensing.jumped = False
            self.setpoints.prune(now_s)
            return
        limit = self.safety.past_a_limit(self.sensing.last_potentiometer)
        if limit is not None:
            self.estop(now_s, limit, cut_power=True)
            return
        if self.sensing.jumped:
            self.sensing.jumped = False
            if np.max(np.abs(self.sensing.state[:2] - self._reference(now_s)[0])) > \
                    self.config.tracking_error_limit_rad:
                self.recovery.moved(now_s)      # a small jump the PID takes back; a large one, not
        self.setpoints.prune(now_s)
        if self.state == S.DRIVER and self.setpoints.driver.idle(now_s):
            self.machine.fire(T.DRIVER_IDLE)
            self.setpoints.brake(now_s)
            self.say(now_s, Kind.DRIVER_IDLE, 'info', 'driver commands stopped: holding')
        self.goals.supervise(now_s, self.sensing.state)

    def _control(self, now_s: float, dt_s: float) -> np.ndarray:
        """The volts of ``Tracking`` toward the setpoint, the driver's decided first."""
        if self.state == S.DRIVER:
            self.setpoints.driver.decide(now_s)
        voltage = self.tracking.volts(now_s, dt_s, self._reference, self.sensing.state,
                                      self.sensing.battery_voltage)
        self.recovery.commanded(now_s, self.tracking.setpoint[0])
        return voltage

    def _reference(self, t_s: float):
        """The setpoint (q, q̇, q̈) at ``t_s``; the estimate, at rest, before any."""
        sample = self.setpoints.sample(t_s)
        return (self._rest_q().copy(), np.zeros(2), np.zeros(2)) if sample is None else sample

    def say(self, now_s: float, kind: Kind, level: str, message: str,
            cause: str = '') -> tuple[bool, str]:
        """An event from outside the core's rules (a setting changed, a controller yielded)."""
        self.events.say(now_s, kind, level, message, cause)
        return True, message

    # ------------------------------------------------------------------ outputs

    @property
    def holding_still(self) -> bool:
        """Settled at the hold for ``STILL_AFTER_S`` and nothing to do (no goal, no plan
        request): the loop may tick at ``holding_rate_hz``."""
        return self.still_since_s is not None and not self.requests_waiting and \
            not self.goals.queue.pending() and \
            self.last_step_s - self.still_since_s >= STILL_AFTER_S

    def _settled_at_the_hold(self) -> bool:
        """Holding with nothing to do, settled as at a goal (``Tracking.settled``)."""
        estimate, config = self.estimate, self.config
        return self.state == S.HOLDING and estimate is not None and not self.requests_waiting \
            and not self.goals.queue.pending() and self.tracking.settled(
                estimate, config.goal_tolerance_rad, config.settled_velocity_rad_s)

    def pending_goals(self):
        """The current goal (first) and the queued ones, in the order they will be visited."""
        return self.goals.queue.pending()
