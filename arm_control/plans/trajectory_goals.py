"""A ROS client's joint trajectory, checked before the arm moves and watched while it does.

``TrajectoryGoals.prepare`` turns a ``TrajectoryRequest`` into a motion the core follows like
a planned one (``GoalRunner.follow``), or refuses it with a ``FollowJointTrajectory`` code:

- every link, sampled along the whole trajectory, keeps out of forbidden space and its
  clearance (``world.clearance_rad``, as goals do; from a start already in either, it may
  only leave: an arm that sagged or was pushed there must be able to get out);
- the motors can give it: the exact model's volts within the bus less the reserves, the
  currents within their limits, the bus above brownout (``timing.check``, as for the
  planner's trajectories). A timing they cannot give is refused with where and by how much
  (``trajectory_infeasible_timing: reject``) or retimed (``retime``) to the fastest timing
  along the same points that they can (``time_optimal_trajectory``: corners rounded within
  free space, as the planner's paths are) but never sooner than asked, else the same spline
  slowed down uniformly.

``TrajectoryWatch`` then judges the goal each monitor period as JTC does: path tolerances
until the end, goal tolerances after it within ``goal_time_tolerance``; and it ends the goal
when the arm stops following it (e-stop, cancel, another goal, the arm off its motion).
"""

from dataclasses import dataclass
import math
from typing import Any, Mapping, Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig, JOINT_NAMES
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.world import ForbiddenSpace
from arm_control.parameters import ParameterError, Reader
from arm_control.plans.joint_trajectory import (ErrorCode, in_arm_order, point_near,
                                                SplineTrajectory, start_delay_s,
                                                TrajectoryRefused, TrajectoryRequest)
from arm_control.timing import (time_optimal_trajectory, TrajectoryError, TrajectoryLimits)
from arm_control.timing.timing import check

TIMINGS = ('retime', 'reject')
# Uniform slow-downs tried when the time-optimal retiming finds nothing.
SLOWER = (1.1, 1.25, 1.5, 2.0, 3.0, 4.0, 6.0)


@dataclass(frozen=True)
class FollowSettings:
    """What to do with a timing the motors cannot give, and the default tolerances."""

    infeasible_timing: str              # 'retime' or 'reject'
    goal_time_s: float                  # default goal_time_tolerance
    goal_position_rad: float            # default goal tolerance (goal_tolerance_rad)
    goal_velocity_rad_s: float          # ... and at rest (settled_velocity_rad_s)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'FollowSettings':
        read = Reader(params)
        timing = read.text('trajectory_infeasible_timing')
        if timing not in TIMINGS:
            raise ParameterError(f"parameter 'trajectory_infeasible_timing' = {timing!r}: "
                                 f'expected one of {list(TIMINGS)}')
        return cls(timing, read.positive('trajectory_goal_time_s'),
                   read.positive('goal_tolerance_rad'), read.positive('settled_velocity_rad_s'))


@dataclass(frozen=True)
class Tolerances:
    """Per joint (rows) the position, velocity and acceleration bounds (inf: none), on the
    path and at the goal, and how long after the end the goal may take."""

    path: np.ndarray
    goal: np.ndarray
    goal_time_s: float

    @classmethod
    def of(cls, request: TrajectoryRequest, settings: FollowSettings) -> 'Tolerances':
        """JTC's rules: a bound > 0 is taken, 0 leaves the default, -1 removes the bound; a
        joint this arm lacks is refused."""
        path = np.full((2, 3), math.inf)
        goal = np.array([[settings.goal_position_rad, settings.goal_velocity_rad_s,
                          math.inf]] * 2)
        for bounds, given, what in ((path, request.path_tolerance, 'path_tolerance'),
                                    (goal, request.goal_tolerance, 'goal_tolerance')):
            for tolerance in given:
                if tolerance.name not in JOINT_NAMES:
                    raise TrajectoryRefused(ErrorCode.INVALID_JOINTS, (
                        f"{what} names {tolerance.name!r}: this arm's joints are "
                        f'{list(JOINT_NAMES)}'))
                row = JOINT_NAMES.index(tolerance.name)
                for column, value in enumerate((tolerance.position, tolerance.velocity,
                                                tolerance.acceleration)):
                    if value > 0.0:
                        bounds[row, column] = value
                    elif value == -1.0:
                        bounds[row, column] = math.inf
                    elif value != 0.0:
                        raise TrajectoryRefused(ErrorCode.INVALID_GOAL, (
                            f'{what} of {tolerance.name} is {value}: > 0, 0 (the default) '
                            'or -1 (none)'))
        goal_time = request.goal_time_tolerance_s
        if not math.isfinite(goal_time) or goal_time < 0.0:
            raise TrajectoryRefused(ErrorCode.INVALID_GOAL,
                                    f'goal_time_tolerance is {goal_time} s')
        return cls(path, goal, goal_time or settings.goal_time_s)


