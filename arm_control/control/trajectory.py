"""Time-optimal trajectories along the planner's joint-space path, under the arm's true limits.

The planner's polyline has its corners rounded (each blend checked free of forbidden space,
else tightened, else the arm stops at that corner), then is timed under the motor voltage of
the coupled model (``ArmDynamics.voltage_for``) and the velocity and acceleration limits,

    V = k·(M(q)q̈ + C(q, q̇)q̇ + τg(q) + τ_friction(q̇)) + e·q̇,   k = R/(n·G·Kt), e = G/Kv.

Along q(s), with x = ṡ², u = s̈: q̇ = q'·ṡ, q̈ = q'·u + q''·x, so

    V = a·u + b·x + c + d·ṡ + k·τ_coulomb(q'·ṡ),   d = (k·b_viscous + e)·q'.

A joint's voltage may go to ``max_voltage`` with its motion (driving) and to
``max_braking_voltage`` against it (braking): the feedback keeps its reserve where it needs it.

From rest (the usual case) the path is first bent where that is faster -- the shortest path
is rarely the fastest: folding the elbow on the way cuts the shoulder's inertia and gravity
load -- by a batched pattern search over a few sine harmonics per joint (``_reshape``), each
shape checked free with room to spare; then it is timed with the back-EMF term d·√x kept
exactly: every constraint is a quadratic in ṡ, so the backward and forward passes of the
classical time-optimal parameterisation have closed forms (``_fastest_speeds``), on a grid
clustered toward both ends, where the discretisation costs the most time.

From a moving start (a preempted move) TOPP-RA (toppra) times the path instead, the √x term
linearised about the previous profile x₀ (Newton's method),

    d·√x ≈ d·(x + x₀) / (2·√x₀),

which overestimates d·√x (√x is concave), so every row whose √x term is positive -- the
motor driving against its own back-EMF, the side that bounds acceleration and top speed -- is
conservative at every iteration; the braking rows are exact at the fixed point. The profile is
re-solved until it stops changing.

Either way the final trajectory is checked with the exact model on dense samples; if its
voltage still overshoots, the budget is lowered by the overshoot and it is solved again, and
as a last resort time is stretched until the check passes. ``PeriodFeedforward`` turns the
trajectory into the voltage a control loop holds over each period.
"""

import dataclasses
from dataclasses import dataclass
import functools
import itertools
import math
from typing import Optional

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint
from toppra.interpolator import AbstractGeometricPath

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.model.dynamics import ArmDynamics, COULOMB_SMOOTHING_RAD_S
from arm_control.model.world import ForbiddenSpace

toppra.setup_logging('CRITICAL')   # failures are reported here, not by toppra's logger

# Path-speed floor for the back-EMF linearisation (ṡ in rad/s of path): √x₀ never below this.
_SPEED_FLOOR = 1e-3
# Corners that turn by more than this (a near reversal) always stop rather than blend.
_MAX_BLEND_TURN_RAD = math.radians(175.0)
_MAX_BLEND_HALVINGS = 6
# A moving start that must turn by more than this first tries braking, then bending.
_BRAKE_FIRST_TURN_RAD = math.radians(130.0)
# Grid: about one stage per this much path length, within [min, max] stages per piece;
# TOPP-RA (moving starts) on the coarser one, the exact timing from rest on the finer.
_GRID_STEP_RAD = 0.01
_MIN_STAGES, _MAX_STAGES = 40, 240
_FINE_GRID_STEP_RAD = 0.005
_FINE_MIN_STAGES, _FINE_MAX_STAGES = 80, 400
_NEWTON_ITERATIONS = 8
_NEWTON_TOLERANCE = 0.003          # relative change of the profile's duration
_VOLTAGE_TOLERANCE = 0.05          # V of overshoot the final check accepts (grid error)
_LIMIT_TOLERANCE = 1.02            # ratio of the velocity/acceleration limits it accepts
# Reshaping (``_reshape``): harmonics per joint, the first batch's grid (per joint, odd: it
# holds 0) and span (± this times the path length), the refinement steps (times the length)
# and how many of them try every combination (the rest one amplitude at a time), the stages
# the shapes are timed on, the room kept, the least gain worth a new shape, and the shortest
# move worth the search (on a shorter one a few percent is less than the search's own time).
_SHAPE_HARMONICS = 2
_SHAPE_GRID = 5
_SHAPE_SPAN = 0.35
_SHAPE_STEPS = (0.06, 0.03, 0.015)
_SHAPE_FULL_STEPS = 3
_SEARCH_STAGES = 20
_RESHAPE_ROOM_M = 0.03
_SHAPE_MIN_GAIN = 0.01
_SHAPE_MIN_DURATION_S = 0.25


