"""Time-optimal trajectories along the planner's joint-space path, under the arm's true limits.

The planner's polyline has its corners rounded (each blend checked free of forbidden space,
else tightened, else the arm stops at that corner), then is timed by TOPP-RA (toppra) under
|V| ≤ max_voltage per joint and the velocity and acceleration limits, with the motor voltage
of the coupled model (``ArmDynamics.voltage_for``)

    V = k·(M(q)q̈ + C(q, q̇)q̇ + τg(q) + τ_friction(q̇)) + e·q̇,   k = R/(n·G·Kt), e = G/Kv.

Along q(s), with x = ṡ², u = s̈: q̇ = q'·ṡ, q̈ = q'·u + q''·x, so

    V = a·u + b·x + c + d·ṡ + k·τ_coulomb(q'·ṡ),   d = (k·b_viscous + e)·q'.

The back-EMF (and viscous) term d·ṡ = d·√x is not of TOPP-RA's canonical form a·u + b·x + c.
It is linearised about the previous profile x₀ (Newton's method),

    d·√x ≈ d·(x + x₀) / (2·√x₀),

which overestimates d·√x (√x is concave), so every row whose √x term is positive -- the
motor driving against its own back-EMF, the side that bounds acceleration and top speed -- is
conservative at every iteration; the braking rows are exact at the fixed point. The profile is
re-solved until it stops changing, then the final trajectory is checked with the exact model
on dense samples; if its voltage still overshoots, the budget is lowered by the overshoot and
it is solved again, and as a last resort time is stretched until the check passes.
"""

from dataclasses import dataclass
import math

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint
from toppra.interpolator import AbstractGeometricPath

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.model.dynamics import ArmDynamics, COULOMB_SMOOTHING_RAD_S
from arm_control.planning.cspace import ForbiddenSpace

toppra.setup_logging('CRITICAL')   # failures are reported here, not by toppra's logger

# Path-speed floor for the back-EMF linearisation (ṡ in rad/s of path): √x₀ never below this.
_SPEED_FLOOR = 1e-3
# Corners that turn by more than this (a near reversal) always stop rather than blend.
_MAX_BLEND_TURN_RAD = math.radians(175.0)
_MAX_BLEND_HALVINGS = 6
# A moving start that must turn by more than this first tries braking, then bending.
_BRAKE_FIRST_TURN_RAD = math.radians(130.0)
# Grid: about one stage per this much path length, within [min, max] stages per piece.
_GRID_STEP_RAD = 0.01
_MIN_STAGES, _MAX_STAGES = 40, 240
_NEWTON_ITERATIONS = 8
_NEWTON_TOLERANCE = 0.003          # relative change of the profile's duration
_VOLTAGE_TOLERANCE = 0.05          # V of overshoot the final check accepts (grid error)
_LIMIT_TOLERANCE = 1.02            # ratio of the velocity/acceleration limits it accepts


@dataclass(frozen=True)
class TrajectoryLimits:
    """What a trajectory may use: per-joint speed and acceleration, and motor volts."""

    max_velocity_rad_s: tuple[float, float]
    max_acceleration_rad_s2: tuple[float, float]
    max_voltage: float          # arm.max_voltage − controller.feedback_voltage_reserve

    @classmethod
    def from_config(cls, arm: ArmConfig, controller: ControllerConfig) -> 'TrajectoryLimits':
        voltage = arm.max_voltage - controller.feedback_voltage_reserve
        if voltage <= 0.0:
            raise ValueError(
                f'feedback_voltage_reserve = {controller.feedback_voltage_reserve} V leaves '
                f'nothing of max_voltage = {arm.max_voltage} V for the trajectory')
        return cls(tuple(controller.max_velocity_rad_s),
                   tuple(controller.max_acceleration_rad_s2), voltage)


class TrajectoryError(ValueError):
    """No trajectory along this path: it leaves free space, or the arm cannot follow it."""


# --- the geometric path ------------------------------------------------------------------

def _ramp(t, r, order):
    """The corner-rounding ramp ρ_r(t) and its derivatives: 0 for t ≤ −r, t for t ≥ r, C³.

    ρ'' = 15/(16r)·(1 − τ²)² on |τ = t/r| < 1 (a smooth bump of unit area), so a polyline
    p(σ) = p₀ + σu₀ + Σ max(0, σ − σₖ)(uₖ − uₖ₋₁) becomes C³ with max(0, ·) → ρ_rₖ.
    """
    tau = np.clip(t / r, -1.0, 1.0)
    inside = np.abs(t) < r
    if order == 0:
        value = (r * (tau / 2 + 15 / 16 * (tau ** 2 / 2 - tau ** 4 / 6 + tau ** 6 / 30))
                 + 5 * r / 32)
        return np.where(inside, value, np.maximum(t, 0.0))
    if order == 1:
        value = 0.5 + 15 / 16 * (tau - 2 * tau ** 3 / 3 + tau ** 5 / 5)
        return np.where(inside, value, (t > 0).astype(float))
    return np.where(inside, 15 / (16 * r) * (1 - tau ** 2) ** 2, 0.0)


