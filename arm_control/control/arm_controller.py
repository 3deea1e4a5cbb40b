"""The controller's pure core: goals in, one voltage per control period out. No ROS here.

Each period the node (or a test, or a benchmark) calls ``step(now_s, reading)``; the core

1. estimates the state: the Kalman filter predicts with the voltage it applied and updates
   with the reading (potentiometers, reported velocities, motor encoders);
2. runs the state machine (``state_machine.py``): takes the next goal from the queue,
   notices arrival, dwell, a planner that does not answer, stale sensors;
3. computes the command: feedforward from the coupled inverse dynamics at the setpoint,
   turned into volts by the motor model with back-EMF, plus PID on the estimated state,

       V = voltage_for(q_sp, q̇_sp, q̈_sp) + kp·e + ki·∫e + kd·ė,   clamped to ±max_voltage;

   the voltage is held for a whole period, so the feedforward is the held voltage that
   keeps a model of the arm on the trajectory (``PeriodFeedforward``: each period's
   position and velocity, not only its average voltage), and the PID tracks that model's
   state; the trajectory is timed with ``feedback_voltage_reserve`` volts left for the PID
   where it brakes a joint (``driving_voltage_reserve`` where it drives one);
4. enforces the e-stop rules: tracking error above ``tracking_error_limit_rad`` for
   ``tracking_error_time_s``, or a joint past its limit -> 0 V until ``reset`` (control has
   failed: holding would lean on what failed). An e-stop by service brakes to rest along
   the path and holds there (``estop_holds_arm``): with no brake, 0 V drops a 45 kg arm.

Planning is asynchronous in the node: starting a goal emits a ``PlanRequest``
(``take_plan_requests``); the answer comes back through ``on_plan`` -- or, split so the
slow part can run off the control thread, ``time_plan`` (pure) then ``on_timed_plan``.
With a ``planner`` object given (anything with ``plan(start_q, goal_xy)``), the core calls
it directly, for tests and benchmarks in simulated time. No plan within
``planner_timeout_s``: the goal is rejected with the reason -- never a blind move.

A goal that preempts the current motion (a preset, as a driver's button) is planned from
where the moving setpoint will be a short lead time ahead, with that velocity, and the new
trajectory takes over at that instant: position and velocity continue.

A large jump of the sensors (the filter re-initialises farther from the setpoint than the
tracking-error limit: the arm was moved, the sim restarted) makes the arm hold where it now
is and plan an interrupted goal again from there; a start in forbidden space is left along
the planner's first leg (timed without the free-space check it cannot pass). Every hold
taken where the arm happens to be (sensors back, reset, enable, moved) first lifts it
``world.clearance_rad`` clear of forbidden space if it sagged nearer at 0 V; a plan that
keeps that clearance is timed keeping it too.
"""

from collections import deque
import dataclasses
from dataclasses import dataclass
import math
import time
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.estimator import ArmEstimator
from arm_control.control.goals import choose_branch, Goal, GoalValidator
from arm_control.control.pid import ArmPid
from arm_control.control.state_machine import (ArmState, COMMANDING, StateMachine, STOPPED,
                                               Trigger)
from arm_control.control.trajectory import (estimated_duration_s, PeriodFeedforward,
                                            sure_acceleration_rad_s2, time_optimal_trajectory,
                                            TrajectoryError, TrajectoryLimits)
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace

# A preempting goal's new trajectory starts this far ahead on the current one: the time
# the planner and the timing need, so the switch happens on time. Doubled on each retry.
PREEMPT_LEAD_S = 0.1
# plan_directly times in full only the elbow branches whose quick duration estimate is
# within this fraction of the best one's.
BRANCH_SCREEN_MARGIN = 0.25
# The first waypoint of a plan may differ from the requested start by rounding only.
PLAN_START_TOLERANCE_RAD = 0.01
# ... and its last must put the tool on the goal.
PLAN_GOAL_TOLERANCE_M = 0.002
# A joint past its limit by more than this (or 6 potentiometer sigmas) e-stops the arm.
JOINT_LIMIT_MARGIN_RAD = 0.01
# A sensor jump means the arm was put elsewhere only if the potentiometers moved farther
# between two readings than this speed (three times the motors' free speed through the
# gearbox, 3.5 rad/s) allows, plus this margin for noise; else the arm is falling or pushed.
MAX_JOINT_SPEED_RAD_S = 10.0
LEAP_MARGIN_RAD = 0.05
# Damping of the Jacobian's inverse in driver mode (m): bounded joint speed near a
# singularity (arm straight or folded), exact far from one.
DRIVER_DAMPING_M = 0.05
# Driver mode stops this much short of forbidden space, on top of the braking distance.
DRIVER_STOP_MARGIN_RAD = 0.03
# A hold is lifted clear of forbidden space only from this near it: deeper in, the way out
# is the planner's.
LIFT_REACH_RAD = 0.35
EVENT_HISTORY = 200


@dataclass(frozen=True)
class SensorReading:
    """One sample of the arm's sensors (the node builds it from joint_states and encoders).

    ``encoder_rad`` may hold NaN when the encoders are missing: the filter skips them.
    ``sampled_s``: when the sensors took it on their own clock (the message's stamp; only
    differences are used), NaN if unknown. ``ArmPlant.read()`` returns an object with the
    same fields (but ``sampled_s``).
    """

    potentiometer_rad: tuple[float, float]
    velocity_rad_s: tuple[float, float]
    encoder_rad: tuple[float, float] = (math.nan, math.nan)
    sampled_s: float = math.nan


@dataclass(frozen=True)
class Event:
    """Something people should hear about: a rejection, an e-stop, an arrival, ..."""

    time_s: float
    level: str          # 'info', 'warning' (a goal rejected or failed), 'error' (e-stop)
    message: str


@dataclass(frozen=True)
class PlanRequest:
    """Plan a path from ``start_q`` to ``goal``; the motion starts at ``start_time_s`` moving
    at ``start_velocity_rad_s`` (a preempted motion) or, when None, on acceptance at rest."""

    request_id: int
    goal: Goal
    start_q: tuple[float, float]
    start_velocity_rad_s: tuple[float, float]
    start_time_s: Optional[float]
    sent_time_s: float
    lead_s: float = PREEMPT_LEAD_S