@dataclass(frozen=True)
class TrajectoryLimits:
    """What a trajectory may use: per-joint speed and acceleration, and motor volts.

    The volts a joint's motors may get depend on which way they push: ``max_voltage`` with
    the joint's motion (driving), ``max_braking_voltage`` against it (braking; None: the
    same). The feedback needs its reserve on the braking side: an arm ahead of its setpoint
    needs more braking than planned, while an arm behind catches up by braking less.
    """

    max_velocity_rad_s: tuple[float, float]
    max_acceleration_rad_s2: tuple[float, float]
    max_voltage: float          # arm.battery.nominal_voltage − controller.driving_voltage_reserve
    max_braking_voltage: Optional[float] = None   # ... − feedback_voltage_reserve

    @property
    def budget(self) -> tuple[float, float]:
        """(driving, braking) volts."""
        braking = self.max_voltage if self.max_braking_voltage is None \
            else self.max_braking_voltage
        return (self.max_voltage, braking)

    @classmethod
    def from_arm(cls, arm: ArmConfig) -> 'TrajectoryLimits':
        """The arm's own limits: the battery both ways, no caps, no reserves."""
        return cls((1e3, 1e3), (1e5, 1e5), arm.battery.nominal_voltage)

    @classmethod
    def from_config(cls, arm: ArmConfig, controller: ControllerConfig) -> 'TrajectoryLimits':
        controller.check_against(arm)
        volts = arm.battery.nominal_voltage
        # Interim, until the timing drops the rows of an absent cap: caps far beyond what
        # the motors can reach bind nothing.
        speed = tuple(min(v, 1e3) for v in controller.max_velocity_rad_s)
        acceleration = tuple(min(a, 1e5) for a in controller.max_acceleration_rad_s2)
        return cls(speed, acceleration, volts - controller.driving_voltage_reserve,
                   volts - controller.feedback_voltage_reserve)


def _window(dq, budget):
    """(centre, half-width) of each joint's allowed voltage where the path direction is q':
    [−braking, driving] for a joint moving forward (q' > 0), [−driving, braking] backward,
    ±max(driving, braking) where it is still."""
    driving, braking = budget
    direction = np.sign(dq)
    centre = direction * (driving - braking) / 2.0
    half = np.where(direction == 0.0, max(driving, braking), (driving + braking) / 2.0)
    return centre, half


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

    q(σ) = polyline(σ) + Σₖ (ρ_rₖ − max(0, ·))(σ − σₖ)·(uₖ − uₖ₋₁) + (v̂ − u₀)·h_r₀(σ)
           + Σₕ aₕ·sin(hπσ/L),
    with uₖ the unit direction of segment k and σₖ the length up to corner k, L the length;
    the last sum (``shape``: rows aₕ = [shoulder, elbow] amplitudes, rad) bends the whole
    path, e.g. folding the elbow on the way (see ``_reshape``). Exactly the polyline outside
    the blends when unshaped; it always starts and ends at the first and last points.
    """

    def __init__(self, points, radii, start_direction=None, start_radius=0.0, shape=None):
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
        self.shape = np.zeros((0, 2)) if shape is None else np.asarray(shape, float).reshape(-1, 2)

    @property
    def speed_bound(self) -> float:
        """An upper bound of |q'(σ)|: 1 on the polyline, more with the start bend and shape."""
        harmonics = np.arange(1, len(self.shape) + 1) * math.pi / self.length
        return (1.0 + 1.2 * float(np.linalg.norm(self.bend))
                + float(np.sum(np.linalg.norm(self.shape, axis=1) * harmonics)))

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
        if len(self.shape):
            q += _shape_terms(s / self.length, self.shape, order) / self.length ** order
        return q[0] if np.ndim(path_positions) == 0 else q


def _shape_terms(fraction, shape, order):
    """Σₕ aₕ·dᵒ/dfᵒ sin(hπf) at path fractions f (n,) for amplitudes (..., H, 2): (..., n, 2)."""
    harmonics = np.arange(1, shape.shape[-2] + 1) * math.pi        # hπ
    phase = np.multiply.outer(fraction, harmonics)                  # (n, H)
    if order == 0:
        basis = np.sin(phase)
    elif order == 1:
        basis = harmonics * np.cos(phase)
    else:
        basis = -harmonics ** 2 * np.sin(phase)
    return basis @ shape


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
        self.terms, self.constants = terms, _model_constants(dynamics)
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
                budget, start_speed: float, guess=None):
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
    centre, half = _window(model.dq, budget)       # voltage rows scaled to |v| ≤ 1
    if guess is None:
        # Start from the speed at which back-EMF alone would use the whole budget.
        headroom = np.maximum(half - np.abs(model.c - centre), 0.05 * half)
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
        a = np.hstack([model.a / half, accel_rows[0]])
        b = np.hstack([b_lin / half, accel_rows[1]])
        c = np.hstack([(c_lin - centre) / half, accel_rows[2]])
        bound = np.concatenate([[1.0, 1.0], accel_bound])
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


