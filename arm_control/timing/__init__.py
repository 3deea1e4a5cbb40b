"""Time-optimal trajectories along the planner's joint-space path, under the robot's real
limits: the motors' volts within the bus, the motor controllers' current limits, the
battery's sag and brownout (DESIGN.md §4b), and any speed and acceleration caps.

The planner's polyline has its corners rounded (each blend checked free of forbidden space,
else tightened, else the arm stops at that corner: ``path``). From rest, the whole path is
first bent where that is faster (``shaping``), then timed exactly, back-EMF included
(``exact``); a moving start (a preempted move) is timed by TOPP-RA (``moving_start``). Both
impose the same rows (``rows``) through the one model of the arm, ``ArmDynamics``:

    V = k·(M(q)q̈ + C(q, q̇)q̇ + τg(q) + τ_friction(q̇)) + e·q̇,   k = R/(n·G·Kt), e = G/Kv,

each joint's V within the bus less the reserves and V − e·q̇ within I_limit·R less the
reserves, the bus sagging under the trajectory's own draw (``bus``). The result is checked
on dense samples with the exact model and the exact electrical model, and tightened until it
passes (``timing``). ``PeriodFeedforward`` (``arm_control.model.feedforward``) turns the
trajectory into the voltage a control loop holds over each period.
"""

import itertools
import math

import numpy as np

from arm_control.model.dynamics import ArmDynamics
from arm_control.model.electrical import PowerSupply
from arm_control.model.feedforward import PeriodFeedforward
from arm_control.model.world import ForbiddenSpace
from arm_control.timing.exact import durations, fastest_speeds
from arm_control.timing.limits import TrajectoryError, TrajectoryLimits
from arm_control.timing.moving_start import stopping_distance
from arm_control.timing.path import (BlendedPath, clean_waypoints, clustered, COARSE_GRID,
                                     FINE_GRID, free_blends, free_length, grid_for, initial_radii,
                                     QUICK_GRID, split_at_stops, turn_angle, unit)
from arm_control.timing.rows import PathTerms, rows, speed_caps
from arm_control.timing.shaping import (best_shape, faster_shape, free_shape, SEARCH_STAGES)
from arm_control.timing.timed import Trajectory
from arm_control.timing.timing import time_piece, TimedPiece, verified

__all__ = ['BlendedPath', 'estimated_bent_duration_s', 'estimated_duration_s',
           'PeriodFeedforward',
           'refined_trajectory', 'sure_acceleration_rad_s2', 'time_optimal_trajectory',
           'Trajectory', 'TrajectoryError', 'TrajectoryLimits']

# A moving start that must turn by more than this first tries braking, then bending.
_BRAKE_FIRST_TURN_RAD = math.radians(130.0)


class _StartUnreachable(Exception):
    """The start speed cannot be turned onto the path in time."""


def time_optimal_trajectory(waypoints_rad, dynamics: ArmDynamics, forbidden: ForbiddenSpace,
                            limits: TrajectoryLimits, start_velocity_rad_s=(0.0, 0.0),
                            check_step_rad: float = 0.001745,
                            reshape: bool = True, quick: bool = False) -> Trajectory:
    """The fastest trajectory along the planner's path within the arm's limits.

    ``waypoints_rad`` (n, 2): a piecewise-linear joint-space path whose first point is where
    the arm is. It leaves at ``start_velocity_rad_s`` (a preempted move keeps moving: the
    path first bends smoothly from that direction into the first segment, or when it cannot
    turn in time, brakes along its direction of motion and comes back) and ends at rest
    exactly on the last waypoint. From rest, with every corner blended, the whole path is
    bent where that is faster (``reshape=False``: never). ``quick``: not bent, and timed on
    a few dozen stages (a few milliseconds, a fraction of a percent slower): a trajectory to
    start on at once while the fine one is found (``refined_trajectory``). Raises
    TrajectoryError when no such trajectory exists.
    """
    points = clean_waypoints(waypoints_rad)
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
                                 reshape and not quick, quick)]
    else:                   # bend the motion onto the path; failing that, brake and return
        plans = [lambda: _follow(points, velocity, dynamics, forbidden, limits,
                                 check_step_rad),
                 lambda: _brake_then_follow(points, velocity, dynamics, forbidden, limits,
                                            check_step_rad)]
        if len(points) < 2:
            plans = plans[1:]
        elif turn_angle(velocity / speed, unit(points[1] - points[0])) > _BRAKE_FIRST_TURN_RAD:
            plans.reverse()         # nearly reversing: the bend almost never has the room
    failure = ''
    for plan in plans:
        try:
            pieces = plan()
        except _StartUnreachable as error:
            failure = str(error)
            continue
        return verified(pieces, start, end, dynamics, limits)
    raise TrajectoryError(failure)