@dataclass(frozen=True)
class TimedPlan:
    """A request's answer: a checked, timed trajectory, or the reason there is none."""

    request: PlanRequest
    trajectory: object = None
    reason: str = ''
    compute_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.trajectory is not None


class HoldTrajectory:
    """Stand still at ``q``: the trajectory of holding."""

    duration_s = 0.0

    def __init__(self, q):
        self.q = np.array(q, dtype=float)

    def sample(self, t_s):
        return self.q.copy(), np.zeros(2), np.zeros(2)


class ChainedTrajectory:
    """Trajectories one after another, each starting where and when the last one ends."""

    def __init__(self, parts):
        self.parts = list(parts)
        self.offsets_s = np.concatenate([[0.0], np.cumsum([p.duration_s for p in self.parts])])
        self.duration_s = float(self.offsets_s[-1])

    def sample(self, t_s):
        index = int(np.clip(np.searchsorted(self.offsets_s, t_s, side='right') - 1,
                            0, len(self.parts) - 1))
        return self.parts[index].sample(t_s - self.offsets_s[index])


class _Anywhere:
    """Free space everywhere: for timing the way out of forbidden space, which the arm is
    already in (the planner's first leg from a start pushed there)."""

    def is_free(self, q):
        q = np.asarray(q, float)
        free = np.ones(q.shape[:-1], dtype=bool)
        return bool(free) if free.ndim == 0 else free


class Motion:
    """A trajectory pinned to the clock: it takes over at ``begin_s`` and is at rest from
    ``end_s`` on, at ``final_q``."""

    def __init__(self, trajectory, begin_s: float):
        self.trajectory = trajectory
        self.begin_s = float(begin_s)
        self.end_s = self.begin_s + float(trajectory.duration_s)
        self.final_q = np.asarray(trajectory.sample(trajectory.duration_s)[0], float).copy()

    def sample(self, now_s: float):
        """(q, q̇, q̈) at ``now_s``; at rest on ``final_q`` from ``end_s`` on."""
        if now_s >= self.end_s:
            return self.final_q.copy(), np.zeros(2), np.zeros(2)
        q, qd, qdd = self.trajectory.sample(max(now_s - self.begin_s, 0.0))
        return np.asarray(q, float), np.asarray(qd, float), np.asarray(qdd, float)

    def finished(self, now_s: float) -> bool:
        return now_s >= self.end_s


class StoppingMotion(Motion):
    """Brake to rest along the path a motion was following (a path known to be free).

    Path time τ runs at rate r = 1 − (t − t₀)/T, from 1 down to 0 over T, so
    q = p(τ), q̇ = ṗ(τ)·r, q̈ = p̈(τ)·r² − ṗ(τ)/T; T is what the acceleration limits need.
    """

    def __init__(self, base: Motion, now_s: float, acceleration_limits):
        _, qd, _ = base.sample(now_s)
        self.base = base
        self.begin_s = float(now_s)
        need = float(np.max(np.abs(qd) / np.asarray(acceleration_limits, float)))
        self.brake_s = max(1.5 * need, 0.05)
        self.end_s = self.begin_s + self.brake_s
        self.final_q = self._path(self.brake_s)[0]

    def _path(self, elapsed_s):
        elapsed = min(max(elapsed_s, 0.0), self.brake_s)
        rate = 1.0 - elapsed / self.brake_s
        tau = elapsed - elapsed ** 2 / (2.0 * self.brake_s)
        q, qd, qdd = self.base.sample(self.begin_s + tau)
        return q, qd * rate, qdd * rate ** 2 - qd / self.brake_s

    def sample(self, now_s: float):
        if now_s >= self.end_s:
            return self.final_q.copy(), np.zeros(2), np.zeros(2)
        return self._path(now_s - self.begin_s)


class StraightStop(Motion):
    """Brake to rest in a straight line: q̇ = q̇₀·(1 − t/T), T = max |q̇₀ᵢ|/aᵢ."""

    def __init__(self, q, qd, now_s: float, acceleration_limits):
        self.q0, self.qd0 = np.array(q, float), np.array(qd, float)
        self.brake_s = max(float(np.max(np.abs(self.qd0) / np.asarray(acceleration_limits))),
                           1e-6)
        self.begin_s = float(now_s)
        self.end_s = self.begin_s + self.brake_s
        self.final_q = self.q0 + 0.5 * self.qd0 * self.brake_s

    def sample(self, now_s: float):
        t = now_s - self.begin_s
        if t >= self.brake_s:
            return self.final_q.copy(), np.zeros(2), np.zeros(2)
        t = max(t, 0.0)
        return (self.q0 + self.qd0 * (t - t * t / (2.0 * self.brake_s)),
                self.qd0 * (1.0 - t / self.brake_s), -self.qd0 / self.brake_s)


class Timeline:
    """The setpoint over time: motions, each taking over from the one before at its
    ``begin_s``. Scheduling a motion drops those that would begin at or after it."""

    def __init__(self):
        self.motions: list[Motion] = []

    def schedule(self, motion: Motion) -> None:
        self.motions = [m for m in self.motions if m.begin_s < motion.begin_s] + [motion]

    def at(self, t_s: float) -> Optional[Motion]:
        """The motion in charge at ``t_s`` (the first one before any has begun)."""
        current = self.motions[0] if self.motions else None
        for motion in self.motions:
            if motion.begin_s <= t_s:
                current = motion
        return current

    def prune(self, now_s: float) -> None:
        active = self.at(now_s)
        if active is not None:
            self.motions = self.motions[self.motions.index(active):]

    @property
    def last(self) -> Optional[Motion]:
        return self.motions[-1] if self.motions else None

    def sample(self, t_s: float):
        motion = self.at(t_s)
        return None if motion is None else motion.sample(t_s)

    def moving_at(self, t_s: float) -> bool:
        last = self.last
        return last is not None and not last.finished(t_s)