def _time_from_rest(model: _PathModel, limits: TrajectoryLimits, budget):
    """x = ṡ² on the grid of the fastest rest-to-rest timing, back-EMF exact
    (``_fastest_speeds``), or None when the path cannot be followed."""
    speed = _fastest_speeds(model.terms, model.constants, model.q[None], model.dq[None],
                            model.ddq[None], np.diff(model.grid), limits, budget)[0]
    mean = speed[1:] + speed[:-1]
    if not np.all(np.isfinite(speed)) or np.any(mean <= 0.0):
        return None
    return speed ** 2


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
    speed = path.speed_bound
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


def _clustered(length: float, stages: int) -> np.ndarray:
    """σ = L·(1 − cos πτ)/2 on uniform τ: stages shrink toward both ends like √σ, as the
    path speed does near rest, so the discretisation costs far less time there (the same
    duration as about three times as many uniform stages)."""
    return 0.5 * length * (1.0 - np.cos(np.linspace(0.0, math.pi, stages + 1)))


def _grid_for(path: BlendedPath, fine: bool = False) -> np.ndarray:
    """Stages clustered toward both ends (``_clustered``), finer inside the blends (where q''
    changes fast); ``fine``: the finer grid."""
    length = path.length
    step, least, most = ((_FINE_GRID_STEP_RAD, _FINE_MIN_STAGES, _FINE_MAX_STAGES) if fine
                         else (_GRID_STEP_RAD, _MIN_STAGES, _MAX_STAGES))
    stages = int(min(most, max(least, math.ceil(length / step))))
    grid = [_clustered(length, stages)]
    step = length / stages
    bends = [(knot, r) for knot, r in zip(path.knots[1:-1], path.radii) if r > 0.0]
    if path.start_radius > 0.0:
        bends.append((0.0, path.start_radius))
    for centre, r in bends:
        spacing = min(step, r / 16)
        if spacing < step:
            grid.append(np.arange(max(centre - r, 0.0), min(centre + r, length), spacing))
    grid = np.unique(np.concatenate(grid))
    keep = np.concatenate([[True], np.diff(grid) > 1e-6 * max(length, 1.0)])
    grid = grid[keep]
    grid[-1] = length
    return grid


# --- reshaping the path: many shapes timed at once ---------------------------------------

def _first_positive_root(alpha, beta, gamma):
    """The least y > 0 with α·y² + β·y + γ = 0, for γ ≥ 0 (α·y² + β·y + γ ≥ 0 on [0, y]);
    inf when there is none, 0 when γ < 0. Written y = 2γ/(√(β² − 4αγ) − β): no cancellation,
    and it covers α = 0."""
    with np.errstate(divide='ignore', invalid='ignore'):
        denominator = np.sqrt(beta * beta - 4.0 * alpha * gamma) - beta
        root = np.where(denominator > 0.0, 2.0 * gamma / denominator, np.inf)
    return np.where(gamma < 0.0, 0.0, root)


