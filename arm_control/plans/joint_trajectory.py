"""Joint trajectories as ROS arms take them: ``trajectory_msgs/JointTrajectory``, read the way
``joint_trajectory_controller`` (JTC) reads it. No ROS here: the node turns the message into
a ``TrajectoryRequest`` and back.

- Joints are named, in any order; a joint left out holds where it is commanded (JTC's partial
  goal). A name this arm does not have, or a name twice: ``INVALID_JOINTS``.
- Each point gives positions for every named joint, and velocities and accelerations for all
  of them or none; ``time_from_start`` strictly increases. ``header.stamp`` 0 starts it on
  arrival, a later stamp then; one that ends before now: ``OLD_HEADER_TIMESTAMP``.
- Between points the setpoint is a quintic where every point has accelerations, a cubic
  Hermite where they have velocities (JTC's interpolation), and where they give positions
  only, a cubic spline through them (JTC draws straight lines: a 45 kg arm cannot turn a
  corner at speed). It starts from where the arm is commanded at the start (position,
  velocity, acceleration), so a point at time 0 must be there already, and ends at rest.
"""

from dataclasses import dataclass, field
from enum import IntEnum
import math
from typing import Optional, Sequence

import numpy as np

from arm_control.config import JOINT_NAMES

# A point at time 0 must be this close to where the arm is commanded then (rad): the
# setpoint cannot jump.
START_TOLERANCE_RAD = 0.02
# A stamp this little in the past (a client's clock, the trip here) starts the trajectory on
# arrival; older ones are OLD_HEADER_TIMESTAMP (the arm cannot join a trajectory midway).
LATE_STAMP_TOLERANCE_S = 0.1
# The last point's velocities must be within this of zero (rad/s): it ends at rest.
REST_VELOCITY_RAD_S = 1e-3
# Samples for the checks at least this close in time (s).
CHECK_STEP_S = 0.005


class ErrorCode(IntEnum):
    """``control_msgs/action/FollowJointTrajectory`` result codes (the same values)."""

    SUCCESSFUL = 0
    INVALID_GOAL = -1
    INVALID_JOINTS = -2
    OLD_HEADER_TIMESTAMP = -3
    PATH_TOLERANCE_VIOLATED = -4
    GOAL_TOLERANCE_VIOLATED = -5


class TrajectoryRefused(ValueError):
    """A trajectory the arm will not follow: the code a client reads, and the reason."""

    def __init__(self, code: ErrorCode, reason: str):
        super().__init__(reason)
        self.code, self.reason = code, reason


@dataclass(frozen=True)
class TrajectoryPoint:
    positions: tuple
    velocities: tuple = ()
    accelerations: tuple = ()
    time_from_start_s: float = 0.0


@dataclass(frozen=True)
class JointTolerance:
    """``control_msgs/JointTolerance``: > 0 the bound, 0 the default, -1 none."""

    name: str
    position: float = 0.0
    velocity: float = 0.0
    acceleration: float = 0.0


@dataclass(frozen=True)
class TrajectoryRequest:
    """A JointTrajectory (and, from the action, its tolerances) as plain data."""

    joint_names: tuple
    points: tuple
    stamp_s: float = 0.0                    # 0: start on arrival
    path_tolerance: tuple = ()
    goal_tolerance: tuple = ()
    goal_time_tolerance_s: float = 0.0      # 0: the default


@dataclass
class Knots:
    """The trajectory in this arm's joint order: times (n,), positions (n, 2), and velocities
    and accelerations (n, 2) or None where the points do not give them."""

    times_s: np.ndarray
    positions: np.ndarray
    velocities: Optional[np.ndarray] = None
    accelerations: Optional[np.ndarray] = None
    partial: tuple = field(default_factory=tuple)     # the joints held (left out)


def _finite(values, count: int, what: str, index: int, required: bool) -> Optional[np.ndarray]:
    if len(values) == 0 and not required:
        return None
    if len(values) != count:
        raise TrajectoryRefused(ErrorCode.INVALID_GOAL,
                                f'point {index} has {len(values)} {what} for {count} joints')
    array = np.asarray(values, float)
    if not np.all(np.isfinite(array)):
        raise TrajectoryRefused(ErrorCode.INVALID_GOAL,
                                f'point {index} has {what} that are not finite: {list(values)}')
    return array


