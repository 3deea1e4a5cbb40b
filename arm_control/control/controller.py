"""The controller's pure core: goals in, one voltage per control period out. No ROS here.

Each period the node (or a test, or a benchmark) calls ``step(now_s, reading)``; the core

1. estimates the state (``sensing.Sensing``: the Kalman filter over the readings);
2. supervises: stale sensors, joint limits, the arm moved under it, then the goals
   (``goal_runner.GoalRunner``: the planner's deadline, arrival, dwell, the next goal);
   ``state_machine.py`` holds every allowed transition;
3. commands V = feedforward + PID, clamped to the battery's volts: the feedforward is the held
   voltage that keeps a model of the arm on the trajectory (``PeriodFeedforward``), the PID
   tracks that model's state on the estimate; a planned motion the arm is late on waits for
   it (``_wait_for_a_late_arm``);
4. enforces the safety rules (``safety.py``): control that has failed stops at 0 V (its
   sensors lost, the robot plays the rest of its last profile: ``robot_command``); an
   e-stop by service brakes to rest along the path and holds there (``estop_holds_arm``:
   with no brake, 0 V drops a 45 kg arm); taking control back after 0 V brakes an arm that
   moves, returns it to where it was held, or lifts it clear of forbidden space.

Planning is asynchronous: starting a goal emits a ``PlanRequest`` (``take_plan_requests``)
and the answer comes back as a ``TimedPlan`` through ``on_timed_plan`` -- timed elsewhere
(``plans.PlanTimer``, in the node's worker process). With a ``planner`` object given (tests,
benchmarks in simulated time) the core plans and times in its own step. No plan within
``planner_timeout_s``: the goal fails with the reason -- never a blind move.
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
from arm_control.control.pid import ArmPid
from arm_control.control.plan_messages import PlanRequest, TimedPlan
from arm_control.control.plans import PlanTimer
from arm_control.control.safety import LEAVES_UNTIL_REACHED, SafetyRules, sure_limits
from arm_control.control.sensing import Sensing
from arm_control.control.state_machine import (ArmState as S, COMMANDING, StateMachine, STOPPED,
                                               Trigger as T)
from arm_control.model.feedforward import PeriodFeedforward
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.text import quote

# A planned motion waits for an arm late on it by over WAIT_AFTER_PERIODS periods (its first
# command taken a robot loop late, a weak start), by that lag less those, at most WAIT_LIMIT_S
# in all: an arm that cannot move still meets the tracking-error rule. Driven to catch up, it
# brakes at the motors' limits with only the reserve; a start missed by one robot loop then
# costs several. Slower than WAIT_MIN_SPEED_RAD_S the lag along the path is not read.
WAIT_AFTER_PERIODS, WAIT_LIMIT_S = 0.35, 0.2
WAIT_MIN_SPEED_RAD_S = 0.5


class ArmController:
    """Estimation, supervision, control and safety; the goals run by a ``GoalRunner``. One
    ``step`` per control period returns the voltage to apply [Va, Vb]."""

    def __init__(self, arm: ArmConfig, config: ControllerConfig, planner=None):
        self.arm, self.config, self.planner = arm, config, planner
        self.period_s = config.period_s
        self.plan_timer = PlanTimer(arm, config)
        dynamics, self.forbidden = self.plan_timer.dynamics, self.plan_timer.forbidden
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.max_velocity, self.max_acceleration = sure_limits(dynamics, self.forbidden, arm,
                                                               config)
        self.sensing = Sensing(arm, config.process_noise_rad_s2)
        self.pid = ArmPid.from_config(config)
        self.feedforward = PeriodFeedforward(dynamics, self.period_s,
                                             arm.battery.nominal_voltage)
        self.safety = SafetyRules(arm, config, self.forbidden, self.max_acceleration,
                                  self.max_velocity)
        self.setpoints = Setpoints(DriverMode(
            self.kinematics, self.forbidden, self.max_velocity, self.max_acceleration,
            self.period_s, config.driver_max_speed_mps, config.driver_command_timeout_s),
            self.max_acceleration)
        self.machine, self.events = StateMachine(), EventLog()
        self.goals = GoalRunner(arm, config, self.machine, self.events, self.setpoints)
        self.last_step_s: Optional[float] = None
        self.commanded_q: Optional[np.ndarray] = None    # the setpoint last commanded
        self.resume_motion = None                         # the last motion back after 0 V
        self.held_when_lost: Optional[np.ndarray] = None  # the goal held as sensors went
        self.lost_motion = None                   # ... or the motion under way then
        self.left_times, self.reached_when_left = 0, 0    # motions left since a goal reached
        self.waited_on, self.waited_s = None, 0.0         # the motion that waited, how long
        self.estop_holding = False                        # e-stopped, holding (not at 0 V)
        self.held_by_robot = False      # ... its sensors then lost: the robot plays the rest
        self.voltage = self.feedforward_v = self.feedback_v = np.zeros(2)
        self.saturated = (0, 0)
        self.setpoint = (np.zeros(2), np.zeros(2), np.zeros(2))
        self.tracking_error_rad = np.zeros(2)
        self.estop_error, self.estops = '', 0

    def retune(self, arm: ArmConfig, config: ControllerConfig, settings=None) -> None:
        """Validated settings from the next period (gains, reserves, tolerances, dwell,
        presets; the physics unchanged); ``settings``: their ``ControllerSettings``, built
        outside the node's lock."""
        timer = settings.plan_timer if settings else PlanTimer(arm, config)
        limits = (settings.max_velocity_rad_s, settings.max_acceleration_rad_s2) if settings \
            else sure_limits(timer.dynamics, self.forbidden, arm, config)
        self.arm, self.config = arm, config
        self.goals.arm, self.goals.config = arm, config
        self.safety.config = config
        self.pid.retune(config)
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
        return self.estop_error or self.goals.last_error

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
            self._say(now_s, Kind.DRIVER, 'info', 'driver velocity mode' +
                      (f': {dropped} goals dropped' if dropped else ''))
        self.setpoints.driver.command(now_s, vx_mps, vy_mps)
        return True, 'driver command accepted'

    def cancel(self, now_s: float) -> tuple[bool, str]:
        """Clear the queue and the current goal; brake to rest along the path and hold."""
        if self.state in COMMANDING:
            self.setpoints.brake(now_s)
        dropped = self.goals.drop()
        if self.machine.can(T.CANCEL):
            self.machine.fire(T.CANCEL)
        return self._say(now_s, Kind.CANCELLED, 'info',
                         f'cancelled: {dropped} goals dropped; holding')

    def estop(self, now_s: float, reason: str = 'e-stop requested',
              cut_power: bool = False) -> tuple[bool, str]:
        """Stopped until ``reset``, the queue cleared: braked to rest along the path and held
        there (``estop_holds_arm``, and the arm under control), else -- ``cut_power``, or
        e-stopped again while held -- 0 V. ``cut_power``: control itself failed."""
        hold = self.config.estop_holds_arm and not cut_power and self.state in COMMANDING
        if self.state == S.ESTOPPED:
            if not self.estop_holding and self.held_by_robot:   # the robot held it: 0 V
                self.held_by_robot = False
                return self._say(now_s, Kind.ESTOP, 'error', 'E-STOP again: 0 V until reset')
            if not self.estop_holding:
                return True, 'already e-stopped: 0 V until reset'
        else:
            if hold:
                self.setpoints.brake(now_s)
            self.goals.drop()
            self.machine.fire(T.ESTOP)
            self.estops += 1
        self.estop_holding = hold
        if not hold:
            self.voltage = np.zeros(2)
            self.pid.reset()
        self.estop_error = f'E-STOP: {reason}'
        action = ('braking to rest and holding there until reset (e-stop again: 0 V)' if hold
                  else 'the robot plays the rest of the last profile, held, until reset '
                  '(e-stop again: 0 V)' if self.held_by_robot else '0 V until reset')
        kind = Kind.CONTROL_FAILED if cut_power else Kind.ESTOP
        return self._say(now_s, kind, 'error', f'E-STOP: {reason}; {action}')

    @property
    def unpowered(self) -> bool:
        """Stopped at 0 V: e-stopped (and not holding), disabled or in error."""
        return self.state in STOPPED and not self.estop_holding

    def reset(self, now_s: float) -> tuple[bool, str]:
        """Clear an e-stop or an error; a held arm keeps its hold, one at 0 V is taken back."""
        if not self.machine.can(T.RESET):
            return False, f"nothing to reset in state '{self.state}'"
        previous, holding = self.state, self.estop_holding or self.state == S.ERROR
        self.machine.fire(T.RESET)
        self.estop_holding, self.estop_error, self.goals.last_error = False, '', ''
        self.held_by_robot = False
        what = 'holding where it was held' if holding else self._resume(now_s)
        return self._say(now_s, Kind.RESET, 'info', f'reset from {previous}: {what}')

    def enable(self, now_s: float, enabled: bool) -> tuple[bool, str]:
        """Enable (take the arm back) or disable (0 V, goals dropped)."""
        if enabled:
            if self.state != S.DISABLED:
                return True, f"already enabled (state '{self.state}')"
            self.machine.fire(T.ENABLE)
            return self._say(now_s, Kind.ENABLED, 'info', f'enabled: {self._resume(now_s)}')
        if self.state == S.DISABLED:
            return True, 'already disabled'
        if not self.machine.can(T.DISABLE):
            return False, f"cannot disable in state '{self.state}': reset first"
        self.goals.drop()
        self.machine.fire(T.DISABLE)
        self.held_by_robot = False
        self.voltage = np.zeros(2)
        self.pid.reset()
        return self._say(now_s, Kind.DISABLED, 'info', 'disabled: 0 V, goals dropped')

    # ------------------------------------------------------------------ planning hand-off

    def take_plan_requests(self) -> list[PlanRequest]:
        """Requests for the node to send to the planner (each once)."""
        return self.goals.take_requests()

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
             earlier=()):
        """One control period: returns [Va, Vb] to apply until the next one.

        ``reading``: the sensors' latest sample since the last step (a ``SensorReading``, or
        a plant's Reading), else None; ``reading_time_s``: when it was taken (default now);
        ``earlier``: (reading, time) of those before it since the last step, folded in first.
        """
        dt_s = self.period_s if self.last_step_s is None else max(now_s - self.last_step_s, 0.0)
        self.last_step_s = now_s
        for earlier_reading, earlier_s in earlier:
            self.sensing.update(now_s, earlier_reading, earlier_s, self.voltage)
        self.sensing.update(now_s, reading, reading_time_s, self.voltage)
        self._supervise(now_s)
        pending = self.goals.plans.pending
        if pending is not None and self.planner is not None:
            self.goals.take_requests()
            self.on_timed_plan(now_s, self.plan_timer.plan_and_time(pending, self.planner))
        self.events.flush(now_s)
        if self.unpowered:
            self.voltage, self.tracking_error_rad = np.zeros(2), np.zeros(2)
            return self.voltage.copy()
        self._wait_for_a_late_arm(now_s)
        self.voltage = self._control(now_s, dt_s)
        failure = self.safety.tracking_failed(now_s, self.tracking_error_rad)
        if failure is not None:
            self.estop(now_s, failure, cut_power=True)
            self.voltage = np.zeros(2)
        elif self._leave_motion(now_s):
            self.voltage = self._control(now_s, dt_s)
        return self.voltage.copy()

    def _wait_for_a_late_arm(self, now_s: float) -> None:
        """Shift the planned motion in hand later when the arm is behind on it: the lag is
        the most any joint faster than WAIT_MIN_SPEED_RAD_S is behind, (q_set − q̂)/q̇_set
        (s); the other joint's feedback then keeps it on the path. Not while a plan is
        awaited (one from the moving arm starts where the unshifted motion would be) or
        another motion follows."""
        timeline = self.setpoints.timeline
        motion = timeline.at(now_s)
        if (self.state != S.TRACKING or type(motion) is not Motion
                or motion is not timeline.last or motion.finished(now_s)
                or self.goals.plans.pending is not None):
            return
        if motion is not self.waited_on:
            self.waited_on, self.waited_s = motion, 0.0
        q_set, qd_set, _ = motion.sample(now_s)
        moving = np.abs(qd_set) >= WAIT_MIN_SPEED_RAD_S
        if not moving.any():
            return
        lag_s = float(np.max((q_set - self.sensing.state[:2])[moving] / qd_set[moving]))
        delay_s = min(lag_s - WAIT_AFTER_PERIODS * self.period_s, WAIT_LIMIT_S - self.waited_s,
                      now_s - motion.begin_s)       # it stays the motion in charge
        if delay_s > 0.0:
            motion.delay(delay_s)
            self.waited_s += delay_s
            self.feedforward.reset()                # its reference restarts on the motion
            self.goals.latency = replace(self.goals.latency,        # said on arrival
                                         waiting_for_the_arm_s=self.waited_s)

    def _leave_motion(self, now_s: float) -> bool:
        """Far off the motion it follows to a goal (its commands held up on the way, as DDS
        does for ~0.3 s when a node joins on a loaded machine; a push): a plan at the motors'
        limits leaves nothing to catch up with, so it brakes from where it is while the goal
        is planned again from there -- at most ``LEAVES_UNTIL_REACHED`` times before a goal
        is reached (not per goal: new goals must not keep an arm that cannot follow from the
        tracking-error rule), and past that the rule decides."""
        goal = self.goals.queue.current
        if self.state not in (S.PLANNING, S.TRACKING) or goal is None \
                or not self.safety.far_off(self.tracking_error_rad):
            return False
        reached = self.goals.counts['reached']
        if reached != self.reached_when_left:
            self.left_times, self.reached_when_left = 0, reached
        if self.left_times >= LEAVES_UNTIL_REACHED:
            return False
        self.left_times += 1
        error = np.degrees(self.tracking_error_rad)
        lost = self.setpoints.timeline.last
        self.goals.interrupt()
        self.machine.fire(T.MOVED)
        self._say(now_s, Kind.OFF_PLAN, 'warning',
                  f'({error[0]:+.1f}, {error[1]:+.1f}) deg off its motion to {goal.label}: '
                  f'{self._resume(now_s, lost=lost)}')
        return True

    def _supervise(self, now_s: float) -> None:
        """Sensors, joint limits, a jump of the sensors, then the goals."""
        # The command sent now holds for a period: stop now if by its end the last reading
        # would be older than the timeout, so commanding ends within joint_state_timeout_s.
        age_s = self.sensing.age_s(now_s)
        fresh = age_s + self.period_s <= self.config.joint_state_timeout_s
        if not fresh and self.machine.can(T.SENSORS_LOST):
            self.held_when_lost = self.commanded_q if self.state == S.HOLDING else None
            timeline = self.setpoints.timeline
            self.lost_motion = timeline.last if timeline.moving_at(now_s) else None
            self.goals.interrupt()                  # resumed when the sensors return
            self.machine.fire(T.SENSORS_LOST)
            self.goals.last_error = (f'no joint states for {age_s:.3f} s (limit '
                                     f'{self.config.joint_state_timeout_s:g} s)')
            action = ('the robot plays the rest of the last profile (to rest, held)'
                      if self.config.command_mode == 'profile' else 'sending 0 V')
            self._say(now_s, Kind.SENSORS_LOST, 'error',
                      f'{self.goals.last_error}: {action} until they return')
        if not fresh and self.estop_holding:
            self.held_by_robot = self.config.command_mode == 'profile'
            self.estop(now_s, f'no joint states for {age_s:.3f} s while holding', cut_power=True)
        if fresh and self.state == S.NO_SENSORS:
            held, self.held_when_lost = self.held_when_lost, None
            lost, self.lost_motion = self.lost_motion, None
            what = self._resume(now_s, lost=lost)
            back_to_goal = held is not None and np.allclose(self.resume_motion.final_q, held)
            self.machine.fire(T.SENSORS_BACK_HELD if back_to_goal else T.SENSORS_BACK)
            if back_to_goal:
                self.goals.goal_q = held
            self._say(now_s, Kind.SENSORS_BACK, 'info', f'joint states arriving: {what}')
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
                self._moved(now_s)      # a small jump the PID takes back; a large one, not
        self.setpoints.prune(now_s)
        if self.state == S.DRIVER and self.setpoints.driver.idle(now_s):
            self.machine.fire(T.DRIVER_IDLE)
            self.setpoints.brake(now_s)
            self._say(now_s, Kind.DRIVER_IDLE, 'info', 'driver commands stopped: holding')
        self.goals.supervise(now_s, self.sensing.state)

    def _control(self, now_s: float, dt_s: float) -> np.ndarray:
        """Feedforward at the setpoint plus PID on the estimate, clamped to the battery's
        open-circuit voltage (within its nominal volts, the command's range)."""
        if self.state == S.DRIVER:
            self.setpoints.driver.decide(now_s)
        self.setpoint = self._reference(now_s)
        # The voltage is held over the coming period: the feedforward keeps a model of the
        # arm on the trajectory at every period's end; the PID tracks that model.
        bus = min(self.sensing.battery_voltage, self.arm.battery.nominal_voltage)
        feedforward = self.feedforward.step(now_s, self._reference, battery_voltage=bus)
        reference, estimate = self.feedforward.state, self.sensing.state
        error = reference[:2] - estimate[:2]
        feedback = np.array(self.pid.update(error, reference[2:] - estimate[2:], dt_s,
                                            self.saturated))
        total = feedforward + feedback
        self.saturated = tuple(int(np.sign(v)) if abs(v) > bus else 0 for v in total)
        self.tracking_error_rad = error
        self.feedforward_v, self.feedback_v = feedforward, feedback
        back = self.resume_motion      # under way or braked, its end: not the sag it left
        self.commanded_q = np.array(back.final_q if self.setpoints.in_charge(back, now_s)
                                    else self.setpoint[0], float)
        return np.clip(total, -bus, bus)

    def _reference(self, t_s: float):
        """The setpoint (q, q̇, q̈) at ``t_s``; the estimate, at rest, before any."""
        sample = self.setpoints.sample(t_s)
        return (self._rest_q().copy(), np.zeros(2), np.zeros(2)) if sample is None else sample

    def _moved(self, now_s: float) -> None:
        """The sensors say the arm is far from where the filter had it (pushed, the sim
        reset): hold where it is now; an interrupted goal is planned again from there."""
        self.goals.interrupt()
        self.machine.fire(T.MOVED)
        self.commanded_q = None              # put there on purpose: no going back
        q = np.degrees(self.sensing.state[:2])
        self._say(now_s, Kind.ARM_MOVED, 'warning',
                  f'the arm is not where it was (moved, or the sim reset) at '
                  f'({q[0]:.1f}, {q[1]:.1f}) deg: {self._resume(now_s)}')

    def _resume(self, now_s: float, lost=None) -> str:
        """Take control back after 0 V (``SafetyRules.resume``); says what it does."""
        state = self.sensing.state if self.sensing.started else np.zeros(4)
        motion, what = self.safety.resume(now_s, state, self.commanded_q, lost)
        self.resume_motion = motion
        self.setpoints.driving = False
        self.setpoints.schedule(motion)
        self.goals.goal_q = None
        self.pid.reset()
        return what

    def _say(self, now_s: float, kind: Kind, level: str, message: str) -> tuple[bool, str]:
        self.events.say(now_s, kind, level, message)
        return True, message

    # ------------------------------------------------------------------ outputs

    def pending_goals(self):
        """The current goal (first) and the queued ones, in the order they will be visited."""
        return self.goals.queue.pending()