def _fastest_speeds(terms, constants, q, dq, ddq, steps, limits, budget, start_speed=0.0):
    """The fastest path speeds ṡ (K, n) along K paths sampled on one grid (q, q', q'' of
    shape (K, n, 2); ``steps`` (n−1,) the grid's stages in σ), from ``start_speed`` to rest
    at the end; NaN rows where the start speed is out of reach.

    Rows v = A·u + B·x + C + D·y (y = ṡ, x = y², u = s̈): the two motor voltages (within
    ``_window`` of the (driving, braking) ``budget``, scaled to |v| ≤ 1) and the two joint
    accelerations (|v| ≤ their limits). The
    back-EMF term D·y is kept exactly (no linearisation): u is held over each stage and the
    rows are imposed at both its ends (as TOPP-RA's interpolation), so every bound is a
    quadratic in y.
    For rows j, m with s = sign(A), some u fits both iff
    W_j|A_m| + W_m|A_j| + s_j|A_m|·r_j − s_m|A_j|·r_m ≥ 0 (r = B·x + C + D·y): the top speed
    (maximum velocity curve) is the first root over all pairs, and the speed limits. Backward
    from rest, y_i is the largest y with y² − 2Δ·(W_j + s_j·r_j)/|A_j| ≤ y²ᵢ₊₁ for every row
    at both ends (braking as hard as the rows allow); forward from the start, accelerate as
    hard as they allow at both ends, under that curve.
    """
    shape = q.shape
    flat = (-1, 2)
    volts_per_nm, emf_per_rad_s, coulomb_v = constants
    mass_dq = terms.mass_times(q.reshape(flat), dq.reshape(flat)).reshape(shape)
    mass_ddq = terms.mass_times(q.reshape(flat), ddq.reshape(flat)).reshape(shape)
    coriolis = terms.coriolis(q.reshape(flat), dq.reshape(flat)).reshape(shape)
    gravity = terms.gravity(q.reshape(flat)).reshape(shape)
    centre, half = _window(dq, budget)
    A = np.concatenate([volts_per_nm * mass_dq / half, dq], axis=-1)
    B = np.concatenate([volts_per_nm * (mass_ddq + coriolis) / half, ddq], axis=-1)
    C = np.concatenate([(volts_per_nm * gravity + coulomb_v * np.sign(dq) - centre) / half,
                        np.zeros(shape)], axis=-1)
    D = np.concatenate([emf_per_rad_s * dq / half, np.zeros(shape)], axis=-1)
    W = np.concatenate([[1.0, 1.0], limits.max_acceleration_rad_s2])
    sign = np.where(A >= 0.0, 1.0, -1.0)
    size = np.abs(A)
    top = np.min(np.array(limits.max_velocity_rad_s) / np.maximum(np.abs(dq), 1e-12), axis=-1)
    for j in range(4):
        for m in range(4):
            if j != m:
                left, right = sign[..., j] * size[..., m], sign[..., m] * size[..., j]
                top = np.minimum(top, _first_positive_root(
                    left * B[..., j] - right * B[..., m], left * D[..., j] - right * D[..., m],
                    W[j] * size[..., m] + W[m] * size[..., j] + left * C[..., j]
                    - right * C[..., m]))
    count, stages = shape[0], shape[1]
    twice = 2.0 * np.asarray(steps, float)                        # 2Δ per stage
    # Stage-major copies (n, K, rows): each step below reads contiguous memory.
    A, B, C, D, sign, size = (np.ascontiguousarray(np.moveaxis(v, 1, 0))
                              for v in (A, B, C, D, sign, size))
    top = np.ascontiguousarray(top.T)
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        inverse = np.where(size > 1e-12, 1.0 / size, 0.0)
        unbounded = np.where(size > 1e-12, 0.0, np.inf)
        # Stage i's u at its start (x_i) and at its end (x_i+1 = x_i + 2Δu): y² − x_i = 2Δu.
        stage = twice[:, None, None]
        start_alpha = stage * sign[:-1] * B[:-1] - size[:-1]
        start_beta = stage * sign[:-1] * D[:-1]
        start_beta_squared = start_beta ** 2
        start_gamma = stage * (W + sign[:-1] * C[:-1])
        end_alpha = -(size[1:] + stage * sign[1:] * B[1:])
        end_beta = -stage * sign[1:] * D[1:]
        end_beta_squared = end_beta ** 2
        end_gamma = stage * (W - sign[1:] * C[1:])
        if count == 1:      # one path: plain floats are several times faster than numpy
            speed, ceiling = _passes_one_path(
                [v[:, 0].tolist() for v in (B, C, D, sign, size, inverse, unbounded)],
                [v[:, 0].tolist() for v in (start_alpha, start_beta, start_gamma, end_alpha,
                                            end_beta, end_gamma)],
                top[:, 0].tolist(), twice.tolist(), W.tolist(), float(start_speed))
            return np.where(start_speed > ceiling[0] * (1.0 + 1e-9) + 1e-12, np.nan,
                            np.array(speed))[None]
        ceiling = np.zeros((stages, count))
        for i in range(stages - 2, -1, -1):
            y = ceiling[i + 1]
            column = y[:, None]
            r = (B[i + 1] * column + D[i + 1]) * column + C[i + 1]
            brake = np.max(-(W + sign[i + 1] * r) * inverse[i + 1] - unbounded[i + 1], axis=1)
            gamma = start_gamma[i] + size[i] * (y * y)[:, None]
            denominator = np.sqrt(start_beta_squared[i] - 4.0 * start_alpha[i] * gamma) \
                - start_beta[i]
            root = np.min(np.where(denominator > 0.0, 2.0 * gamma / denominator, np.inf), axis=1)
            ceiling[i] = np.minimum(np.minimum(top[i], root),
                                    np.sqrt(np.maximum(y * y - twice[i] * brake, 0.0)))
        speed = np.zeros((stages, count))
        speed[0] = start_speed
        for i in range(stages - 1):
            y = speed[i]
            column = y[:, None]
            r = (B[i] * column + D[i]) * column + C[i]
            push = np.min((W - sign[i] * r) * inverse[i] + unbounded[i], axis=1)
            gamma = end_gamma[i] + size[i + 1] * (y * y)[:, None]
            denominator = np.sqrt(end_beta_squared[i] - 4.0 * end_alpha[i] * gamma) \
                - end_beta[i]
            at_end = np.min(np.where(denominator > 0.0, 2.0 * gamma / denominator, np.inf),
                            axis=1)
            speed[i + 1] = np.minimum(np.sqrt(np.clip(np.minimum(
                y * y + twice[i] * push, ceiling[i + 1] ** 2), 0.0, None)), at_end)
    speed, ceiling = speed.T.copy(), ceiling.T
    speed[start_speed > ceiling[:, 0] * (1.0 + 1e-9) + 1e-12] = np.nan
    return speed