def _start_bend(s, r, order):
    """h(σ) = σ·(1 − σ/r)⁴ on [0, r], 0 beyond: h(0) = 0, h'(0) = 1, C³ at σ = r.

    Adding (v̂ − u₀)·h(σ) to the path turns its initial direction from u₀ to v̂ (the arm's
    current direction of motion) and leaves it unchanged from σ = r on.
    """
    tau = np.clip(s / r, 0.0, 1.0)
    inside = s < r
    if order == 0:
        value = s * (1 - tau) ** 4
    elif order == 1:
        value = (1 - tau) ** 3 * (1 - 5 * tau)
    else:
        value = (1 - tau) ** 2 * (20 * tau - 8) / r
    return np.where(inside, value, 0.0)


class BlendedPath(AbstractGeometricPath):
    """A joint-space polyline with rounded corners, parameterised by polyline length σ.

    q(σ) = polyline(σ) + Σₖ (ρ_rₖ − max(0, ·))(σ − σₖ)·(uₖ − uₖ₋₁) + (v̂ − u₀)·h_r₀(σ),
    with uₖ the unit direction of segment k and σₖ the length up to corner k. Exactly the
    polyline outside the blends, so it starts and ends at the first and last points.
    """

    def __init__(self, points, radii, start_direction=None, start_radius=0.0):
        points = np.asarray(points, dtype=float)
        steps = np.diff(points, axis=0)
        self.lengths = np.linalg.norm(steps, axis=1)
        if len(points) < 2 or np.any(self.lengths <= 0.0):
            raise ValueError('a path needs two or more distinct consecutive points')
        self.points = points
        self.directions = steps / self.lengths[:, None]
        self.knots = np.concatenate([[0.0], np.cumsum(self.lengths)])
        self.radii = np.asarray(radii, dtype=float)        # one per interior point
        self.start_radius = float(start_radius)
        self.bend = (np.zeros(2) if start_direction is None or start_radius <= 0.0
                     else np.asarray(start_direction, float) - self.directions[0])
        self.length = float(self.knots[-1])

    @property
    def dof(self) -> int:
        return 2

    @property
    def path_interval(self):
        return np.array([0.0, self.length])

    def __call__(self, path_positions, order=0):
        s = np.atleast_1d(np.asarray(path_positions, dtype=float))
        segment = np.clip(np.searchsorted(self.knots, s, side='right') - 1,
                          0, len(self.lengths) - 1)
        if order == 0:
            fraction = ((s - self.knots[segment]) / self.lengths[segment])[:, None]
            q = self.points[segment] + fraction * (self.points[segment + 1]
                                                   - self.points[segment])
        elif order == 1:
            q = self.directions[segment].copy()
        else:
            q = np.zeros((len(s), 2))
        for k, r in enumerate(self.radii, start=1):
            if r <= 0.0:
                continue
            t = s - self.knots[k]
            near = np.abs(t) < r
            if np.any(near):
                kink = self.directions[k] - self.directions[k - 1]
                correction = _ramp(t[near], r, order)
                if order == 0:                   # minus the polyline's own kink
                    correction -= np.maximum(t[near], 0.0)
                elif order == 1:
                    correction -= (t[near] > 0).astype(float)
                q[near] += correction[:, None] * kink
        if self.start_radius > 0.0:
            near = s < self.start_radius
            if np.any(near):
                q[near] += _start_bend(s[near], self.start_radius, order)[:, None] * self.bend
        return q[0] if np.ndim(path_positions) == 0 else q


# --- timing one piece that starts at a given path speed and ends at rest ------------------

class _VoltageConstraint(toppra.constraint.LinearConstraint):
    """Rows v = a·u + b·x + c with −g ≤ v ≤ g, precomputed on the grid, plus x ≤ x_bound."""

    def __init__(self, a, b, c, bound, x_bound):
        super().__init__()
        self.dof = 2
        self.identical = True
        self.set_discretization_type(toppra.constraint.DiscretizationType.Interpolation)
        self._rows = (a, b, c)
        m = a.shape[1]
        self._F = np.vstack([np.eye(m), -np.eye(m)])
        self._g = np.concatenate([bound, bound])
        self._x_bound = x_bound

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        a, b, c = self._rows
        x_bound = np.column_stack([np.zeros(len(gridpoints)), self._x_bound])
        return toppra.constraint.canlinear_colloc_to_interpolate(
            a, b, c, self._F, self._g, None, x_bound, gridpoints, identical=True)