def in_arm_order(request: TrajectoryRequest, held_q) -> Knots:
    """The request's points in [shoulder, elbow] order, a joint left out held at ``held_q``
    (where it is commanded) at rest; or ``TrajectoryRefused``."""
    names = list(request.joint_names)
    if not names:
        raise TrajectoryRefused(ErrorCode.INVALID_JOINTS, 'the trajectory names no joints')
    unknown = [n for n in names if n not in JOINT_NAMES]
    if unknown or len(set(names)) != len(names):
        what = f'unknown joints {unknown}' if unknown else f'a joint named twice in {names}'
        raise TrajectoryRefused(ErrorCode.INVALID_JOINTS,
                                f"{what}: this arm's joints are {list(JOINT_NAMES)}")
    if not request.points:
        raise TrajectoryRefused(ErrorCode.INVALID_GOAL, 'the trajectory has no points')
    column = [names.index(n) if n in names else None for n in JOINT_NAMES]
    count = len(names)
    times, rows = [], {'positions': [], 'velocities': [], 'accelerations': []}
    for index, point in enumerate(request.points):
        t = float(point.time_from_start_s)
        if not math.isfinite(t) or t < 0.0 or (times and t <= times[-1]):
            raise TrajectoryRefused(ErrorCode.INVALID_GOAL, (
                f'point {index} has time_from_start {t:g} s: times must be finite, from 0 and '
                f'strictly increasing (the point before is at {times[-1] if times else 0:g} s)'))
        times.append(t)
        for what in rows:
            given = _finite(getattr(point, what), count, what, index, what == 'positions')
            rows[what].append(None if given is None else [
                given[c] if c is not None else (held_q[j] if what == 'positions' else 0.0)
                for j, c in enumerate(column)])
    out = {}
    for what, values in rows.items():
        present = [v is not None for v in values]
        if any(present) and not all(present):
            raise TrajectoryRefused(ErrorCode.INVALID_GOAL, (
                f'points {[k for k, p in enumerate(present) if not p]} give no {what} while '
                'others do: give them for every point or none'))
        out[what] = np.array(values, float) if all(present) else None
    if out['velocities'] is not None and \
            np.max(np.abs(out['velocities'][-1])) > REST_VELOCITY_RAD_S:
        raise TrajectoryRefused(ErrorCode.INVALID_GOAL, (
            f'the last point (point {len(times) - 1}) has velocities '
            f'{out["velocities"][-1].tolist()} rad/s: a trajectory must end at rest'))
    return Knots(np.array(times), out['positions'], out['velocities'], out['accelerations'],
                 tuple(n for n, c in zip(JOINT_NAMES, column) if c is None))


def start_delay_s(request: TrajectoryRequest, now_s: float) -> float:
    """How long after ``now_s`` the trajectory's time 0 is (0: on arrival), or
    ``TrajectoryRefused`` (OLD_HEADER_TIMESTAMP) for a stamp the arm can no longer keep."""
    if request.stamp_s == 0.0:
        return 0.0
    delay = request.stamp_s - now_s
    if delay >= -LATE_STAMP_TOLERANCE_S:
        return max(delay, 0.0)
    end = request.stamp_s + max(p.time_from_start_s for p in request.points)
    when = f'ended {now_s - end:.3f} s ago' if end < now_s else 'is under way'
    raise TrajectoryRefused(ErrorCode.OLD_HEADER_TIMESTAMP, (
        f'header.stamp is {-delay:.3f} s in the past and the trajectory {when}: the arm '
        'cannot join one midway (stamp 0 starts it on arrival)'))