def beyond(bounds: np.ndarray, error) -> Optional[str]:
    """Which bound the error [[q, q̇, q̈] per joint] passes first, in words; None within."""
    for row, joint in enumerate(JOINT_NAMES):
        for column, (what, unit) in enumerate((('position', 'rad'), ('velocity', 'rad/s'),
                                               ('acceleration', 'rad/s^2'))):
            value = float(error[column][row])
            if abs(value) > bounds[row, column]:
                return (f'{joint} {what} error {value:+.4f} {unit} beyond '
                        f'{bounds[row, column]:g}')
    return None


@dataclass
class PreparedTrajectory:
    """A trajectory the arm will follow: the trajectory (its time 0 at ``begin_s``), its
    tolerances, and what was done to it (retimed: said in the result)."""

    trajectory: Any
    begin_s: float
    tolerances: Tolerances
    note: str = ''
    final_q: Any = None


class TrajectoryGoals:
    """Checks ROS clients' joint trajectories against this arm's world and its motors."""

    def __init__(self, arm: ArmConfig, config: ControllerConfig, settings: FollowSettings):
        self.arm, self.settings = arm, settings
        self.dynamics = ArmDynamics(arm)
        self.forbidden = ForbiddenSpace(arm)
        self.clear_space = ForbiddenSpace(arm, arm.world.clearance_rad)
        self.limits = TrajectoryLimits.from_config(arm, config)

    def prepare(self, request: TrajectoryRequest, now_s: float, setpoint) -> PreparedTrajectory:
        """The trajectory from ``setpoint`` (a function of time giving (q, q̇, q̈) where the arm
        is commanded), or ``TrajectoryRefused`` with the code and the reason."""
        delay_s = start_delay_s(request, now_s)
        begin_s = now_s + delay_s
        tolerances = Tolerances.of(request, self.settings)
        q, qd, qdd = (np.asarray(v, float) for v in setpoint(begin_s))
        knots = in_arm_order(request, q)
        spline = SplineTrajectory(knots, q, qd, qdd)
        self.check_space(spline, knots.times_s, 0.0)
        verdict = check(spline, self.dynamics, self.limits)
        if verdict.passes:
            return PreparedTrajectory(spline, begin_s, tolerances, '', spline.q[-1])
        worst = verdict.times[int(np.argmax(verdict.excess_at))]
        reason = (f'the motors cannot give its timing: {self.shortfall(verdict)}, worst '
                  f'{point_near(knots.times_s, worst)}')
        if self.settings.infeasible_timing == 'reject':
            raise TrajectoryRefused(ErrorCode.INVALID_GOAL, reason)
        retimed, how = self.retime(spline, qd)
        self.check_space(retimed, knots.times_s, math.nan)
        note = f'retimed ({reason}): {how}'
        return PreparedTrajectory(retimed, begin_s, tolerances, note, spline.q[-1])

    def shortfall(self, verdict) -> str:
        parts = []
        if math.isinf(verdict.excess_v):
            parts.append('the bus would brown out')
        elif verdict.excess_v > 0.05:
            parts.append(f'{verdict.excess_v:.2f} V past what the bus less the reserves '
                         '(or the current limits, or the brownout floor) allows')
        if verdict.speed_ratio > 1.02:
            parts.append(f'{verdict.speed_ratio:.2f} times the speed cap')
        if verdict.accel_ratio > 1.02:
            parts.append(f'{verdict.accel_ratio:.2f} times the acceleration cap')
        return '; '.join(parts)

    def check_space(self, trajectory, times_s, offset_s: float) -> None:
        """Refuse a trajectory one of whose links enters forbidden space or the clearance
        around it, beyond the stretch it starts in. ``offset_s``: the request's time 0 on the
        trajectory's clock (NaN: retimed, the point's times no longer hold)."""
        step = self.arm.world.check_step_rad
        times = trajectory.check_times()
        q = trajectory.sample_many(times)[0]
        # Finer where a joint moves more than a check step between samples.
        moves = np.max(np.abs(np.diff(q, axis=0)), axis=1)
        extra = [np.linspace(a, b, int(math.ceil(m / step)) + 1)[1:-1]
                 for a, b, m in zip(times[:-1], times[1:], moves) if m > step]
        if extra:
            times = np.sort(np.concatenate([times] + extra))
            q = trajectory.sample_many(times)[0]
        free = np.asarray(self.forbidden.is_free(q), bool).reshape(-1)
        clear = np.asarray(self.clear_space.is_free(q), bool).reshape(-1)
        # The stretch it starts in (forbidden, or within the clearance: an arm pushed or
        # sagged there) it may leave; once out, it must stay out.
        bad = (~free & (np.cumsum(free) > 0)) | (~clear & (np.cumsum(clear) > 0))
        if not np.any(bad):
            return
        first = int(np.argmax(~free if np.any(~free) else bad))   # forbidden before close
        why = self.forbidden.why_forbidden(q[first]) or self.clear_space.why_forbidden(q[first])
        where = (f'at {times[first]:.3f} s of the retimed trajectory' if math.isnan(offset_s)
                 else point_near(times_s, times[first], offset_s))
        raise TrajectoryRefused(ErrorCode.INVALID_GOAL, (
            f'{where}, at {np.round(q[first], 4).tolist()} rad: {why}'))

    def retime(self, spline: SplineTrajectory, start_qd):
        """The fastest timing the motors give along the spline's points (``retime``)."""
        points = spline.q
        try:
            space = self.clear_space if self.clear_space.path_is_free(points) \
                else self.forbidden
            fastest = time_optimal_trajectory(points, self.dynamics, space, self.limits,
                                              start_velocity_rad_s=start_qd, reshape=False)
        except TrajectoryError:
            fastest = None
        asked = spline.duration_s
        if fastest is not None:
            said = (f'the fastest timing along its points, {fastest.duration_s:.3f} s instead '
                    f'of {asked:.3f} s')
            if fastest.duration_s >= asked or np.any(start_qd):
                return fastest, said
            # Never sooner than asked (a client's slow scaling is on purpose): the same
            # timing slowed uniformly to the duration asked, when that passes too.
            slower = fastest.scaled(asked / fastest.duration_s)
            if check(slower, self.dynamics, self.limits).passes:
                return slower, (f'the fastest timing along its points, slowed to the '
                                f'{asked:.3f} s asked')
            return fastest, said
        for factor in SLOWER:
            slower = spline.scaled(factor)
            if check(slower, self.dynamics, self.limits).passes:
                return slower, (f'its own timing {factor:g} times slower, '
                                f'{slower.duration_s:.3f} s')
        raise TrajectoryRefused(ErrorCode.INVALID_GOAL,
                                'the motors cannot give its timing, nor one 6 times slower')