class _ArmTerms:
    """M(q), C(q, q̇)q̇ and τg(q) of ``ArmDynamics`` for many configurations at once.

    The model has Pedersen's structure (DESIGN.md §4): M00 = α + 2β·cos θb,
    M01 = γ + β·cos θb, M11 = γ, C(q, q̇)q̇ = β·sin θb·[−θ̇b·θ̇a − (θ̇a + θ̇b)·θ̇b, θ̇a²],
    τg = [G1·cos θa + G2·cos(θa + θb), G2·cos(θa + θb)]. The constants are read off the
    model's own scalar methods at a few configurations; the final check of every trajectory
    uses ``voltage_for`` itself.
    """

    def __init__(self, dynamics: ArmDynamics):
        straight = dynamics.mass_matrix((0.0, 0.0))
        square = dynamics.mass_matrix((0.0, math.pi / 2))
        self.alpha, self.gamma = square[0, 0], square[1, 1]
        self.beta = (straight[0, 0] - self.alpha) / 2
        self.g_outer = dynamics.gravity_torque((0.0, 0.0))[1]
        self.g_upper = dynamics.gravity_torque((0.0, math.pi / 2))[0]

    def mass_times(self, q, v):
        """M(q)·v for rows of q and v."""
        cos_b = np.cos(q[:, 1])
        m00, m01 = self.alpha + 2 * self.beta * cos_b, self.gamma + self.beta * cos_b
        return np.column_stack([m00 * v[:, 0] + m01 * v[:, 1],
                                m01 * v[:, 0] + self.gamma * v[:, 1]])

    def coriolis(self, q, qd):
        h = self.beta * np.sin(q[:, 1])
        return np.column_stack([-h * qd[:, 1] * qd[:, 0] - h * (qd[:, 0] + qd[:, 1]) * qd[:, 1],
                                h * qd[:, 0] ** 2])

    def gravity(self, q):
        outer = self.g_outer * np.cos(q[:, 0] + q[:, 1])
        return np.column_stack([self.g_upper * np.cos(q[:, 0]) + outer, outer])


class _PathModel:
    """Voltage and acceleration of the arm along a path as functions of (u, x) on a grid.

    V = a·u + b·x + c + d·√x + coulomb(√x);  q̈ = q'·u + q''·x;  q̇ = q'·√x, with
    a = k·M q',  b = k·(M q'' + C(q, q')q'),  c = k·τg,  d = (k·b_viscous + e)·q'
    (k volts per newton-metre and e back-EMF volts per rad/s of each joint's motors).
    """

    def __init__(self, path: BlendedPath, dynamics: ArmDynamics, grid):
        self.grid = grid
        q, dq, ddq = path(grid), path(grid, 1), path(grid, 2)
        self.q, self.dq, self.ddq = q, dq, ddq
        motors = dynamics.motors
        volts_per_nm = np.array([m.voltage_for(1.0, 0.0) for m in motors])
        back_emf = np.array([m.back_emf_v(1.0) for m in motors])
        joints = dynamics.arm.joints
        viscous = np.array([j.viscous_friction_nm_s_per_rad for j in joints])
        self._coulomb_v = volts_per_nm * np.array([j.coulomb_friction_nm for j in joints])
        terms = _ArmTerms(dynamics)
        self.a = volts_per_nm * terms.mass_times(q, dq)
        self.b = volts_per_nm * (terms.mass_times(q, ddq) + terms.coriolis(q, dq))
        self.c = volts_per_nm * terms.gravity(q)
        self.d = (volts_per_nm * viscous + back_emf) * dq

    def coulomb(self, speed):
        """k·c·tanh(q'ṡ/ω_s): the model's smoothed Coulomb friction in volts."""
        return self._coulomb_v * np.tanh(self.dq * speed[:, None] / COULOMB_SMOOTHING_RAD_S)

    def voltage(self, u, x):
        speed = np.sqrt(np.maximum(x, 0.0))
        return (self.a * u[:, None] + self.b * x[:, None] + self.c
                + self.d * speed[:, None] + self.coulomb(speed))