def refined_trajectory(quick: Trajectory, handover_s: float, dynamics: ArmDynamics,
                       forbidden: ForbiddenSpace, limits: TrajectoryLimits,
                       check_step_rad: float = 0.001745):
    """The rest of ``quick``'s path from where it is at ``handover_s`` (moving), bent where
    that is faster and timed finely: (the trajectory from there, which the arm takes over at
    ``handover_s``), or None when it would not arrive sooner than ``quick`` (or there is
    none). The hand-over keeps the position and velocity; the bend keeps the direction."""
    located = quick.path_at(handover_s)
    if located is None:
        return None
    path, s = located
    q, velocity, _ = quick.sample(handover_s)
    ahead = path.knots[1:-1] > s + 1e-9
    points = np.vstack([q, path.points[1:-1][ahead], path.points[-1]])
    if np.linalg.norm(points[-1] - q) < 1e-6:
        return None
    try:
        pieces = _follow(clean_waypoints(points), np.asarray(velocity, float), dynamics,
                         forbidden, limits, check_step_rad, reshape=True)
        refined = verified(pieces, q, quick.end_rad, dynamics, limits)
    except (TrajectoryError, _StartUnreachable):
        return None
    if handover_s + refined.duration_s >= quick.duration_s:
        return None
    return refined


def estimated_duration_s(waypoints_rad, dynamics: ArmDynamics, limits: TrajectoryLimits) -> float:
    """A quick estimate (a millisecond or two) of how long the path takes from rest to rest:
    the planner's polyline with its corners rounded (not checked) and not reshaped, timed on
    a coarse grid at the nominal bus. For ranking paths, e.g. the goal's two elbow branches;
    inf when the waypoints are malformed or the arm cannot follow the path."""
    try:
        points = clean_waypoints(waypoints_rad)
    except TrajectoryError:
        return math.inf
    if len(points) < 2:
        return 0.0
    path = BlendedPath(points, initial_radii(points))
    grid = clustered(path.length, 2 * SEARCH_STAGES)
    steps = np.diff(grid)
    terms = PathTerms(dynamics, path(grid)[None], path(grid, 1)[None], path(grid, 2)[None])
    A, B, C, D, W = rows(terms, limits)
    speeds = fastest_speeds(A, B, C, D, W, speed_caps(limits, terms.dq), steps)
    return float(durations(steps, speeds)[0])


def estimated_bent_duration_s(waypoints_rad, dynamics: ArmDynamics, forbidden: ForbiddenSpace,
                              limits: TrajectoryLimits) -> float:
    """A closer estimate (a few milliseconds) of the path's duration from rest to rest: its
    corners rounded (not checked), the first grid of bends tried, timed on a coarse grid
    under the unbent path's bus. For ranking paths whose quick estimates come close; inf when
    the arm cannot follow the path."""
    try:
        points = clean_waypoints(waypoints_rad)
    except TrajectoryError:
        return math.inf
    if len(points) < 2:
        return 0.0
    return best_shape(BlendedPath(points, initial_radii(points)), dynamics, forbidden, limits,
                      steps=())[2]


def sure_acceleration_rad_s2(dynamics: ArmDynamics, forbidden, voltage: float,
                             samples: int = 61) -> np.ndarray:
    """Per joint, the acceleration (either way) that ``voltage`` surely gives from rest in
    every free pose on a ``samples``² grid of the joints' ranges: what braking and driver
    mode may count on when the trajectory limits are the motors' best (the least favourable
    pose, gravity working against it). At rest the volts are also held within each motor's
    current limit and the lowest bus those limits allow, less the reserve ``voltage`` keeps
    from the nominal bus. Back-EMF only adds braking at speed."""
    arm = dynamics.arm
    supply = PowerSupply(arm, dynamics.motors)
    reserve = arm.battery.nominal_voltage - voltage
    lowest_bus = supply.min_bus_voltage()
    volts = np.minimum(voltage, np.array(supply.current_window_v) - reserve)
    if math.isfinite(lowest_bus):
        volts = np.minimum(volts, lowest_bus - reserve)
    ranges = [np.linspace(j.min_angle_rad, j.max_angle_rad, samples) for j in arm.joints]
    q = np.stack(np.meshgrid(*ranges, indexing='ij'), axis=-1).reshape(-1, 2)
    q = q[np.asarray(forbidden.is_free(q), dtype=bool)]
    if len(q) == 0:
        return np.zeros(2)
    x = np.hstack([q, np.zeros_like(q)])
    reach = np.stack([dynamics.accelerations(x, np.array(signs) * volts)
                      for signs in itertools.product((-1.0, 1.0), repeat=2)])   # (4, poses, 2)
    return np.minimum(np.min(reach.max(axis=0), axis=0), np.min(-reach.min(axis=0), axis=0))


