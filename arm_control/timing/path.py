"""The geometric path: the planner's polyline with its corners rounded, bent by a shape, and
its free-space checks.

Corners are rounded by C³ blends, each checked free of forbidden space at the world's check
step, else tightened, else the arm stops at that corner. A moving start bends smoothly from
the arm's direction of motion into the first segment. A shape Σₕ aₕ·sin(hπσ/L) bends the
whole path (``shaping``). The timing grid clusters its stages toward both ends.
"""

import copy
import math

import numpy as np

from arm_control.model.world import ForbiddenSpace
from arm_control.timing.limits import TrajectoryError

# Corners that turn by more than this (a near reversal) always stop rather than blend.
MAX_BLEND_TURN_RAD = math.radians(175.0)
_MAX_BLEND_HALVINGS = 6
# Timing grids: about one stage per this much path length (rad), within [least, most] stages,
# and each blend of radius r cut in stages of r/(this last number); a moving start on the
# coarser one, the exact timing from rest on the finer.
COARSE_GRID = (0.01, 40, 240, 16)
FINE_GRID = (0.0075, 60, 260, 16)
# ... a quick timing (the arm starts on it while the fine one is found) on this one, and
# the bus a fine timing starts from on the last. With a long path's many blends (the FRC
# robot's) cut in r/4, or not cut at all, their accelerations went unseen between the
# grid's points: the quick timing then failed its check and came out up to 3.8x the fine
# one (scaled until it passed), and the bus found for the fine one sagged too far, up to
# 1.45x slower (the FRC robot's 34 moves of bench/planning_ros.py: 6 faster, none slower).
QUICK_GRID = (0.05, 32, 48, 8)
BUS_GRID = (math.inf, 32, 32, 8)


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


class BlendedPath:
    """A joint-space polyline with rounded corners, parameterised by polyline length σ.

    q(σ) = polyline(σ) + Σₖ (ρ_rₖ − max(0, ·))(σ − σₖ)·(uₖ − uₖ₋₁) + (v̂ − u₀)·h_r₀(σ)
           + Σₕ aₕ·sin(hπσ/L),
    with uₖ the unit direction of segment k and σₖ the length up to corner k, L the length;
    the last sum (``shape``: rows aₕ = [shoulder, elbow] amplitudes, rad) bends the whole
    path, e.g. folding the elbow on the way (``shaping``); with ``flat_start`` (a path the
    arm enters moving) each sine less hπσ/L·(1 − σ/L)^6, so that the bend leaves the initial
    direction alone. Exactly the polyline outside the blends when unshaped; it always starts
    and ends at the first and last points. TOPP-RA takes it as its path as it is
    (``__call__``, ``dof``, ``path_interval``).
    """

    def __init__(self, points, radii, start_direction=None, start_radius=0.0, shape=None,
                 flat_start=False):
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
        self.flat_start = bool(flat_start)

    def with_shape(self, shape) -> 'BlendedPath':
        """The same path bent by ``shape`` instead (amplitudes (H, 2), rad)."""
        bent = copy.copy(self)
        bent.shape = np.asarray(shape, float).reshape(-1, 2)
        return bent

    @property
    def speed_bound(self) -> float:
        """An upper bound of |q'(σ)|: 1 on the polyline, more with the start bend and shape."""
        harmonics = np.arange(1, len(self.shape) + 1) * math.pi / self.length
        flat = 2.0 if self.flat_start else 1.0        # the flattening term's slope ≤ hπ/L
        return (1.0 + 1.2 * float(np.linalg.norm(self.bend))
                + flat * float(np.sum(np.linalg.norm(self.shape, axis=1) * harmonics)))

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
                elif order == 1:                 # from knot k on, direction k is the base
                    correction -= (t[near] >= 0).astype(float)
                q[near] += correction[:, None] * kink
        if self.start_radius > 0.0:
            near = s < self.start_radius
            if np.any(near):
                q[near] += _start_bend(s[near], self.start_radius, order)[:, None] * self.bend
        if len(self.shape):
            q += shape_terms(s / self.length, self.shape, order,
                             self.flat_start) / self.length ** order
        return q[0] if np.ndim(path_positions) == 0 else q


# The power of (1 − f) in the flattening term of a moving start's shape.
_FLAT_POWER = 6


def shape_terms(fraction, shape, order, flat=False):
    """Σₕ aₕ·dᵒ/dfᵒ bₕ(f) at path fractions f (n,) for amplitudes (..., H, 2): (..., n, 2),
    bₕ(f) = sin(hπf), less hπ·f·(1 − f)^N with ``flat`` (then bₕ'(0) = 0: bₕ(0) = bₕ(1) = 0
    either way)."""
    harmonics = np.arange(1, shape.shape[-2] + 1) * math.pi        # hπ
    phase = np.multiply.outer(fraction, harmonics)                  # (n, H)
    if order == 0:
        basis = np.sin(phase)
    elif order == 1:
        basis = harmonics * np.cos(phase)
    else:
        basis = -harmonics ** 2 * np.sin(phase)
    if flat:
        f, n = np.asarray(fraction, float)[:, None], _FLAT_POWER
        rest = 1.0 - f
        if order == 0:
            ramp = f * rest ** n
        elif order == 1:
            ramp = rest ** n - n * f * rest ** (n - 1)
        else:
            ramp = -2 * n * rest ** (n - 1) + n * (n - 1) * f * rest ** (n - 2)
        basis = basis - harmonics * ramp
    return basis @ shape