def _time_piece(path: BlendedPath, model: _PathModel, limits: TrajectoryLimits,
                voltage_budget: float, start_speed: float, guess=None):
    """TOPP-RA under the voltage (back-EMF linearised about the previous profile) and limits.

    Returns (x on the grid, controllable start x) or (None, controllable start x) when the
    start speed is out of reach. x is the squared path speed ṡ²; the piece ends at rest.
    """
    grid = model.grid
    speed_cap = np.min(np.array(limits.max_velocity_rad_s)
                       / np.maximum(np.abs(model.dq), 1e-9), axis=1)
    x_bound = np.minimum(speed_cap ** 2, 1e4)
    start_x = start_speed ** 2
    if start_x > x_bound[0]:
        # Moving faster than the limits allow already: let it slow down into them.
        slowing = 0.5 * min(limits.max_acceleration_rad_s2)
        x_bound = np.maximum(x_bound, start_x * 1.001 - 2.0 * slowing * grid)
    if guess is None:
        # Start from the speed at which back-EMF alone would use the whole budget.
        headroom = np.maximum(voltage_budget - np.abs(model.c), 0.05 * voltage_budget)
        emf_cap = np.min(headroom / np.maximum(np.abs(model.d), 1e-9), axis=1)
        guess = np.minimum(x_bound, emf_cap ** 2)
    x_prev = np.asarray(guess, float)
    accel_rows = (model.dq, model.ddq, np.zeros_like(model.dq))
    accel_bound = np.array(limits.max_acceleration_rad_s2)
    duration_prev = math.inf
    reachable_start = math.inf
    for iteration in range(_NEWTON_ITERATIONS):
        root = np.sqrt(np.maximum(x_prev, _SPEED_FLOOR ** 2))
        coulomb = model.coulomb(root)
        b_lin = model.b + model.d / (2 * root[:, None])
        c_lin = model.c + model.d * root[:, None] / 2 + coulomb
        a = np.hstack([model.a, accel_rows[0]])
        b = np.hstack([b_lin, accel_rows[1]])
        c = np.hstack([c_lin, accel_rows[2]])
        bound = np.concatenate([[voltage_budget] * 2, accel_bound])
        constraint = _VoltageConstraint(a, b, c, bound, x_bound)
        solver = toppra.algorithm.TOPPRA([constraint], path, gridpoints=grid,
                                         solver_wrapper='seidel')
        _, sd, _, K = solver.compute_parameterization(start_speed, 0.0, return_data=True)
        if K is None or np.isnan(K).any():
            return None, 0.0
        reachable_start = K[0, 1]
        if sd is None:
            # Not (yet) controllable from the start speed. Give up when far out of reach;
            # else linearise next about the fastest controllable speeds and try again.
            if reachable_start < (0.25 if iteration == 0 else 0.6) * start_x:
                break
            x_prev, duration_prev = np.minimum(K[:, 1], x_bound), math.inf
            continue
        if np.isnan(sd).any():
            return None, reachable_start
        duration = _piece_duration(grid, sd)
        converged = abs(duration - duration_prev) <= _NEWTON_TOLERANCE * duration
        x_prev, duration_prev = sd ** 2, duration
        if converged:
            break
    if start_x > reachable_start * (1 + 1e-6) + 1e-9 or math.isinf(duration_prev):
        return None, reachable_start
    return x_prev, reachable_start


def _piece_duration(grid, speed):
    mean = 0.5 * (speed[1:] + speed[:-1])
    return float(np.sum(np.diff(grid) / np.maximum(mean, 1e-12)))


@dataclass
class _Piece:
    """One timed piece: s(t) piecewise quadratic on the grid (s̈ constant per stage)."""

    path: BlendedPath
    grid: np.ndarray
    speed: np.ndarray        # ṡ at the grid points
    accel: np.ndarray        # s̈ on each stage
    times: np.ndarray        # t at the grid points, from the piece's start
    end_rad: np.ndarray

    @classmethod
    def from_profile(cls, path, grid, x, time_scale=1.0):
        speed = np.sqrt(np.maximum(x, 0.0)) / time_scale
        deltas = np.diff(grid)
        mean = 0.5 * (speed[1:] + speed[:-1])
        if np.any(mean <= 0.0):
            raise TrajectoryError('the path speed profile stalls before the end')
        stage_s = deltas / mean
        accel = (speed[1:] - speed[:-1]) / stage_s
        times = np.concatenate([[0.0], np.cumsum(stage_s)])
        return cls(path, grid, speed, accel, times, path.points[-1].copy())

    @property
    def duration_s(self) -> float:
        return float(self.times[-1])

    def state(self, t):
        """(s, ṡ, s̈) at time t within the piece (t in [0, duration])."""
        t = np.atleast_1d(t)
        i = np.clip(np.searchsorted(self.times, t, side='right') - 1, 0, len(self.accel) - 1)
        tau = t - self.times[i]
        s = self.grid[i] + self.speed[i] * tau + 0.5 * self.accel[i] * tau ** 2
        return (np.minimum(s, self.grid[i + 1]), self.speed[i] + self.accel[i] * tau,
                self.accel[i])

    def sample(self, t):
        s, sd, sdd = self.state(t)
        dq, ddq = self.path(s, 1), self.path(s, 2)
        return (self.path(s), dq * sd[:, None],
                dq * sdd[:, None] + ddq * (sd ** 2)[:, None])