class SplineTrajectory:
    """q(t), q̇(t), q̈(t) through the knots from a start state (t = 0): per segment a quintic
    (accelerations given), a cubic Hermite (velocities), or a cubic spline through the
    positions that leaves at the start velocity and ends at rest. At rest after the end."""

    def __init__(self, knots: Knots, start_q, start_qd=(0.0, 0.0), start_qdd=(0.0, 0.0)):
        times, q = knots.times_s, knots.positions
        start_q = np.asarray(start_q, float)
        if times[0] == 0.0:
            gap = float(np.max(np.abs(q[0] - start_q)))
            if gap > START_TOLERANCE_RAD:
                raise TrajectoryRefused(ErrorCode.INVALID_GOAL, (
                    f'point 0 (at 0 s) is {math.degrees(gap):.2f} deg from where the arm is '
                    f'commanded then, {np.round(start_q, 4).tolist()} rad (at most '
                    f'{math.degrees(START_TOLERANCE_RAD):.2f} deg): the setpoint cannot jump'))
            times, q = times[1:], q[1:]
            knots = Knots(times, q, *(None if v is None else v[1:]
                                      for v in (knots.velocities, knots.accelerations)))
        self.times_s = np.concatenate([[0.0], times])
        self.q = np.vstack([start_q, q])
        n = len(self.times_s)
        qd = knots.velocities
        if qd is None and n > 1:
            from scipy.interpolate import CubicSpline   # here: a tenth of a second to import
            spline = CubicSpline(self.times_s, self.q, axis=0,
                                 bc_type=((1, np.asarray(start_qd, float)), (1, np.zeros(2))))
            qd = spline(times, 1)
        self.qd = np.vstack([np.asarray(start_qd, float), qd if n > 1 else np.zeros((0, 2))])
        self.qd[-1] = 0.0
        quintic = knots.accelerations is not None
        self.qdd = np.vstack([np.asarray(start_qdd, float), knots.accelerations]) \
            if quintic else None
        self.duration_s = float(self.times_s[-1])
        self.coefficients = self._coefficients()            # (segments, 6, 2)
        self.peak_voltage = math.nan

    def _coefficients(self) -> np.ndarray:
        """a0..a5 of q(τ) = Σ aₖ τᵏ on each segment [tᵢ, tᵢ₊₁], τ = t − tᵢ, T = tᵢ₊₁ − tᵢ,
        h = qᵢ₊₁ − qᵢ. Cubic Hermite: a2 = (3h − (2v0 + v1)T)/T², a3 = (−2h + (v0 + v1)T)/T³.
        Quintic: a2 = A0/2, a3 = (20h − (8v1 + 12v0)T − (3A0 − A1)T²)/(2T³),
        a4 = (−30h + (14v1 + 16v0)T + (3A0 − 2A1)T²)/(2T⁴), a5 = (12h − 6(v1 + v0)T +
        (A1 − A0)T²)/(2T⁵)."""
        T = np.diff(self.times_s)[:, None]
        h = np.diff(self.q, axis=0)
        v0, v1 = self.qd[:-1], self.qd[1:]
        c = np.zeros((len(T), 6, 2))
        c[:, 0], c[:, 1] = self.q[:-1], v0
        if self.qdd is None:
            c[:, 2] = (3 * h - (2 * v0 + v1) * T) / T ** 2
            c[:, 3] = (-2 * h + (v0 + v1) * T) / T ** 3
        else:
            a0, a1 = self.qdd[:-1], self.qdd[1:]
            c[:, 2] = a0 / 2
            c[:, 3] = (20 * h - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T ** 2) / (2 * T ** 3)
            c[:, 4] = (-30 * h + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T ** 2) \
                / (2 * T ** 4)
            c[:, 5] = (12 * h - 6 * (v1 + v0) * T + (a1 - a0) * T ** 2) / (2 * T ** 5)
        return c

    def sample_many(self, times_s):
        """(q, q̇, q̈), each (n, 2), at each of ``times_s`` (clamped to [0, duration])."""
        t = np.clip(np.asarray(times_s, float).reshape(-1), 0.0, self.duration_s)
        q = np.tile(self.q[-1], (len(t), 1))
        qd, qdd = np.zeros_like(q), np.zeros_like(q)
        if len(self.coefficients) == 0:
            return q, qd, qdd
        moving = t < self.duration_s
        i = np.clip(np.searchsorted(self.times_s, t[moving], side='right') - 1,
                    0, len(self.coefficients) - 1)
        tau = (t[moving] - self.times_s[i])[:, None]
        c = self.coefficients[i]
        q[moving] = sum(c[:, k] * tau ** k for k in range(6))
        qd[moving] = sum(k * c[:, k] * tau ** (k - 1) for k in range(1, 6))
        qdd[moving] = sum(k * (k - 1) * c[:, k] * tau ** (k - 2) for k in range(2, 6))
        return q, qd, qdd

    def sample(self, t_s: float):
        q, qd, qdd = self.sample_many([t_s])
        return q[0], qd[0], qdd[0]

    def check_times(self) -> np.ndarray:
        """Every knot and at least every ``CHECK_STEP_S`` between: where the checks look."""
        count = max(2, int(math.ceil(self.duration_s / CHECK_STEP_S)) + 1)
        return np.union1d(np.linspace(0.0, self.duration_s, count), self.times_s)

    def scaled(self, factor: float) -> 'SplineTrajectory':
        """The same path ``factor`` times slower: t → factor·t, q̇ → q̇/factor, q̈ → q̈/factor²."""
        slower = object.__new__(SplineTrajectory)
        slower.times_s, slower.q = self.times_s * factor, self.q.copy()
        slower.qd = self.qd / factor
        slower.qdd = None if self.qdd is None else self.qdd / factor ** 2
        slower.duration_s = self.duration_s * factor
        slower.coefficients = slower._coefficients()
        slower.peak_voltage = math.nan
        return slower


def point_near(times_s: Sequence[float], t_s: float, offset_s: float = 0.0) -> str:
    """Words for where ``t_s`` (on the request's own clock, ``offset_s`` after its time 0)
    falls among the request's points: 'point 3 (1.200 s)' or 'between point 2 (1.000 s)
    and point 3 (1.500 s)'."""
    t = t_s - offset_s
    times = np.asarray(times_s, float)
    near = int(np.argmin(np.abs(times - t)))
    if abs(times[near] - t) <= 1e-6:
        return f'point {near} ({times[near]:.3f} s)'
    after = int(np.searchsorted(times, t))
    if after == 0:
        return f'before point 0 ({times[0]:.3f} s), coming from where the arm is'
    if after >= len(times):
        return f'after the last point ({times[-1]:.3f} s)'
    return (f'between point {after - 1} ({times[after - 1]:.3f} s) and point {after} '
            f'({times[after]:.3f} s)')