def _passes_one_path(rows, stage_rows, top, twice, W, start_speed):
    """``_fastest_speeds``'s backward and forward passes for one path, on floats."""
    B, C, D, sign, size, inverse, unbounded = rows
    start_alpha, start_beta, start_gamma, end_alpha, end_beta, end_gamma = stage_rows
    stages = len(top)
    kinds = range(len(W))
    sqrt, inf = math.sqrt, math.inf

    def first_root(alpha, beta, gamma):
        discriminant = beta * beta - 4.0 * alpha * gamma
        if discriminant < 0.0:
            return inf
        denominator = sqrt(discriminant) - beta
        return 2.0 * gamma / denominator if denominator > 0.0 else inf

    ceiling = [0.0] * stages
    for i in range(stages - 2, -1, -1):
        y = ceiling[i + 1]
        x = y * y
        bound = top[i]
        brake = -inf
        after, here = i + 1, i
        for j in kinds:
            if not unbounded[after][j]:
                r = (B[after][j] * y + D[after][j]) * y + C[after][j]
                brake = max(brake, -(W[j] + sign[after][j] * r) * inverse[after][j])
            bound = min(bound, first_root(start_alpha[here][j], start_beta[here][j],
                                          start_gamma[here][j] + size[here][j] * x))
        ceiling[i] = min(bound, sqrt(max(x - twice[i] * brake, 0.0)))
    speed = [0.0] * stages
    speed[0] = start_speed
    for i in range(stages - 1):
        y = speed[i]
        x = y * y
        push = inf
        reach = ceiling[i + 1]
        for j in kinds:
            if not unbounded[i][j]:
                r = (B[i][j] * y + D[i][j]) * y + C[i][j]
                push = min(push, (W[j] - sign[i][j] * r) * inverse[i][j])
            reach = min(reach, first_root(end_alpha[i][j], end_beta[i][j],
                                          end_gamma[i][j] + size[i + 1][j] * x))
        speed[i + 1] = min(sqrt(max(min(x + twice[i] * push, ceiling[i + 1] ** 2), 0.0)),
                           reach)
    return speed, ceiling


def _durations(steps, speeds):
    """Σ 2Δ/(ṡ_i + ṡ_i+1) per row; inf where the speed stalls (or is NaN)."""
    mean = speeds[:, 1:] + speeds[:, :-1]
    stalls = ~np.all(mean > 0.0, axis=1)
    return np.where(stalls, np.inf, np.sum(2.0 * np.asarray(steps) / np.where(
        stalls[:, None], 1.0, mean), axis=1))


def _model_constants(dynamics: ArmDynamics):
    """Volts per N·m, back-EMF (plus viscous) volts per rad/s, Coulomb volts, per joint."""
    motors = dynamics.motors
    volts_per_nm = np.array([m.voltage_for(1.0, 0.0) for m in motors])
    back_emf = np.array([m.back_emf_v(1.0) for m in motors])
    joints = dynamics.arm.joints
    viscous = np.array([j.viscous_friction_nm_s_per_rad for j in joints])
    coulomb = volts_per_nm * np.array([j.coulomb_friction_nm for j in joints])
    return volts_per_nm, volts_per_nm * viscous + back_emf, coulomb


@functools.lru_cache(maxsize=8)
def _with_room(arm: ArmConfig) -> ForbiddenSpace:
    """Forbidden space with every region grown by ``_RESHAPE_ROOM_M`` more."""
    world = dataclasses.replace(arm.world, clearance_m=arm.world.clearance_m + _RESHAPE_ROOM_M)
    return ForbiddenSpace(dataclasses.replace(arm, world=world))