class Trajectory:
    """q(t), q̇(t), q̈(t) along the timed pieces; t clamped to [0, duration], at rest after."""

    def __init__(self, pieces, start_rad, end_rad):
        self._pieces = list(pieces)
        self._offsets = np.concatenate(
            [[0.0], np.cumsum([p.duration_s for p in self._pieces])])
        self.duration_s = float(self._offsets[-1])
        self.start_rad = np.array(start_rad, dtype=float)
        self.end_rad = np.array(end_rad, dtype=float)
        self.peak_voltage = math.nan          # set by the final check

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, q̈), each shape (2,), at time ``t_s`` from the start."""
        q, qd, qdd = self.sample_many(np.array([float(t_s)]))
        return q[0], qd[0], qdd[0]

    def sample_many(self, times_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, q̈), each shape (n, 2), at each of ``times_s``."""
        times = np.clip(np.asarray(times_s, dtype=float).reshape(-1), 0.0, self.duration_s)
        q = np.tile(self.end_rad, (len(times), 1))
        qd, qdd = np.zeros_like(q), np.zeros_like(q)
        if not self._pieces:
            return q, qd, qdd
        index = np.clip(np.searchsorted(self._offsets, times, side='right') - 1,
                        0, len(self._pieces) - 1)
        for i, piece in enumerate(self._pieces):
            mine = (index == i) & (times < self.duration_s)
            if np.any(mine):
                q[mine], qd[mine], qdd[mine] = piece.sample(times[mine] - self._offsets[i])
        return q, qd, qdd

    def check_times(self) -> np.ndarray:
        """Every grid time and stage midpoint: where the constraints were imposed and between."""
        times = []
        for offset, piece in zip(self._offsets, self._pieces):
            mid = 0.5 * (piece.times[1:] + piece.times[:-1])
            times.append(offset + np.concatenate([piece.times, mid]))
        return np.sort(np.concatenate(times)) if times else np.zeros(1)

    def scaled(self, factor: float) -> 'Trajectory':
        """The same path, ``factor`` times slower (factor > 1) or faster."""
        pieces = [_Piece.from_profile(p.path, p.grid, p.speed ** 2, factor)
                  for p in self._pieces]
        return Trajectory(pieces, self.start_rad, self.end_rad)


def trajectory_voltage(trajectory: Trajectory, dynamics: ArmDynamics, times_s=None):
    """The feedforward volts (n, 2) the model needs along the trajectory at ``times_s``."""
    times = trajectory.check_times() if times_s is None else np.asarray(times_s, float)
    q, qd, qdd = trajectory.sample_many(times)
    return np.array([dynamics.voltage_for(*state) for state in zip(q, qd, qdd)])


# --- the path: blends verified free, stops where they cannot be -------------------------

def _clean_waypoints(waypoints_rad) -> np.ndarray:
    points = np.asarray(waypoints_rad, dtype=float)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) == 0:
        raise TrajectoryError(f'waypoints must be an (n, 2) array of joint angles, '
                              f'got shape {points.shape}')
    if not np.all(np.isfinite(points)):
        raise TrajectoryError('waypoints contain a non-finite angle')
    keep = [points[0]]
    for point in points[1:]:
        if np.linalg.norm(point - keep[-1]) > 1e-9:
            keep.append(point)
    # Drop interior points on a straight line (no corner there).
    out = [keep[0]]
    for i in range(1, len(keep) - 1):
        before, after = keep[i] - out[-1], keep[i + 1] - keep[i]
        cross = before[0] * after[1] - before[1] * after[0]
        if abs(cross) > 1e-9 * np.linalg.norm(before) * np.linalg.norm(after) \
                or np.dot(before, after) < 0.0:
            out.append(keep[i])
    if len(keep) > 1:
        out.append(keep[-1])
    return np.array(out)


def _unit(vector) -> np.ndarray:
    return vector / np.linalg.norm(vector)


def _turn_angle(u_in, u_out) -> float:
    return math.acos(max(-1.0, min(1.0, float(np.dot(u_in, u_out)))))


def _initial_radii(points) -> np.ndarray:
    """The largest blends whose regions do not overlap: r_k + r_k+1 ≤ the segment between."""
    lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)
    directions = np.diff(points, axis=0) / lengths[:, None]
    count = len(points) - 2
    radii = np.zeros(count)
    for k in range(1, len(points) - 1):
        if _turn_angle(directions[k - 1], directions[k]) > _MAX_BLEND_TURN_RAD:
            continue
        share_in = lengths[k - 1] if k == 1 else lengths[k - 1] / 2
        share_out = lengths[k] if k == len(points) - 2 else lengths[k] / 2
        radii[k - 1] = min(share_in, share_out)
    return radii


def _forbidden_at(path: BlendedPath, forbidden: ForbiddenSpace, step_rad: float):
    """Path positions σ of the samples (about ``step_rad`` apart in q) that are forbidden."""
    speed = 1.0 + 1.2 * float(np.linalg.norm(path.bend))      # bounds |q'(σ)|
    s = np.linspace(0.0, path.length, max(2, int(math.ceil(path.length * speed / step_rad)) + 1))
    return s[~np.asarray(forbidden.is_free(path(s)), dtype=bool)]