def clean_waypoints(waypoints_rad) -> np.ndarray:
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


def unit(vector) -> np.ndarray:
    return vector / np.linalg.norm(vector)


def turn_angle(u_in, u_out) -> float:
    return math.acos(max(-1.0, min(1.0, float(np.dot(u_in, u_out)))))


def initial_radii(points) -> np.ndarray:
    """The largest blends whose regions do not overlap: r_k + r_k+1 ≤ the segment between."""
    lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)
    directions = np.diff(points, axis=0) / lengths[:, None]
    count = len(points) - 2
    radii = np.zeros(count)
    for k in range(1, len(points) - 1):
        if turn_angle(directions[k - 1], directions[k]) > MAX_BLEND_TURN_RAD:
            continue
        share_in = lengths[k - 1] if k == 1 else lengths[k - 1] / 2
        share_out = lengths[k] if k == len(points) - 2 else lengths[k] / 2
        radii[k - 1] = min(share_in, share_out)
    return radii


def forbidden_at(path: BlendedPath, forbidden: ForbiddenSpace, step_rad: float):
    """Path positions σ of the samples (about ``step_rad`` apart in q) that are forbidden."""
    speed = path.speed_bound
    s = np.linspace(0.0, path.length, max(2, int(math.ceil(path.length * speed / step_rad)) + 1))
    return s[~np.asarray(forbidden.is_free(path(s)), dtype=bool)]


def free_blends(points, radii, forbidden, step_rad, start_direction=None, start_radius=0.0,
                ignore_until=-1.0):
    """Halve each blend (and the start bend) with forbidden samples; 0 means stop there.

    Samples up to path position ``ignore_until`` are not checked (the planner's way out of
    forbidden space when the arm starts inside it). Returns (radii, start_radius). Raises
    TrajectoryError when the polyline itself is not free.
    """
    radii = radii.copy()
    for _ in range(_MAX_BLEND_HALVINGS + 1):
        path = BlendedPath(points, radii, start_direction, start_radius)
        bad = forbidden_at(path, forbidden, step_rad)
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
    bad = forbidden_at(polyline, forbidden, step_rad)
    bad = bad[bad > ignore_until]
    if len(bad):
        where = polyline(bad[0])
        raise TrajectoryError(
            f'the planned path itself enters forbidden space at '
            f'({math.degrees(where[0]):.1f}, {math.degrees(where[1]):.1f}) deg: '
            f'{forbidden.why_forbidden(where)}')
    return np.zeros_like(radii), 0.0


def split_at_stops(points, radii):
    """Pieces (points, radii) between corners with no blend (the arm stops there)."""
    pieces, first = [], 0
    for k, r in enumerate(radii, start=1):
        if r <= 0.0:
            pieces.append((points[first:k + 1], radii[first:k - 1]))
            first = k
    pieces.append((points[first:], radii[first:]))
    return pieces


def clustered(length: float, stages: int) -> np.ndarray:
    """σ = L·(1 − cos πτ)/2 on uniform τ: stages shrink toward both ends like √σ, as the
    path speed does near rest, so the discretisation costs far less time there (the same
    duration as about three times as many uniform stages)."""
    return 0.5 * length * (1.0 - np.cos(np.linspace(0.0, math.pi, stages + 1)))


def grid_for(path: BlendedPath, stages=COARSE_GRID) -> np.ndarray:
    """Stages clustered toward both ends (``clustered``), finer inside the blends (where q''
    changes fast); ``stages``: (step, least, most, per radius), e.g. ``FINE_GRID``."""
    length = path.length
    step, least, most, per_radius = stages
    stages = int(min(most, max(least, math.ceil(length / step))))
    grid = [clustered(length, stages)]
    step = length / stages
    bends = [(knot, r) for knot, r in zip(path.knots[1:-1], path.radii) if r > 0.0]
    if path.start_radius > 0.0:
        bends.append((0.0, path.start_radius))
    for centre, r in bends:
        spacing = min(step, r / per_radius)
        if spacing < step:
            grid.append(np.arange(max(centre - r, 0.0), min(centre + r, length), spacing))
    grid = np.unique(np.concatenate(grid))
    keep = np.concatenate([[True], np.diff(grid) > 1e-6 * max(length, 1.0)])
    grid = grid[keep]
    grid[-1] = length
    return grid


def free_length(start, direction, forbidden, step_rad, longest_rad=2.0) -> float:
    """How far the straight line from ``start`` along ``direction`` stays free."""
    s = np.arange(0.0, longest_rad + step_rad, step_rad)
    free = np.asarray(forbidden.is_free(start + s[:, None] * direction), dtype=bool)
    blocked = np.flatnonzero(~free)
    return float(longest_rad if len(blocked) == 0 else s[max(blocked[0] - 1, 0)])