def _timed_piece(points, radii, dynamics, limits, start_speed, start_direction=None,
                 start_radius=0.0, shape=None, bus_hint=None, quick=False) -> TimedPiece:
    path = BlendedPath(points, radii, start_direction, start_radius, shape,
                       flat_start=start_speed > 0.0)
    if quick:
        grid = grid_for(path, QUICK_GRID)
    else:
        grid = grid_for(path, FINE_GRID if start_speed == 0.0 or shape is not None
                        else COARSE_GRID)
    terms = PathTerms.along(dynamics, path, grid)
    x, reachable, bus = time_piece(path, grid, terms, limits, start_speed, bus_hint=bus_hint,
                                   coarse=quick)
    if x is None and start_speed == 0.0:
        raise TrajectoryError('the arm cannot follow the path within its limits: it cannot '
                              'hold still somewhere along it')
    if x is None:
        raise _StartUnreachable(
            f'cannot take the path from a start speed of {start_speed:.3f} rad/s: '
            f'at most {math.sqrt(max(reachable, 0.0)):.3f} rad/s is controllable')
    return TimedPiece(path, grid, terms, x, bus, quick)


def _reference_acceleration(q, velocity, dynamics, limits) -> float:
    """A rough joint acceleration the arm can surely make at q: sizes the start bend."""
    holding = np.array(dynamics.voltage_for(q, velocity, (0.0, 0.0)))
    per_unit = np.abs(np.array(dynamics.voltage_for(q, velocity, (1.0, 1.0))) - holding)
    torque = np.abs(holding - np.array(dynamics.emf_v_per_rad_s) * velocity)
    spare = np.minimum(min(limits.budget) - np.abs(holding),
                       np.min(limits.current_budget_v, axis=1) - torque)
    reach = float(np.min(np.maximum(spare, 0.0) / np.maximum(per_unit, 1e-9)))
    return min(max(0.5 * reach, 0.5), min(limits.max_acceleration_rad_s2))


def _brake_then_follow(points, velocity, dynamics, forbidden, limits, step_rad):
    """Keep going along the current motion until stopped, come back, then follow the path."""
    speed = float(np.linalg.norm(velocity))
    direction = velocity / speed
    start = points[0]
    room = free_length(start, direction, forbidden, step_rad)
    distance = stopping_distance(start, direction, speed, dynamics, limits, room)
    if distance is None:
        raise _StartUnreachable(
            f'moving at {speed:.2f} rad/s, the arm cannot stop before forbidden space '
            f'({room:.3f} rad ahead)')
    # A little room beyond the exact stop: the timing's linearisation is conservative.
    for stretch in (1.1, 1.3, 1.7):
        length = min(room, max(distance * stretch, 4 * step_rad))
        stop = start + length * direction
        try:
            brake = _timed_piece(np.array([start, stop]), np.zeros(0), dynamics, limits, speed)
        except _StartUnreachable:
            continue
        back = clean_waypoints(np.vstack([stop, points]) if len(points) >= 2
                               else np.array([stop, start]))
        return [brake] + _follow(back, None, dynamics, forbidden, limits, step_rad)
    raise _StartUnreachable(f'moving at {speed:.2f} rad/s, the arm cannot brake in time')


def _follow(points, velocity, dynamics, forbidden, limits, step_rad, reshape=False,
            quick=False):
    """Blend the corners (and the start bend when moving), then time each piece (``quick``:
    on few stages)."""
    radii = initial_radii(points)
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
    radii, start_radius = free_blends(points, radii, forbidden, step_rad, start_direction,
                                      start_radius, ignore_until)
    if speed > 0.0 and start_direction is not None and start_radius == 0.0:
        raise _StartUnreachable('no free room to bend the current motion onto the path')
    if reshape and ignore_until < 0.0 and np.all(radii > 0.0) and hasattr(forbidden, 'arm'):
        # Along one piece: bend the whole path where that is faster (leaving a moving
        # start's direction alone).
        base = BlendedPath(points, radii, start_direction, start_radius, flat_start=speed > 0)
        shape, bus, _ = best_shape(base, dynamics, forbidden, limits, speed)
        shape, checked_bus = faster_shape(base, free_shape(base, shape, forbidden, step_rad),
                                          dynamics, limits, speed)
        return [_timed_piece(points, radii, dynamics, limits, speed, start_direction,
                             start_radius, shape=shape, bus_hint=checked_bus or bus)]
    pieces = []
    for i, (piece_points, piece_radii) in enumerate(split_at_stops(points, radii)):
        first_piece = i == 0
        pieces.append(_timed_piece(piece_points, piece_radii, dynamics, limits,
                                   speed if first_piece else 0.0,
                                   start_direction if first_piece else None,
                                   start_radius if first_piece else 0.0, quick=quick))
    return pieces