def _free_blends(points, radii, forbidden, step_rad, start_direction=None, start_radius=0.0,
                 ignore_until=-1.0):
    """Halve each blend (and the start bend) with forbidden samples; 0 means stop there.

    Samples up to path position ``ignore_until`` are not checked (the planner's way out of
    forbidden space when the arm starts inside it). Returns (radii, start_radius). Raises
    TrajectoryError when the polyline itself is not free.
    """
    radii = radii.copy()
    for _ in range(_MAX_BLEND_HALVINGS + 1):
        path = BlendedPath(points, radii, start_direction, start_radius)
        bad = _forbidden_at(path, forbidden, step_rad)
        bad = bad[bad > ignore_until]
        if len(bad) == 0:
            return radii, start_radius
        changed = False
        for k, r in enumerate(radii):
            if r > 0.0 and np.any(np.abs(bad - path.knots[k + 1]) < r):
                radii[k] = r / 2 if r / 2 > step_rad else 0.0
                changed = True
        if start_radius > 0.0 and np.any(bad < start_radius):
            start_radius = start_radius / 2 if start_radius / 2 > step_rad else 0.0
            changed = True
        if not changed:
            break
    polyline = BlendedPath(points, np.zeros_like(radii))
    bad = _forbidden_at(polyline, forbidden, step_rad)
    bad = bad[bad > ignore_until]
    if len(bad):
        where = polyline(bad[0])
        raise TrajectoryError(
            f'the planned path itself enters forbidden space at '
            f'({math.degrees(where[0]):.1f}, {math.degrees(where[1]):.1f}) deg: '
            f'{forbidden.why_forbidden(where)}')
    return np.zeros_like(radii), 0.0


def _split_at_stops(points, radii):
    """Pieces (points, radii) between corners with no blend (the arm stops there)."""
    pieces, first = [], 0
    for k, r in enumerate(radii, start=1):
        if r <= 0.0:
            pieces.append((points[first:k + 1], radii[first:k - 1]))
            first = k
    pieces.append((points[first:], radii[first:]))
    return pieces


def _grid_for(path: BlendedPath) -> np.ndarray:
    """Uniform stages, finer inside the blends (where q'' changes fast)."""
    length = path.length
    stages = int(min(_MAX_STAGES, max(_MIN_STAGES, math.ceil(length / _GRID_STEP_RAD))))
    grid = [np.linspace(0.0, length, stages + 1)]
    step = length / stages
    bends = [(knot, r) for knot, r in zip(path.knots[1:-1], path.radii) if r > 0.0]
    if path.start_radius > 0.0:
        bends.append((0.0, path.start_radius))
    for centre, r in bends:
        fine = min(step, r / 16)
        if fine < step:
            grid.append(np.arange(max(centre - r, 0.0), min(centre + r, length), fine))
    grid = np.unique(np.concatenate(grid))
    keep = np.concatenate([[True], np.diff(grid) > 1e-6 * max(length, 1.0)])
    grid = grid[keep]
    grid[-1] = length
    return grid


# --- the public entry point -----------------------------------------------------------

def time_optimal_trajectory(waypoints_rad, dynamics: ArmDynamics, forbidden: ForbiddenSpace,
                            limits: TrajectoryLimits, start_velocity_rad_s=(0.0, 0.0),
                            check_step_rad: float = 0.001745) -> Trajectory:
    """The fastest trajectory along the planner's path within the arm's voltage and limits.

    ``waypoints_rad`` (n, 2): a piecewise-linear joint-space path whose first point is where
    the arm is. It leaves at ``start_velocity_rad_s`` (a preempted move keeps moving: the
    path first bends smoothly from that direction into the first segment, or when it cannot
    turn in time, brakes along its direction of motion and comes back) and ends at rest
    exactly on the last waypoint. Raises TrajectoryError when no such trajectory exists.
    """
    points = _clean_waypoints(waypoints_rad)
    velocity = np.asarray(start_velocity_rad_s, dtype=float).reshape(2)
    if not np.all(np.isfinite(velocity)):
        raise TrajectoryError(f'start velocity {velocity} is not finite')
    start, end = points[0].copy(), np.asarray(waypoints_rad, float)[-1].copy()
    speed = float(np.linalg.norm(velocity))
    if speed < 1e-6:
        speed = 0.0
    if len(points) < 2 and speed == 0.0:
        trajectory = Trajectory([], start, end)
        trajectory.peak_voltage = float(np.max(np.abs(dynamics.voltage_for(end, (0, 0), (0, 0)))))
        return trajectory

    if speed == 0.0:
        plans = [lambda: _follow(points, None, dynamics, forbidden, limits, check_step_rad)]
    else:                   # bend the motion onto the path; failing that, brake and return
        plans = [lambda: _follow(points, velocity, dynamics, forbidden, limits,
                                 check_step_rad),
                 lambda: _brake_then_follow(points, velocity, dynamics, forbidden, limits,
                                            check_step_rad)]
        if len(points) < 2:
            plans = plans[1:]
        elif _turn_angle(velocity / speed, _unit(points[1] - points[0])) > _BRAKE_FIRST_TURN_RAD:
            plans.reverse()         # nearly reversing: the bend almost never has the room
    failure = ''
    for plan in plans:
        try:
            pieces = plan()
        except _StartUnreachable as error:
            failure = str(error)
            continue
        return _verified(pieces, start, end, dynamics, limits)
    raise TrajectoryError(failure)