class TrajectoryWatch:
    """One goal's verdict each monitor period, as JTC gives it: None while it runs, else
    (code, sentence)."""

    def __init__(self, motion, tolerances: Tolerances):
        self.motion, self.tolerances = motion, tolerances

    def judge(self, now_s: float, following: bool, why_not: str, actual) -> Optional[tuple]:
        """``following``: the motion is still the one the arm is given (else ``why_not``);
        ``actual``: the estimate [q, q̇] (None before any)."""
        if not following:
            return ErrorCode.PATH_TOLERANCE_VIOLATED, f'the arm stopped following it: {why_not}'
        if actual is None:
            return None
        error = self.error(now_s, actual)
        if now_s < self.motion.end_s:
            broken = beyond(self.tolerances.path, error)
            return None if broken is None else (
                ErrorCode.PATH_TOLERANCE_VIOLATED,
                f'{now_s - self.motion.begin_s:.3f} s into it: {broken}')
        broken = beyond(self.tolerances.goal, error)
        if broken is None:
            return ErrorCode.SUCCESSFUL, ''
        late_s = now_s - self.motion.end_s
        if late_s > self.tolerances.goal_time_s:
            return ErrorCode.GOAL_TOLERANCE_VIOLATED, (
                f'{late_s:.3f} s after its end (goal_time_tolerance '
                f'{self.tolerances.goal_time_s:g} s): {broken}')
        return None

    def error(self, now_s: float, actual) -> np.ndarray:
        """[q, q̇, q̈] desired − actual (rows), per joint (columns); no measured q̈: 0."""
        q, qd, _ = self.motion.sample(now_s)
        actual = np.asarray(actual, float)
        return np.array([q - actual[:2], qd - actual[2:], np.zeros(2)])