def _reshape(points, radii, dynamics: ArmDynamics, forbidden, limits: TrajectoryLimits):
    """Amplitudes (H, 2) of the bend Σₕ aₕ·sin(hπσ/L) that make the path fastest, or zeros.

    The planner's path is short, not fast: the fastest motion often folds the elbow on the
    way (less inertia and gravity torque at the shoulder) or lets one joint lead. A pattern
    search over the first ``_SHAPE_HARMONICS`` harmonics per joint: a grid of the first
    harmonic's amplitudes, then ``_SHAPE_STEPS`` refinements over every combination of
    ±step; each batch timed at once by ``_fastest_speeds``. A shape counts only when
    its samples are free and, where the planner's path has ``_RESHAPE_ROOM_M`` of room to
    spare around forbidden regions, keep that room (for tracking errors).
    """
    base = BlendedPath(points, radii)
    length = base.length
    grid = _clustered(length, _SEARCH_STAGES)
    fraction = grid / length
    q0, dq0, ddq0 = base(grid), base(grid, 1), base(grid, 2)
    terms = _ArmTerms(dynamics)
    constants = _model_constants(dynamics)
    steps = np.diff(grid)
    roomy = _with_room(forbidden.arm)
    base_roomy = np.asarray(roomy.is_free(q0), dtype=bool)

    def durations(shapes):
        q = q0 + _shape_terms(fraction, shapes, 0)
        dq = dq0 + _shape_terms(fraction, shapes, 1) / length
        ddq = ddq0 + _shape_terms(fraction, shapes, 2) / length ** 2
        # Free with room where the planner's path has room, free elsewhere (room ⇒ free).
        ok = np.asarray(roomy.is_free(q.reshape(-1, 2)), dtype=bool).reshape(q.shape[:2])
        tight = ~ok & ~base_roomy
        if np.any(tight):
            ok[tight] = np.asarray(forbidden.is_free(q[tight]), dtype=bool)
        ok = np.all(ok, axis=1)
        out = np.full(len(shapes), np.inf)
        if np.any(ok):
            out[ok] = _durations(steps, _fastest_speeds(
                terms, constants, q[ok], dq[ok], ddq[ok], steps, limits, limits.budget))
        return out

    if durations(np.zeros((1, _SHAPE_HARMONICS, 2)))[0] < _SHAPE_MIN_DURATION_S:
        return np.zeros((_SHAPE_HARMONICS, 2))        # a hop: the search would cost more
    levels = np.linspace(-_SHAPE_SPAN, _SHAPE_SPAN, _SHAPE_GRID) * length
    batch = np.zeros((_SHAPE_GRID ** 2, _SHAPE_HARMONICS, 2))
    batch[:, 0, 0], batch[:, 0, 1] = (axis.ravel() for axis in np.meshgrid(levels, levels))
    batch = np.concatenate([np.zeros((1, _SHAPE_HARMONICS, 2)), batch])   # unshaped first
    times = durations(batch)
    best, best_s = batch[int(np.argmin(times))], float(np.min(times))
    unshaped_s = float(times[0])
    every = np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=2 * _SHAPE_HARMONICS)))
    every = every.reshape(-1, _SHAPE_HARMONICS, 2)
    axes = every[np.sum(np.abs(every), axis=(1, 2)) <= 1.0]
    for index, step in enumerate(_SHAPE_STEPS):
        offsets = every if index < _SHAPE_FULL_STEPS else axes
        batch = best + offsets * step * length
        times = durations(batch)
        if np.min(times) < best_s:
            best, best_s = batch[int(np.argmin(times))], float(np.min(times))
    if not math.isfinite(best_s) or best_s >= unshaped_s * (1.0 - _SHAPE_MIN_GAIN):
        return np.zeros((_SHAPE_HARMONICS, 2))
    return best


# --- the public entry point -----------------------------------------------------------