class _StartUnreachable(Exception):
    """The start speed cannot be turned onto the path in time."""


def _timed_piece(points, radii, dynamics, limits, start_speed, start_direction=None,
                 start_radius=0.0, budget=None):
    path = BlendedPath(points, radii, start_direction, start_radius)
    grid = _grid_for(path)
    model = _PathModel(path, dynamics, grid)
    x, reachable = _time_piece(path, model, limits, budget or limits.max_voltage, start_speed)
    if x is None:
        raise _StartUnreachable(
            f'cannot take the path from a start speed of {start_speed:.3f} rad/s: '
            f'at most {math.sqrt(max(reachable, 0.0)):.3f} rad/s is controllable')
    return (path, model, x)


def _follow(points, velocity, dynamics, forbidden, limits, step_rad):
    """Blend the corners (and the start bend when moving), then time each piece."""
    radii = _initial_radii(points)
    start_direction, start_radius = None, 0.0
    speed = 0.0
    if velocity is not None:
        speed = float(np.linalg.norm(velocity))
        start_direction = velocity / speed
        first = points[1] - points[0]
        turn = np.linalg.norm(start_direction - first / np.linalg.norm(first))
        reach = _reference_acceleration(points[0], velocity, dynamics, limits)
        wanted = 8.0 * turn * speed ** 2 / reach          # |q''(0)|·ṡ² ≈ reach
        start_radius = float(min(np.linalg.norm(first), max(4 * step_rad, wanted)))
        if turn < 1e-9:
            start_direction, start_radius = None, 0.0
    ignore_until = -1.0
    if not forbidden.is_free(points[0]):
        # The planner's first segment leads out of forbidden space the arm was pushed into:
        # follow it as it is, and stop where it reaches free space.
        ignore_until = float(np.linalg.norm(points[1] - points[0])) * (1 - 1e-9)
        radii[:1] = 0.0
    radii, start_radius = _free_blends(points, radii, forbidden, step_rad, start_direction,
                                       start_radius, ignore_until)
    if speed > 0.0 and start_direction is not None and start_radius == 0.0:
        raise _StartUnreachable('no free room to bend the current motion onto the path')
    pieces = []
    for i, (piece_points, piece_radii) in enumerate(_split_at_stops(points, radii)):
        first_piece = i == 0
        pieces.append(_timed_piece(piece_points, piece_radii, dynamics, limits,
                                   speed if first_piece else 0.0,
                                   start_direction if first_piece else None,
                                   start_radius if first_piece else 0.0))
    return pieces


def _reference_acceleration(q, velocity, dynamics, limits) -> float:
    """A rough joint acceleration the arm can surely make at q: sizes the start bend."""
    holding = np.abs(dynamics.voltage_for(q, velocity, (0.0, 0.0)))
    per_unit = np.abs(np.array(dynamics.voltage_for(q, velocity, (1.0, 1.0))) - holding)
    spare = np.maximum(limits.max_voltage - holding, 0.0)
    reach = float(np.min(spare / np.maximum(per_unit, 1e-9)))
    return min(max(0.5 * reach, 0.5), min(limits.max_acceleration_rad_s2))


def _brake_then_follow(points, velocity, dynamics, forbidden, limits, step_rad):
    """Keep going along the current motion until stopped, come back, then follow the path."""
    speed = float(np.linalg.norm(velocity))
    direction = velocity / speed
    start = points[0]
    free_length = _free_length(start, direction, forbidden, step_rad)
    distance = _stopping_distance(start, direction, speed, dynamics, limits, free_length)
    if distance is None:
        raise _StartUnreachable(
            f'moving at {speed:.2f} rad/s, the arm cannot stop before forbidden space '
            f'({free_length:.3f} rad ahead)')
    # A little room beyond the exact stop: the timing's linearisation is conservative.
    for stretch in (1.1, 1.3, 1.7):
        length = min(free_length, max(distance * stretch, 4 * step_rad))
        stop = start + length * direction
        try:
            brake = _timed_piece(np.array([start, stop]), np.zeros(0), dynamics, limits, speed)
        except _StartUnreachable:
            continue
        back = _clean_waypoints(np.vstack([stop, points]) if len(points) >= 2
                                else np.array([stop, start]))
        return [brake] + _follow(back, None, dynamics, forbidden, limits, step_rad)
    raise _StartUnreachable(f'moving at {speed:.2f} rad/s, the arm cannot brake in time')


def _free_length(start, direction, forbidden, step_rad, longest_rad=2.0) -> float:
    """How far the straight line from ``start`` along ``direction`` stays free."""
    s = np.arange(0.0, longest_rad + step_rad, step_rad)
    free = np.asarray(forbidden.is_free(start + s[:, None] * direction), dtype=bool)
    blocked = np.flatnonzero(~free)
    return float(longest_rad if len(blocked) == 0 else s[max(blocked[0] - 1, 0)])