class ArmController:
    """The controller: goal queue, planning hand-off, trajectory following, estimation,
    safety. One ``step`` per control period returns the voltage to apply [Va, Vb].

    ``planner``: anything with ``plan(start_q, goal_xy)`` returning an object with ``ok``,
    ``reason`` and ``waypoints_rad``, called directly (tests, benchmarks); None leaves the
    requests to ``take_plan_requests`` (the node sends them to the planner node).
    """

    def __init__(self, arm: ArmConfig, config: ControllerConfig, planner=None):
        self.arm = arm
        self.config = config
        self.planner = planner
        self.dynamics = ArmDynamics(arm)
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.validator = GoalValidator(arm, config.clamp_unreachable_goals)
        self.forbidden = self.validator.forbidden
        self.clear_space = ForbiddenSpace(arm, arm.world.clearance_rad)
        self.limits = TrajectoryLimits.from_config(arm, config)
        self.estimator = ArmEstimator(arm, config.process_noise_rad_s2)
        self.pid = ArmPid.from_config(config)
        self.period_feedforward = PeriodFeedforward(self.dynamics, 1.0 / config.loop_rate_hz,
                                                    arm.battery.nominal_voltage)
        self.machine = StateMachine()
        self.period_s = 1.0 / config.loop_rate_hz
        # Braking and driver mode count on what the motors surely give in any pose, which
        # the trajectory limits (the motors' best) may exceed: no more than the free speed,
        # and the acceleration the least favourable free pose allows.
        self.max_velocity = np.minimum(
            np.asarray(config.max_velocity_rad_s, float),
            [min(self.limits.budget) / motor.back_emf_v(1.0) for motor in self.dynamics.motors])
        self.max_acceleration = np.minimum(
            np.asarray(config.max_acceleration_rad_s2, float),
            sure_acceleration_rad_s2(self.dynamics, self.forbidden, min(self.limits.budget)))
        self.limit_margin_rad = np.array([max(JOINT_LIMIT_MARGIN_RAD,
                                              6.0 * j.potentiometer_noise_rad)
                                          for j in arm.joints])

        self.queue: deque[Goal] = deque()
        self.current_goal: Optional[Goal] = None
        self.goal_started_s = math.nan
        self.goal_deadline_s = math.inf         # planner timeout of the current goal
        self.pending: Optional[PlanRequest] = None
        self._outbox: list[PlanRequest] = []
        self._next_request_id = 1
        self.timeline = Timeline()
        self.goal_q: Optional[np.ndarray] = None     # where the current trajectory ends
        self.arrived_s = -math.inf
        self.last_timed_plan: Optional[TimedPlan] = None
        self.planner_available: Optional[bool] = None   # as the node's client sees it

        self.last_step_s: Optional[float] = None
        self.estimate_time_s: Optional[float] = None
        self.last_reading_s = -math.inf
        self.last_potentiometer: Optional[np.ndarray] = None
        self.last_sampled_s = math.nan  # the last reading's time on the sensors' clock
        self.jumped = False             # the filter re-initialised: the arm is elsewhere
        self.voltage = np.zeros(2)
        self.feedforward_v = np.zeros(2)
        self.feedback_v = np.zeros(2)
        self.saturated = (0, 0)
        self.setpoint = (np.zeros(2), np.zeros(2), np.zeros(2))
        self.tracking_error_rad = np.zeros(2)
        self.over_limit_since_s: Optional[float] = None
        self.estop_holding = False      # e-stopped, holding the arm (not at 0 V)

        # Driver mode: the setpoint over the current period, q̈ constant (decided at t0).
        self.driver_velocity_mps = np.zeros(2)
        self.driver_command_s = -math.inf
        self.driver_t0_s = 0.0
        self.driver_q0 = np.zeros(2)
        self.driver_qd0 = np.zeros(2)
        self.driver_qdd = np.zeros(2)

        self.events: deque[Event] = deque(maxlen=EVENT_HISTORY)
        self._new_events: list[Event] = []
        self.last_error = ''
        self.queue_version = 0
        self.counts = {'queued': 0, 'started': 0, 'rejected': 0, 'reached': 0, 'failed': 0,
                       'estops': 0}

    @property
    def state(self) -> ArmState:
        return self.machine.state

    # ------------------------------------------------------------------ commands

    def submit_goal(self, now_s: float, x: float, y: float, z: float = 0.0,
                    frame_id: str = '', label: Optional[str] = None,
                    preempt: bool = False) -> tuple[bool, str]:
        """Queue a goal point -- or, with ``preempt``, drop the queue and go there now from
        wherever the arm is, moving or not. Returns (accepted, the sentence said about it)."""
        name = label or f'({x}, {y})'
        if self.state == ArmState.ESTOPPED:
            return self._reject(now_s, f'goal {name} rejected: the arm is e-stopped; call '
                                       'reset first')
        if self.state == ArmState.DISABLED:
            return self._reject(now_s, f'goal {name} rejected: the arm is disabled; enable '
                                       'it first')
        check = self.validator.check(x, y, z, frame_id, label)
        if not check.ok:
            return self._reject(now_s, f'goal rejected: {check.reason}')
        goal = check.goal
        note = f' ({goal.note})' if goal.note else ''
        if preempt:
            dropped = len(self.queue) + (self.current_goal is not None)
            self.queue.clear()
            self.queue_version += 1
            extra = f'; {dropped} earlier goals dropped' if dropped else ''
            if self.machine.can(Trigger.GOAL):
                self._start_goal(now_s, goal)
                return self._accept(now_s, f'goal {goal.label} accepted{note}: going there '
                                           f'now{extra}')
            self.current_goal = None
            self.queue.append(goal)
            return self._accept(now_s, f'goal {goal.label} accepted{note}: next{extra}')
        if len(self.queue) >= self.config.goal_queue_size:
            return self._reject(now_s, f'goal {goal.label} rejected: the queue is full '
                                       f'({self.config.goal_queue_size} goals waiting); the '
                                       'queued goals are kept')
        self.queue.append(goal)
        self.queue_version += 1
        self.counts['queued'] += 1
        return self._accept(now_s, f'goal {goal.label} queued{note} ({len(self.queue)} '
                                   'waiting)')

    def submit_preset(self, now_s: float, name: str, preempt: bool = True) -> tuple[bool, str]:
        """A named goal from the parameter file, as a driver's button: by default it
        replaces the queue and the current motion."""
        for preset, x, y in self.arm.presets:
            if preset == name:
                return self.submit_goal(now_s, x, y, 0.0, '', f"preset '{name}'", preempt)
        known = ', '.join(p[0] for p in self.arm.presets) or 'none'
        return self._reject(now_s, f"preset '{name}' rejected: no such preset (known: {known})")

    def driver_command(self, now_s: float, vx_mps: float, vy_mps: float,
                       frame_id: str = '') -> tuple[bool, str]:
        """End-effector velocity (m/s, arm_base) from a driver; takes over from goals."""
        if not (math.isfinite(vx_mps) and math.isfinite(vy_mps)):
            return self._reject(now_s, f'driver command ({vx_mps}, {vy_mps}) rejected: not '
                                       'finite')
        if frame_id not in ('', 'arm_base'):
            return self._reject(now_s, f"driver command rejected: frame '{frame_id}', "
                                       "expected 'arm_base'")
        if self.state != ArmState.DRIVER:
            if not self.machine.can(Trigger.DRIVER_COMMAND):
                return self._reject(now_s, f"driver command ignored in state '{self.state}'")
            q, qd, _ = self._reference(now_s)
            dropped = len(self.queue) + (self.current_goal is not None)
            self._drop_goals()
            self._fire(Trigger.DRIVER_COMMAND)
            self.driver_t0_s, self.driver_q0, self.driver_qd0 = now_s, q, qd
            self.driver_qdd = np.zeros(2)
            self._say(now_s, 'info', 'driver velocity mode' +
                      (f': {dropped} goals dropped' if dropped else ''))
        velocity = np.array([vx_mps, vy_mps], float)
        speed = float(np.hypot(*velocity))
        if speed > self.config.driver_max_speed_mps:
            velocity *= self.config.driver_max_speed_mps / speed
        self.driver_velocity_mps = velocity
        self.driver_command_s = now_s
        return True, 'driver command accepted'

    def cancel(self, now_s: float) -> tuple[bool, str]:
        """Clear the queue and the current goal; brake to rest along the path and hold."""
        dropped = len(self.queue) + (self.current_goal is not None)
        if self.state in COMMANDING:
            self._brake(now_s)
        self._drop_goals()
        if self.machine.can(Trigger.CANCEL):
            self._fire(Trigger.CANCEL)
        message = f'cancelled: {dropped} goals dropped; holding'
        self._say(now_s, 'info', message)
        return True, message

    def estop(self, now_s: float, reason: str = 'e-stop requested',
              cut_power: bool = False) -> tuple[bool, str]:
        """Stopped until ``reset``, the queue cleared: braked to rest along the path and held
        there (``estop_holds_arm``, and the arm under control), else -- ``cut_power``, or
        e-stopped again while held -- 0 V."""
        hold = self.config.estop_holds_arm and not cut_power and self.state in COMMANDING
        if self.state == ArmState.ESTOPPED:
            if not self.estop_holding:
                return True, 'already e-stopped: 0 V until reset'
        else:
            if hold:
                self._brake(now_s)
            self._drop_goals()
            self._fire(Trigger.ESTOP)
            self.counts['estops'] += 1
        self.estop_holding = hold
        if not hold:
            self.voltage = np.zeros(2)
            self.pid.reset()
        self.last_error = f'E-STOP: {reason}'
        action = ('braking to rest and holding there until reset (e-stop again: 0 V)' if hold
                  else '0 V until reset')
        message = f'E-STOP: {reason}; {action}'
        self._say(now_s, 'error', message)
        return True, message

    def reset(self, now_s: float) -> tuple[bool, str]:
        """Clear an e-stop or an error: hold where the arm is now."""
        if not self.machine.can(Trigger.RESET):
            return False, f"nothing to reset in state '{self.state}'"
        previous = self.state
        self._fire(Trigger.RESET)
        self.estop_holding = False
        self._hold_at_estimate(now_s)
        self.last_error = ''
        message = f'reset from {previous}: holding at the current position'
        self._say(now_s, 'info', message)
        return True, message

    def enable(self, now_s: float, enabled: bool) -> tuple[bool, str]:
        """Enable (hold where the arm is) or disable (0 V, goals dropped)."""
        if enabled:
            if self.state != ArmState.DISABLED:
                return True, f"already enabled (state '{self.state}')"
            self._fire(Trigger.ENABLE)
            self._hold_at_estimate(now_s)
            self._say(now_s, 'info', 'enabled: holding at the current position')
            return True, 'enabled'
        if self.state == ArmState.DISABLED:
            return True, 'already disabled'
        if not self.machine.can(Trigger.DISABLE):
            return False, f"cannot disable in state '{self.state}': reset first"
        self._drop_goals()
        self._fire(Trigger.DISABLE)
        self.voltage = np.zeros(2)
        self.pid.reset()
        self._say(now_s, 'info', 'disabled: 0 V, goals dropped')
        return True, 'disabled'

    # ------------------------------------------------------------------ planning hand-off

    def take_plan_requests(self) -> list[PlanRequest]:
        """Requests for the node to send to the planner (each once)."""
        out, self._outbox = self._outbox, []
        return out

    def time_plan(self, request: PlanRequest, plan) -> TimedPlan:
        """Check a plan and time it. Reads only immutable parts of the core: safe to run
        off the control thread."""
        started = time.perf_counter()
        try:
            trajectory, reason = self._time_plan(request, plan)
        except TrajectoryError as error:
            trajectory, reason = None, f'no trajectory along the plan to {request.goal.label}: ' \
                                       f'{error}'
        return TimedPlan(request, trajectory, reason, time.perf_counter() - started)

    def _time_plan(self, request: PlanRequest, plan):
        if plan is None or not getattr(plan, 'ok', False):
            why = getattr(plan, 'reason', '') or 'the planner found no path'
            return None, f'no plan to {request.goal.label}: {why}'
        waypoints = np.array(plan.waypoints_rad, dtype=float).reshape(-1, 2)
        if len(waypoints) == 0 or not np.all(np.isfinite(waypoints)):
            return None, f'the plan to {request.goal.label} is empty or not finite'
        start = np.asarray(request.start_q, float)
        if np.max(np.abs(waypoints[0] - start)) > PLAN_START_TOLERANCE_RAD:
            return None, (f'the plan to {request.goal.label} starts at '
                          f'{np.round(waypoints[0], 3).tolist()} rad, not where the arm is '
                          f'({np.round(start, 3).tolist()} rad)')
        waypoints[0] = start
        end_xy = self.kinematics.forward(waypoints[-1])
        if math.dist(end_xy, request.goal.xy) > PLAN_GOAL_TOLERANCE_M:
            return None, (f'the plan to {request.goal.label} ends at ({end_xy[0]:.3f}, '
                          f'{end_xy[1]:.3f}) m, not at the goal')
        escape = len(waypoints) > 2 and not self.forbidden.is_free(start)
        if escape:      # the arm is in forbidden space: the planner's first leg takes it out
            out, rest = waypoints[:2], waypoints[1:]
        else:
            out, rest = None, waypoints
        if len(rest) > 1 and not self.forbidden.path_is_free(rest):
            return None, f'the plan to {request.goal.label} enters forbidden space: refused'
        # A path that keeps the clearance is bent (when timing finds a faster shape) only
        # where it keeps it still.
        space = self.clear_space if self.clear_space.path_is_free(rest) \
            else self.forbidden
        if out is None:
            return time_optimal_trajectory(rest, self.dynamics, space, self.limits,
                                           start_velocity_rad_s=request.start_velocity_rad_s), ''
        first = time_optimal_trajectory(out, self.dynamics, _Anywhere(), self.limits,
                                        start_velocity_rad_s=request.start_velocity_rad_s)
        second = time_optimal_trajectory(rest, self.dynamics, space, self.limits)
        return ChainedTrajectory([first, second]), ''

    def plan_directly(self, request: PlanRequest, planner=None) -> TimedPlan:
        """Plan and time ``request`` with ``planner`` (default: the one given to the core).

        A planner that can plan to a configuration (``plan_to_configuration``) is asked for
        each free elbow branch, and the branch whose trajectory is shortest in time wins;
        otherwise the planner chooses the branch (by its own cost).
        """
        planner = planner or self.planner
        started = time.perf_counter()
        if hasattr(planner, 'plan_to_configuration'):
            # Each branch's path, ranked by a quick estimate of its duration; only those
            # within BRANCH_SCREEN_MARGIN of the best are timed in full (path reshaping
            # gains less than that).
            plans = {tuple(q): planner.plan_to_configuration(request.start_q, q)
                     for q in self.validator.free_configurations(*request.goal.xy)}
            several = sum(plan.ok for plan in plans.values()) > 1
            estimates = {q: estimated_duration_s(plan.waypoints_rad, self.dynamics, self.limits)
                         if plan.ok and several else 0.0 for q, plan in plans.items()}
            fastest = min(estimates.values(), default=math.inf)
            timed = {}
            for q, plan in plans.items():
                if plan.ok and estimates[q] <= fastest * (1.0 + BRANCH_SCREEN_MARGIN):
                    option = self.time_plan(request, plan)
                    if option.ok:
                        timed[q] = option
            best = choose_branch(request.start_q, list(timed),
                                 lambda q: timed[tuple(q)].trajectory.duration_s)
            if best is not None:
                return dataclasses.replace(timed[tuple(best)],
                                           compute_s=time.perf_counter() - started)
        plan = planner.plan(request.start_q, request.goal.xy)
        return dataclasses.replace(self.time_plan(request, plan),
                                   compute_s=time.perf_counter() - started)

    def on_plan(self, now_s: float, request: PlanRequest, plan) -> TimedPlan:
        """The planner's answer to ``request``: check it, time it, take it."""
        timed = self.time_plan(request, plan)
        self.on_timed_plan(now_s, timed)
        return timed

    def on_timed_plan(self, now_s: float, timed: TimedPlan) -> None:
        """Take a timed plan (from ``time_plan``); answers to stale requests are ignored."""
        request = timed.request
        if self.pending is None or request.request_id != self.pending.request_id:
            return
        self.pending = None
        self.last_timed_plan = timed
        if not timed.ok:
            self._goal_failed(now_s, timed.reason)
            return
        if request.start_time_s is None:                # from rest: once the arm is there
            last = self.timeline.last
            begin = now_s if last is None else max(now_s, last.end_s)
        elif now_s <= request.start_time_s:             # take over the moving arm on time
            begin = request.start_time_s
        else:                                           # too late for that: ask again
            if now_s + 2.0 * request.lead_s > self.goal_deadline_s:
                self._goal_failed(now_s, f'the plan for {request.goal.label} came too late to '
                                         'take over the moving arm')
            else:
                self._request_plan(now_s, request.goal, 2.0 * request.lead_s)
            return
        motion = Motion(timed.trajectory, begin)
        self.timeline.schedule(motion)
        self.goal_q = motion.final_q
        self._fire(Trigger.PLAN_READY)

    # ------------------------------------------------------------------ the control period

    def step(self, now_s: float, reading=None, reading_time_s: Optional[float] = None):
        """One control period: returns [Va, Vb] to apply until the next one.

        ``reading``: the sensors' latest sample if one arrived since the last step (an
        ``ArmPlant`` Reading or a SensorReading), else None; ``reading_time_s`` when it was
        taken (default now).
        """
        dt_s = self.period_s if self.last_step_s is None else max(now_s - self.last_step_s, 0.0)
        self.last_step_s = now_s
        self._estimate(now_s, reading, reading_time_s)
        self._supervise(now_s)
        if self.pending is not None and self.planner is not None:
            request = self.pending
            self._outbox = []
            self.on_timed_plan(now_s, self.plan_directly(request))
        if self.state in STOPPED and not self.estop_holding:
            self.voltage = np.zeros(2)
            self.tracking_error_rad = np.zeros(2)
            return self.voltage.copy()
        self.voltage = self._control(now_s, dt_s)
        self._check_tracking(now_s)
        if self.state in STOPPED and not self.estop_holding:
            self.voltage = np.zeros(2)
        return self.voltage.copy()

    def _estimate(self, now_s, reading, reading_time_s) -> None:
        """Predict with the applied voltage up to the reading, update, predict up to now."""
        if reading is not None:
            pot = np.asarray(reading.potentiometer_rad, float).reshape(2)
            if not np.all(np.isfinite(pot)):
                reading = None
        if reading is None:
            if self.estimate_time_s is not None and now_s > self.estimate_time_s:
                self.estimator.predict(self.voltage, now_s - self.estimate_time_s)
                self.estimate_time_s = now_s
            return
        taken_s = now_s if reading_time_s is None else min(reading_time_s, now_s)
        velocity = np.asarray(reading.velocity_rad_s, float).reshape(2)
        encoder = np.asarray(reading.encoder_rad, float).reshape(2)
        sampled_s = float(getattr(reading, 'sampled_s', math.nan))
        leapt = self._leapt(pot, taken_s, sampled_s)
        self.last_reading_s = taken_s
        self.last_sampled_s = sampled_s
        self.last_potentiometer = pot
        if self.estimate_time_s is None:
            self.estimator.reset(pot, np.where(np.isfinite(encoder), encoder, 0.0))
            self.estimate_time_s = taken_s
        else:
            if taken_s > self.estimate_time_s:
                self.estimator.predict(self.voltage, taken_s - self.estimate_time_s)
                self.estimate_time_s = taken_s
            resets = self.estimator.jump_count
            self.estimator.update(pot, velocity, encoder)
            self.jumped |= self.estimator.jump_count > resets and leapt
        if now_s > self.estimate_time_s:
            self.estimator.predict(self.voltage, now_s - self.estimate_time_s)
            self.estimate_time_s = now_s

    def _leapt(self, pot, taken_s: float, sampled_s: float) -> bool:
        """The potentiometers moved farther since the last reading than the arm can move: it
        was put somewhere (the sim reset or restarted), not driven or dropped there. A drop --
        the arm failing to follow -- is the tracking-error rule's to judge, not a new hold.

        The interval is the longer of arrival and sampling: readings delayed and delivered
        together (a loaded machine) arrive close but were taken far apart."""
        if self.last_potentiometer is None:
            return True
        interval_s = max(taken_s - self.last_reading_s, 0.0)
        if math.isfinite(sampled_s - self.last_sampled_s):
            interval_s = max(interval_s, sampled_s - self.last_sampled_s)
        step = float(np.max(np.abs(pot - self.last_potentiometer)))
        return step > MAX_JOINT_SPEED_RAD_S * interval_s + LEAP_MARGIN_RAD

    def _supervise(self, now_s: float) -> None:
        """Sensors, joint limits, planner timeout, arrival, dwell, the next goal."""
        # The command sent now holds for a period: stop now if by its end the last reading
        # would be older than the timeout, so commanding ends within joint_state_timeout_s.
        age_s = now_s - self.last_reading_s
        fresh = age_s + self.period_s <= self.config.joint_state_timeout_s
        if not fresh and self.machine.can(Trigger.SENSORS_LOST):
            self.pending, self._outbox = None, []
            if self.current_goal is not None:       # resumed when the sensors return
                self.queue.appendleft(self.current_goal)
                self.current_goal = None
            self._fire(Trigger.SENSORS_LOST)
            self.last_error = (f'no joint states for {age_s:.3f} s (limit '
                               f'{self.config.joint_state_timeout_s:g} s)')
            self._say(now_s, 'error', f'{self.last_error}: sending 0 V until they return')
        if not fresh and self.estop_holding:
            self.estop(now_s, f'no joint states for {age_s:.3f} s while holding', cut_power=True)
        if fresh and self.state == ArmState.NO_SENSORS:
            self._fire(Trigger.SENSORS_BACK)
            self._say(now_s, 'info', 'joint states arriving: holding at the current position')
            self._hold_at_estimate(now_s)
        if self.state in STOPPED:
            self.jumped = False
            self.timeline.prune(now_s)
            return
        if self.last_potentiometer is not None and self._past_a_limit(now_s):
            return
        if self.jumped:
            self.jumped = False
            q_sp = self._reference(now_s)[0]
            if np.max(np.abs(self.estimator.state[:2] - q_sp)) > \
                    self.config.tracking_error_limit_rad:
                self._moved(now_s)      # a small jump the PID takes back; a large one, not
        if self.pending is not None and now_s > self.goal_deadline_s:
            note = ' (the plan_path service is not available)' \
                if self.planner_available is False else ''
            self._goal_failed(now_s, f'the planner did not answer within '
                                     f'{self.config.planner_timeout_s:g} s{note}')
        self.timeline.prune(now_s)
        if self.state == ArmState.TRACKING and self._arrived(now_s):
            self._arrive(now_s)
        elif self.state == ArmState.DRIVER:
            self._driver_timeout(now_s)
        state = self.state
        idle = state in (ArmState.WAITING, ArmState.ERROR) or (
            state == ArmState.HOLDING and now_s >= self.arrived_s + self.config.dwell_s)
        if idle and self.queue:
            goal = self.queue.popleft()
            self.queue_version += 1
            self._start_goal(now_s, goal)

    def _moved(self, now_s: float) -> None:
        """The sensors say the arm is far from where the filter had it (pushed, the sim
        reset): hold where it is now; an interrupted goal is planned again from there."""
        self.pending, self._outbox = None, []
        if self.current_goal is not None:
            self.queue.appendleft(self.current_goal)
            self.current_goal = None
            self.queue_version += 1
        self._fire(Trigger.MOVED)
        self._hold_at_estimate(now_s)
        q = np.degrees(self.estimator.state[:2])
        self._say(now_s, 'warning', f'the arm is not where it was (moved, or the sim reset): '
                                    f'holding at ({q[0]:.1f}, {q[1]:.1f}) deg')

    def _arrived(self, now_s: float) -> bool:
        """Done moving, both joints within tolerance of the goal and nearly still."""
        if self.timeline.moving_at(now_s) or self.goal_q is None:
            return False
        estimate = self.estimator.state
        return bool(np.all(np.abs(estimate[:2] - self.goal_q) <= self.config.goal_tolerance_rad)
                    and np.all(np.abs(estimate[2:]) <= self.config.settled_velocity_rad_s))

    def _arrive(self, now_s: float) -> None:
        goal = self.current_goal
        error = np.degrees(self.estimator.state[:2] - self.goal_q)
        self._fire(Trigger.ARRIVED)
        self.arrived_s = now_s
        self.counts['reached'] += 1
        self.current_goal = None
        self.queue_version += 1
        if goal is not None:
            self._say(now_s, 'info', f'reached {goal.label} {now_s - self.goal_started_s:.2f} s '
                                     f'after starting it (error {error[0]:+.2f}, '
                                     f'{error[1]:+.2f} deg)')

    def _past_a_limit(self, now_s: float) -> bool:
        pot = self.last_potentiometer
        for index, joint in enumerate(self.arm.joints):
            margin = self.limit_margin_rad[index]
            if not (joint.min_angle_rad - margin <= pot[index] <= joint.max_angle_rad + margin):
                self.estop(now_s, f'{joint.name} at {math.degrees(pot[index]):.1f} deg is past '
                                  f'its limits [{math.degrees(joint.min_angle_rad):.1f}, '
                                  f'{math.degrees(joint.max_angle_rad):.1f}] deg',
                           cut_power=True)
                return True
        return False

    def _control(self, now_s: float, dt_s: float) -> np.ndarray:
        """Feedforward at the setpoint plus PID on the estimate, clamped to ±max_voltage."""
        if self.state == ArmState.DRIVER:
            self._driver_step(now_s)
        q_sp, qd_sp, qdd_sp = self._reference(now_s)
        # The voltage is held over the coming period: the feedforward keeps a model of the
        # arm on the trajectory at every period's end; the PID tracks that model.
        feedforward = self.period_feedforward.step(now_s, self._reference)
        reference = self.period_feedforward.state
        estimate = self.estimator.state
        error = reference[:2] - estimate[:2]
        feedback = np.array(self.pid.update(error, reference[2:] - estimate[2:], dt_s,
                                            self.saturated))
        total = feedforward + feedback
        limit = self.arm.battery.nominal_voltage
        self.saturated = tuple(int(np.sign(v)) if abs(v) > limit else 0 for v in total)
        self.setpoint = (q_sp, qd_sp, qdd_sp)
        self.tracking_error_rad = error
        self.feedforward_v, self.feedback_v = feedforward, feedback
        return np.clip(total, -limit, limit)

    def _check_tracking(self, now_s: float) -> None:
        worst = float(np.max(np.abs(self.tracking_error_rad)))
        if worst <= self.config.tracking_error_limit_rad:
            self.over_limit_since_s = None
            return
        if self.over_limit_since_s is None:
            self.over_limit_since_s = now_s
        if now_s - self.over_limit_since_s >= self.config.tracking_error_time_s:
            self.estop(now_s, f'tracking error {math.degrees(worst):.1f} deg above '
                              f'{math.degrees(self.config.tracking_error_limit_rad):.1f} deg '
                              f'for {self.config.tracking_error_time_s:g} s', cut_power=True)

    # ------------------------------------------------------------------ driver mode

    def _driver_sample(self, t_s: float):
        """The driver setpoint: q̈ constant over the period decided at t0, q̇ constant after."""
        tau = max(t_s - self.driver_t0_s, 0.0)
        ramp = min(tau, self.period_s)
        qd_end = self.driver_qd0 + self.driver_qdd * ramp
        q = (self.driver_q0 + self.driver_qd0 * ramp + 0.5 * self.driver_qdd * ramp ** 2
             + qd_end * (tau - ramp))
        return q, qd_end, (self.driver_qdd.copy() if tau < self.period_s else np.zeros(2))

    def _driver_step(self, now_s: float) -> None:
        """Decide the joint velocity at the end of this period: q̇ = J⁻¹v (damped), within
        the speed and acceleration limits; brake instead when moving on and then braking
        would meet forbidden space, so the arm stops short of it."""
        q, qd, _ = self._driver_sample(now_s)
        fresh = now_s - self.driver_command_s <= self.config.driver_command_timeout_s
        tool_velocity = self.driver_velocity_mps if fresh else np.zeros(2)
        target = self.kinematics.joint_velocity_for(q, tool_velocity, DRIVER_DAMPING_M)
        scale = float(np.max(np.abs(target) / self.max_velocity))
        if scale > 1.0:
            target = target / scale
        dt = self.period_s
        new_qd = qd + np.clip(target - qd, -self.max_acceleration * dt,
                              self.max_acceleration * dt)
        if not self._stops_free(q, new_qd):
            new_qd = self._braked(qd)
        self.driver_t0_s, self.driver_q0, self.driver_qd0 = now_s, q, qd
        self.driver_qdd = (new_qd - qd) / dt

    def _braked(self, qd) -> np.ndarray:
        """One period of braking along the same direction at the acceleration limit."""
        need = float(np.max(np.abs(qd) / self.max_acceleration))
        if need <= self.period_s:
            return np.zeros(2)
        return qd * (1.0 - self.period_s / need)

    def _stops_free(self, q, qd) -> bool:
        """Ramping to q̇ over one period and then braking, does the arm stay free, with
        ``DRIVER_STOP_MARGIN_RAD`` to spare?"""
        stop_s = float(np.max(np.abs(qd) / self.max_acceleration))
        travel = qd * (self.period_s + 0.5 * stop_s)
        length = float(np.max(np.abs(travel)))
        if length == 0.0:
            return True
        end = q + travel * (1.0 + DRIVER_STOP_MARGIN_RAD / length)
        return self.forbidden.segment_is_free(q, end, 5 * self.forbidden.check_step_rad)

    def _driver_timeout(self, now_s: float) -> None:
        stale = now_s - self.driver_command_s > self.config.driver_command_timeout_s
        q, qd, _ = self._driver_sample(now_s)
        if stale and not np.any(qd) and not np.any(self.driver_qdd):
            self._fire(Trigger.DRIVER_IDLE)
            self.timeline.schedule(Motion(HoldTrajectory(q), now_s))
            self._say(now_s, 'info', 'driver commands stopped: holding')

    # ------------------------------------------------------------------ helpers

    def _reference(self, t_s: float):
        """The setpoint (q, q̇, q̈) at ``t_s``."""
        if self.state == ArmState.DRIVER:
            return self._driver_sample(t_s)
        sample = self.timeline.sample(t_s)
        if sample is None:
            estimate = self.estimator.state
            return estimate[:2].copy(), np.zeros(2), np.zeros(2)
        return sample

    def _start_goal(self, now_s: float, goal: Goal) -> None:
        """Make ``goal`` current and ask for its plan."""
        if self.state == ArmState.DRIVER:           # leave driver mode by braking to rest
            q, qd, _ = self._driver_sample(now_s)
            self.timeline.schedule(StraightStop(q, qd, now_s, self.max_acceleration) if np.any(qd)
                                   else Motion(HoldTrajectory(q), now_s))
        self.current_goal = goal
        self.goal_started_s = now_s
        self.goal_deadline_s = now_s + self.config.planner_timeout_s
        self.counts['started'] += 1
        self.queue_version += 1
        self._fire(Trigger.GOAL)
        self._request_plan(now_s, goal)

    def _request_plan(self, now_s: float, goal: Goal, lead_s: float = PREEMPT_LEAD_S) -> None:
        """From where the setpoint will be ``lead_s`` ahead if it is still moving then (the
        new motion takes over there), else from where it comes to rest."""
        start_time = now_s + lead_s
        if self.timeline.moving_at(start_time):
            q, qd, _ = self.timeline.sample(start_time)
            begin, velocity = start_time, (float(qd[0]), float(qd[1]))
        else:
            last = self.timeline.last
            q = last.final_q if last is not None else self.estimator.state[:2]
            begin, velocity = None, (0.0, 0.0)
        request = PlanRequest(self._next_request_id, goal, (float(q[0]), float(q[1])),
                              velocity, begin, now_s, lead_s)
        self._next_request_id += 1
        self.pending = request
        self._outbox = [request]

    def _goal_failed(self, now_s: float, reason: str) -> None:
        self.pending, self._outbox = None, []
        self.counts['failed'] += 1
        goal = self.current_goal
        self.current_goal = None
        self.queue_version += 1
        self._brake(now_s)
        if self.machine.can(Trigger.PLAN_FAILED):
            self._fire(Trigger.PLAN_FAILED)
        self.last_error = f'goal {goal.label if goal else ""} failed: {reason}'
        self._say(now_s, 'warning', self.last_error)

    def _brake(self, now_s: float) -> None:
        """Come to rest from the current setpoint (along its path) and hold there."""
        if self.state == ArmState.DRIVER:
            q, qd, _ = self._driver_sample(now_s)
            self.timeline.schedule(StraightStop(q, qd, now_s, self.max_acceleration))
            return
        motion = self.timeline.at(now_s)
        if motion is None:
            return
        if motion.finished(now_s):
            self.timeline.schedule(Motion(HoldTrajectory(motion.final_q), now_s))
        else:
            self.timeline.schedule(StoppingMotion(motion, now_s, self.max_acceleration))

    def _drop_goals(self) -> None:
        if self.queue or self.current_goal is not None:
            self.queue_version += 1
        self.queue.clear()
        self.current_goal = None
        self.pending, self._outbox = None, []

    def _hold_at_estimate(self, now_s: float) -> None:
        """Hold where the arm is; nearer forbidden space than ``world.clearance_rad`` (it
        sagged there at 0 V), lift it clear first, by the shortest straight move."""
        q = self.estimator.state[:2].copy() if self.estimate_time_s is not None else np.zeros(2)
        motion = Motion(HoldTrajectory(q), now_s)
        margin = self.arm.world.clearance_rad
        if self.estimate_time_s is not None and margin > 0.0 and \
                not self.forbidden.clear_by(q, margin):
            target = self.forbidden.nearest_clear(q, margin, LIFT_REACH_RAD)
            lift = None
            if target is not None:
                try:
                    lift = time_optimal_trajectory(np.array([q, target]), self.dynamics,
                                                   _Anywhere(), self.limits)
                except TrajectoryError:
                    pass
            if lift is None:
                self._say(now_s, 'warning', f'the arm is in or within '
                                            f'{math.degrees(margin):.1f} deg of forbidden '
                                            'space and no short move lifts it clear: holding '
                                            'there; the next goal leaves along its plan')
            else:
                motion = Motion(lift, now_s)
                step = np.degrees(target - q)
                self._say(now_s, 'warning', f'the arm is within {math.degrees(margin):.1f} deg '
                                            f'of forbidden space: lifting it clear by '
                                            f'({step[0]:+.1f}, {step[1]:+.1f}) deg, holding '
                                            'there')
        self.timeline.schedule(motion)
        self.goal_q = None
        self.pid.reset()
        self.over_limit_since_s = None

    def _reject(self, now_s: float, message: str) -> tuple[bool, str]:
        self.counts['rejected'] += 1
        self.last_error = message
        self._say(now_s, 'warning', message)
        idle = not self.queue and self.current_goal is None
        if idle and self.machine.can(Trigger.GOAL_FAILED):
            self._fire(Trigger.GOAL_FAILED)
        return False, message

    def _accept(self, now_s: float, message: str) -> tuple[bool, str]:
        self._say(now_s, 'info', message)
        return True, message

    def _fire(self, trigger: Trigger) -> None:
        self.machine.fire(trigger)

    def _say(self, now_s: float, level: str, message: str) -> None:
        event = Event(now_s, level, message)
        self.events.append(event)
        self._new_events.append(event)
        del self._new_events[:-EVENT_HISTORY]

    # ------------------------------------------------------------------ outputs

    def on_planner_available(self, now_s: float, available: bool) -> None:
        """Say when the planner comes or goes: a goal sent while it is away fails at its
        planner timeout, and the reason should already be on record."""
        if available == self.planner_available:
            return
        if available:
            self._say(now_s, 'info', 'the planner (plan_path) is available')
        elif self.planner_available is None:
            self._say(now_s, 'info', 'waiting for the planner (plan_path) to appear')
        else:
            self._say(now_s, 'warning', 'the planner (plan_path) is gone: goals fail until '
                                        'it is back')
        self.planner_available = available

    def take_events(self) -> list[Event]:
        """Events since the last call (for the node to log and publish)."""
        out, self._new_events = self._new_events, []
        return out

    @property
    def estimate(self) -> Optional[np.ndarray]:
        """[θa, θb, ωa, ωb] or None before the first reading."""
        return None if self.estimate_time_s is None else self.estimator.state

    def pending_goals(self) -> list[Goal]:
        """The current goal (first) and the queued ones, in the order they will be visited."""
        current = [self.current_goal] if self.current_goal is not None else []
        return current + list(self.queue)

    def diagnostics(self, now_s: float) -> dict:
        return {
            'state': str(self.state),
            'queued goals': len(self.queue),
            'current goal': self.current_goal.label if self.current_goal else '',
            'joint states age (s)': f'{now_s - self.last_reading_s:.3f}',
            'last error': self.last_error,
            'voltage (V)': [round(float(v), 3) for v in self.voltage],
            'tracking error (deg)': [round(math.degrees(e), 3) for e in self.tracking_error_rad],
            **{f'goals {k}': v for k, v in self.counts.items()},
        }