def time_optimal_trajectory(waypoints_rad, dynamics: ArmDynamics, forbidden: ForbiddenSpace,
                            limits: TrajectoryLimits, start_velocity_rad_s=(0.0, 0.0),
                            check_step_rad: float = 0.001745,
                            reshape: bool = True) -> Trajectory:
    """The fastest trajectory along the planner's path within the arm's voltage and limits.

    ``waypoints_rad`` (n, 2): a piecewise-linear joint-space path whose first point is where
    the arm is. It leaves at ``start_velocity_rad_s`` (a preempted move keeps moving: the
    path first bends smoothly from that direction into the first segment, or when it cannot
    turn in time, brakes along its direction of motion and comes back) and ends at rest
    exactly on the last waypoint. From rest, with every corner blended, the whole path is
    bent where that is faster (``_reshape``; ``reshape=False``: never) and timed with the
    back-EMF exact (``_fastest_speeds``); a moving start is timed by TOPP-RA. Raises
    TrajectoryError when no such trajectory exists.
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
        plans = [lambda: _follow(points, None, dynamics, forbidden, limits, check_step_rad,
                                 reshape)]
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


def estimated_duration_s(waypoints_rad, dynamics: ArmDynamics, limits: TrajectoryLimits) -> float:
    """A quick estimate (a millisecond or two) of how long the path takes from rest to rest:
    the planner's polyline with its corners rounded (not checked) and not reshaped, timed on
    a coarse grid. For ranking paths, e.g. the goal's two elbow branches; inf when the
    waypoints are malformed or the arm cannot follow the path."""
    try:
        points = _clean_waypoints(waypoints_rad)
    except TrajectoryError:
        return math.inf
    if len(points) < 2:
        return 0.0
    path = BlendedPath(points, _initial_radii(points))
    grid = _clustered(path.length, 2 * _SEARCH_STAGES)
    steps = np.diff(grid)
    speeds = _fastest_speeds(_ArmTerms(dynamics), _model_constants(dynamics), path(grid)[None],
                             path(grid, 1)[None], path(grid, 2)[None], steps, limits,
                             limits.budget)
    return float(_durations(steps, speeds)[0])


class _StartUnreachable(Exception):
    """The start speed cannot be turned onto the path in time."""


def _timed_piece(points, radii, dynamics, limits, start_speed, start_direction=None,
                 start_radius=0.0, budget=None, shape=None):
    path = BlendedPath(points, radii, start_direction, start_radius, shape)
    grid = _grid_for(path, fine=start_speed == 0.0)
    model = _PathModel(path, dynamics, grid)
    if start_speed == 0.0:
        x = _time_from_rest(model, limits, budget or limits.budget)
        if x is None:
            raise TrajectoryError('the arm cannot follow the path within its voltage: it '
                                  'cannot hold still somewhere along it')
        return (path, model, x)
    x, reachable = _time_piece(path, model, limits, budget or limits.budget, start_speed)
    if x is None:
        raise _StartUnreachable(
            f'cannot take the path from a start speed of {start_speed:.3f} rad/s: '
            f'at most {math.sqrt(max(reachable, 0.0)):.3f} rad/s is controllable')
    return (path, model, x)


def _follow(points, velocity, dynamics, forbidden, limits, step_rad, reshape=False):
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
    if reshape and speed == 0.0 and ignore_until < 0.0 and np.all(radii > 0.0) \
            and hasattr(forbidden, 'arm'):
        # From rest along one piece: bend the whole path where that is faster.
        shape = _free_shape(points, radii, _reshape(points, radii, dynamics, forbidden,
                                                    limits), forbidden, step_rad)
        return [_timed_piece(points, radii, dynamics, limits, 0.0, shape=shape)]
    pieces = []
    for i, (piece_points, piece_radii) in enumerate(_split_at_stops(points, radii)):
        first_piece = i == 0
        pieces.append(_timed_piece(piece_points, piece_radii, dynamics, limits,
                                   speed if first_piece else 0.0,
                                   start_direction if first_piece else None,
                                   start_radius if first_piece else 0.0))
    return pieces


def _free_shape(points, radii, shape, forbidden, step_rad):
    """``shape``, or the largest of its halves, quarters, ... whose path is free at
    ``step_rad`` (the search saw only coarse samples); zeros when none is."""
    for scale in (1.0, 0.5, 0.25):
        if not np.any(shape):
            break
        path = BlendedPath(points, radii, shape=scale * shape)
        if len(_forbidden_at(path, forbidden, step_rad)) == 0:
            return scale * shape
    return None


def _reference_acceleration(q, velocity, dynamics, limits) -> float:
    """A rough joint acceleration the arm can surely make at q: sizes the start bend."""
    holding = np.abs(dynamics.voltage_for(q, velocity, (0.0, 0.0)))
    per_unit = np.abs(np.array(dynamics.voltage_for(q, velocity, (1.0, 1.0))) - holding)
    spare = np.maximum(min(limits.budget) - holding, 0.0)
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
    centre, half = _window(model.dq, limits.budget)      # voltage rows scaled to |v| ≤ 1
    x = speed ** 2
    for i, delta in enumerate(np.diff(grid)):
        volts = (model.b[i] * x + model.c[i] + model.d[i] * math.sqrt(x)
                 + model.coulomb(np.array([math.sqrt(x)]))[0])
        rows = [(model.a[i] / half[i], (volts - centre[i]) / half[i], 1.0),
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
    budget, solve_limits = limits.budget, limits
    trajectory = _assemble(pieces, start, end)
    for _ in range(3):
        peak, excess, speed_ratio, accel_ratio = _check(trajectory, dynamics, limits)
        if _passes(excess, speed_ratio, accel_ratio):
            trajectory.peak_voltage = peak
            return trajectory
        # Between grid points the exact model can ask a little more: tighten by the excess.
        budget = tuple(v - max(excess, 0.0) - _VOLTAGE_TOLERANCE for v in budget)
        solve_limits = TrajectoryLimits(
            tuple(np.array(solve_limits.max_velocity_rad_s) / max(speed_ratio, 1.0)),
            tuple(np.array(solve_limits.max_acceleration_rad_s2) / max(accel_ratio, 1.0)),
            *budget)
        retimed = []
        for path, model, x in pieces:
            if x[0] == 0.0:
                new_x = _time_from_rest(model, solve_limits, budget)
            else:
                new_x, _ = _time_piece(path, model, solve_limits, budget, math.sqrt(x[0]),
                                       guess=x)
            retimed.append((path, model, x if new_x is None else new_x))
        pieces = retimed
        trajectory = _assemble(pieces, start, end)
    # Last resort: slow the whole thing down until the exact check passes (from rest only:
    # stretching time would change a moving start's velocity).
    moving = pieces[0][2][0] > 0.0
    for factor in () if moving else (1.02, 1.05, 1.1, 1.2, 1.4, 1.7, 2.0, 3.0):
        slower = trajectory.scaled(factor)
        peak, excess, speed_ratio, accel_ratio = _check(slower, dynamics, limits)
        if _passes(excess, speed_ratio, accel_ratio):
            slower.peak_voltage = peak
            return slower
    raise TrajectoryError(
        f'no trajectory found within the limits: it needs {excess:.2f} V more than the '
        f'{limits.budget[0]:.2f} V (driving) / {limits.budget[1]:.2f} V (braking) it may use, '
        f'{speed_ratio:.2f} times the speed limit and {accel_ratio:.2f} times the '
        'acceleration limit')


def _passes(excess, speed_ratio, accel_ratio) -> bool:
    return (excess <= _VOLTAGE_TOLERANCE
            and speed_ratio <= _LIMIT_TOLERANCE and accel_ratio <= _LIMIT_TOLERANCE)


def _assemble(pieces, start, end) -> Trajectory:
    timed = [_Piece.from_profile(path, model.grid, x) for path, model, x in pieces]
    return Trajectory(timed, start, end)


def _check(trajectory, dynamics, limits):
    """On the check times, with the model: the peak |V|, how far the voltage goes past what
    it may use (driving: along the joint's motion; braking: against it; either way for a
    joint still within 1e-3 rad/s), and the largest ratios of speed and acceleration to
    their limits (a start already faster than the speed limit may slow down into it)."""
    times = trajectory.check_times()
    q, qd, qdd = trajectory.sample_many(times)
    volts = model_voltages(dynamics, q, qd, qdd)
    driving, braking = limits.budget
    direction = np.where(np.abs(qd) > 1e-3, np.sign(qd), 0.0)
    along = direction * volts
    allowed = np.where(direction == 0.0, max(driving, braking), np.where(
        along >= 0.0, driving, braking))
    excess = float(np.max(np.abs(volts) - allowed))
    speed_limit = np.maximum(np.array(limits.max_velocity_rad_s), np.abs(qd[0]))
    speed_ratio = float(np.max(np.abs(qd) / speed_limit))
    accel_ratio = float(np.max(np.abs(qdd) / np.array(limits.max_acceleration_rad_s2)))
    return float(np.max(np.abs(volts))), excess, speed_ratio, accel_ratio


def model_voltages(dynamics: ArmDynamics, q, qd, qdd) -> np.ndarray:
    """``dynamics.voltage_for`` for many states (n, 2) at once:
    V = k·(M(q)q̈ + C(q, q̇)q̇ + τg(q) + b·q̇ + c·tanh(q̇/ω_s)) + e·q̇."""
    return _voltages(_ArmTerms(dynamics), _model_constants(dynamics), q, qd, qdd)


def _voltages(terms, constants, q, qd, qdd) -> np.ndarray:
    q, qd, qdd = (np.asarray(v, float).reshape(-1, 2) for v in (q, qd, qdd))
    volts_per_nm, emf_per_rad_s, coulomb_v = constants
    torque = terms.mass_times(q, qdd) + terms.coriolis(q, qd) + terms.gravity(q)
    return (volts_per_nm * torque + emf_per_rad_s * qd
            + coulomb_v * np.tanh(qd / COULOMB_SMOOTHING_RAD_S))


# --- following a trajectory with a voltage held over each control period -----------------

def _accelerations(terms, constants, x, u):
    """q̈ (P, 2) of the model for states x (P, 4) = [θa, θb, ωa, ωb] and volts u (P, 2):
    M(q)q̈ = (V − e·q̇ − k·c·tanh(q̇/ω_s))/k − C(q, q̇)q̇ − τg(q), as ``ArmDynamics``."""
    volts_per_nm, emf_per_rad_s, coulomb_v = constants
    q, qd = x[:, :2], x[:, 2:]
    drive = ((u - emf_per_rad_s * qd - coulomb_v * np.tanh(qd / COULOMB_SMOOTHING_RAD_S))
             / volts_per_nm - terms.coriolis(q, qd) - terms.gravity(q))
    cos_b = np.cos(q[:, 1])
    m00, m01 = terms.alpha + 2 * terms.beta * cos_b, terms.gamma + terms.beta * cos_b
    det = m00 * terms.gamma - m01 * m01
    return np.column_stack([(terms.gamma * drive[:, 0] - m01 * drive[:, 1]) / det,
                            (m00 * drive[:, 1] - m01 * drive[:, 0]) / det])


def sure_acceleration_rad_s2(dynamics: ArmDynamics, forbidden, voltage: float,
                             samples: int = 61) -> np.ndarray:
    """Per joint, the acceleration (either way) that ``voltage`` surely gives from rest in
    every free pose on a ``samples``² grid of the joints' ranges: what braking and driver
    mode may count on when the trajectory limits are the motors' best (the least favourable
    pose, gravity working against it). Back-EMF only adds braking at speed."""
    ranges = [np.linspace(j.min_angle_rad, j.max_angle_rad, samples)
              for j in dynamics.arm.joints]
    q = np.stack(np.meshgrid(*ranges, indexing='ij'), axis=-1).reshape(-1, 2)
    q = q[np.asarray(forbidden.is_free(q), dtype=bool)]
    if len(q) == 0:
        return np.zeros(2)
    terms, constants = _ArmTerms(dynamics), _model_constants(dynamics)
    x = np.hstack([q, np.zeros_like(q)])
    reach = []
    for signs in itertools.product((-1.0, 1.0), repeat=2):
        reach.append(_accelerations(terms, constants, x, np.tile(np.array(signs) * voltage,
                                                                 (len(q), 1))))
    reach = np.stack(reach)                                   # (4, poses, 2)
    return np.minimum(np.min(reach.max(axis=0), axis=0), np.min(-reach.min(axis=0), axis=0))