def _stopping_distance(start, direction, speed, dynamics, limits, longest_rad):
    """Path length the hardest braking the limits allow takes to stop, or None (exact voltage).

    Steps the path speed forward with the most negative s̈ every row allows at the current
    ṡ: −V ≤ a·u + b·x + c + d·√x + coulomb ≤ V and −A ≤ q'·u + q''·x ≤ A.
    """
    if longest_rad <= 0.0:
        return None
    path = BlendedPath(np.array([start, start + longest_rad * direction]), np.zeros(0))
    stages = int(min(150, max(20, math.ceil(longest_rad / 0.01))))
    grid = np.linspace(0.0, longest_rad, stages + 1)
    model = _PathModel(path, dynamics, grid)
    x = speed ** 2
    for i, delta in enumerate(np.diff(grid)):
        volts = (model.b[i] * x + model.c[i] + model.d[i] * math.sqrt(x)
                 + model.coulomb(np.array([math.sqrt(x)]))[0])
        rows = [(model.a[i], volts, limits.max_voltage),
                (model.dq[i], model.ddq[i] * x, np.array(limits.max_acceleration_rad_s2))]
        lowest = -math.inf
        for slope, offset, bound in rows:
            for k in range(2):
                if abs(slope[k]) > 1e-12:
                    ends = ((-bound if np.ndim(bound) == 0 else -bound[k]) - offset[k],
                            (bound if np.ndim(bound) == 0 else bound[k]) - offset[k])
                    lowest = max(lowest, min(end / slope[k] for end in ends))
        if not math.isfinite(lowest) or lowest >= 0.0:
            return None
        x_next = x + 2 * delta * lowest
        if x_next <= 0.0:
            return float(grid[i] + x / (-2 * lowest))
        x = x_next
    return None


def _verified(pieces, start, end, dynamics, limits) -> Trajectory:
    """Build the trajectory, check it with the exact model, and tighten until it passes."""
    budget, solve_limits = limits.max_voltage, limits
    trajectory = _assemble(pieces, start, end)
    for _ in range(3):
        peak, speed_ratio, accel_ratio = _check(trajectory, dynamics, limits)
        if _passes(limits, peak, speed_ratio, accel_ratio):
            trajectory.peak_voltage = peak
            return trajectory
        # Between grid points the exact model can ask a little more: tighten by the excess.
        budget -= max(peak - limits.max_voltage, 0.0) + _VOLTAGE_TOLERANCE
        solve_limits = TrajectoryLimits(
            tuple(np.array(solve_limits.max_velocity_rad_s) / max(speed_ratio, 1.0)),
            tuple(np.array(solve_limits.max_acceleration_rad_s2) / max(accel_ratio, 1.0)),
            budget)
        retimed = []
        for path, model, x in pieces:
            new_x, _ = _time_piece(path, model, solve_limits, budget, math.sqrt(x[0]), guess=x)
            retimed.append((path, model, x if new_x is None else new_x))
        pieces = retimed
        trajectory = _assemble(pieces, start, end)
    # Last resort: slow the whole thing down until the exact check passes (from rest only:
    # stretching time would change a moving start's velocity).
    moving = pieces[0][2][0] > 0.0
    for factor in () if moving else (1.02, 1.05, 1.1, 1.2, 1.4, 1.7, 2.0, 3.0):
        slower = trajectory.scaled(factor)
        peak, speed_ratio, accel_ratio = _check(slower, dynamics, limits)
        if _passes(limits, peak, speed_ratio, accel_ratio):
            slower.peak_voltage = peak
            return slower
    raise TrajectoryError(
        f'no trajectory found within the limits: it needs {peak:.2f} V of '
        f'{limits.max_voltage:.2f} V, {speed_ratio:.2f} times the speed limit and '
        f'{accel_ratio:.2f} times the acceleration limit')


def _passes(limits, peak, speed_ratio, accel_ratio) -> bool:
    return (peak <= limits.max_voltage + _VOLTAGE_TOLERANCE
            and speed_ratio <= _LIMIT_TOLERANCE and accel_ratio <= _LIMIT_TOLERANCE)


def _assemble(pieces, start, end) -> Trajectory:
    timed = [_Piece.from_profile(path, model.grid, x) for path, model, x in pieces]
    return Trajectory(timed, start, end)


def _check(trajectory, dynamics, limits):
    """Peak |V| of the exact model on the check times, and the largest ratios of speed and
    acceleration to their limits (a start already faster than the speed limit may slow down
    into it)."""
    times = trajectory.check_times()
    q, qd, qdd = trajectory.sample_many(times)
    volts = np.array([dynamics.voltage_for(*state) for state in zip(q, qd, qdd)])
    speed_limit = np.maximum(np.array(limits.max_velocity_rad_s), np.abs(qd[0]))
    speed_ratio = float(np.max(np.abs(qd) / speed_limit))
    accel_ratio = float(np.max(np.abs(qdd) / np.array(limits.max_acceleration_rad_s2)))
    return float(np.max(np.abs(volts))), speed_ratio, accel_ratio
