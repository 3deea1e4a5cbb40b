"""Timing one piece of path, and the final check of a whole trajectory with the exact model.

A piece is timed exactly (``exact.fastest_speeds``) from rest or from its start speed, a
moving start the exact passes cannot take (its start speed past their first stage's reach)
by TOPP-RA (``moving_start``), both under the bus their own draw leaves (``bus``). The
trajectory is then checked on dense samples with the exact model: ``ArmDynamics.voltages``
for the volts, ``PowerSupply.bus_voltages`` for the bus they leave (what
``PowerSupply.solve`` gives when it lowers nothing, which is what passing the check means),
every voltage within its bus less the reserves, every current within its limit less the
reserves, the bus above the brownout voltage, the speed and acceleration caps kept. If the
check fails, every window is narrowed by the excess and the pieces timed again; as a last
resort time is stretched until it passes.
"""

import dataclasses
import math

import numpy as np

from arm_control.model.dynamics import ArmDynamics
from arm_control.timing.bus import (along, bus_profile, exact_timing, FINE_BUS_ITERATIONS,
                                    QUICK_AFTER_FIT, under_the_bus)
from arm_control.timing.limits import TrajectoryError, TrajectoryLimits
from arm_control.timing.moving_start import time_moving
from arm_control.timing.rows import PathTerms
from arm_control.timing.timed import Piece, Trajectory

VOLTAGE_TOLERANCE = 0.05           # V past a window the final check accepts (grid error)
TIGHTENINGS = 5                    # retimings after a failed check before time is stretched
LOCAL_SLOWDOWN = 1.02              # a retiming held back locally may cost this much more
LIMIT_TOLERANCE = 1.02             # ratio of the speed/acceleration caps it accepts


@dataclasses.dataclass
class TimedPiece:
    """A piece of path, its grid and the arm's terms along it, and its profile x = ṡ²;
    ``coarse``: its bus is found on its own grid, with no finer pass (a quick timing)."""

    path: object
    grid: np.ndarray
    terms: PathTerms
    x: np.ndarray
    bus: tuple = None           # the (σ, sag) the timing assumed
    coarse: bool = False

    @property
    def start_speed(self) -> float:
        return math.sqrt(max(float(self.x[0]), 0.0))


def time_from_rest(path, grid, terms: PathTerms, limits: TrajectoryLimits,
                   margin_v: float = 0.0, bus_hint=None, start_speed: float = 0.0,
                   coarse: bool = False):
    """(x = ṡ² of the fastest timing from ``start_speed`` to rest under the bus it leaves,
    back-EMF exact, or None when the path cannot be followed from there; the (σ, sag) it
    assumed).

    The bus is found on a coarse grid first (``bus.bus_profile``, from ``bus_hint``, the
    (σ, sag) of a like path), then only raised where it falls short on the fine one;
    ``coarse``: found on ``grid`` itself, from the hint (a quick timing on few stages)."""
    solve = exact_timing(terms, grid, limits, margin_v, start_speed)
    if limits.supply is None:
        return solve(0.0), None
    if coarse:
        start = None if bus_hint is None else np.interp(grid, *bus_hint)
        x, sag = under_the_bus(solve, terms, limits, grid, start, after_fit=QUICK_AFTER_FIT)
        return x, (grid, sag)
    sigma, sag = bus_profile(path, terms.dynamics, limits, along(grid, margin_v), start_speed,
                             bus_hint)
    start = np.interp(grid, sigma, sag)
    if bus_hint is not None and np.array_equal(bus_hint[0], grid):
        # This piece's own bus from its last timing (tightened since): from the coarse one
        # alone the fine timing can miss it and fall back to the much slower safe bus.
        start = np.maximum(start, bus_hint[1])
    x, fine = under_the_bus(solve, terms, limits, grid, start, FINE_BUS_ITERATIONS, relax=0.0,
                            give_up=True)
    if x is None:
        # The fine timing ran ahead of the coarse one's bus: start again from the most sag
        # of each coarse point and its neighbours.
        envelope = np.maximum(sag, np.maximum(np.append(sag[1:], sag[-1]),
                                              np.insert(sag[:-1], 0, sag[0])))
        x, fine = under_the_bus(solve, terms, limits, grid, np.interp(grid, sigma, envelope),
                                FINE_BUS_ITERATIONS, relax=0.0)
    return x, (grid, fine)


def time_piece(path, grid, terms, limits, start_speed, margin_v=0.0, guess=None,
               bus_hint=None, coarse=False):
    """(x, controllable start x, bus (σ, sag)): exactly, and for a moving start the exact
    timing failing, by TOPP-RA; x None when there is none."""
    x, bus = time_from_rest(path, grid, terms, limits, margin_v, bus_hint, start_speed, coarse)
    if x is not None or start_speed == 0.0:
        return x, start_speed ** 2, bus
    x, reachable = time_moving(path, grid, terms, limits, start_speed, margin_v, guess,
                               bus_hint)
    return x, reachable, None


@dataclasses.dataclass
class Verdict:
    """What the final check found: the peak |V|, how far past its windows the trajectory
    goes (V: voltage, current, or the bus short of the brownout), and the largest ratios of
    speed and acceleration to their caps."""

    peak_voltage: float
    excess_v: float
    speed_ratio: float
    accel_ratio: float
    times: np.ndarray = None        # the check times, and the excess (V) at each
    excess_at: np.ndarray = None

    @property
    def passes(self) -> bool:
        return (self.excess_v <= VOLTAGE_TOLERANCE and self.speed_ratio <= LIMIT_TOLERANCE
                and self.accel_ratio <= LIMIT_TOLERANCE)


def _past(values, direction, driving, braking):
    """How far |values| goes past the window: driving along the joint's motion, braking
    against it, the larger of the two for a joint still within 1e-3 rad/s."""
    along = direction * values
    allowed = np.where(direction == 0.0, np.maximum(driving, braking),
                       np.where(along >= 0.0, driving, braking))
    return np.abs(values) - allowed


def check(trajectory: Trajectory, dynamics: ArmDynamics, limits: TrajectoryLimits) -> Verdict:
    """The trajectory on its check times against every limit, with the exact model (a start
    already faster than a speed cap may slow down into it)."""
    times = trajectory.check_times()
    q, qd, qdd = trajectory.sample_many(times)
    volts = dynamics.voltages(q, qd, qdd)
    direction = np.where(np.abs(qd) > 1e-3, np.sign(qd), 0.0)
    driving, braking = limits.budget
    excess = np.full(len(times), -math.inf)
    if limits.supply is not None:
        bus = limits.supply.bus_voltages(volts, qd)      # NaN: a brownout
        excess = np.nan_to_num(limits.supply.brownout_voltage + VOLTAGE_TOLERANCE - bus,
                               nan=np.inf)
        sag = np.maximum(limits.nominal_voltage - np.nan_to_num(bus, nan=0.0), 0.0)[:, None]
        torque = volts - np.array(dynamics.emf_v_per_rad_s) * qd
        current = limits.current_budget_v
        excess = np.maximum(excess, np.max(_past(torque, direction, current[:, 0],
                                                 current[:, 1]), axis=1))
    else:
        sag = 0.0
    excess = np.maximum(excess, np.max(_past(volts, direction, driving - sag, braking - sag),
                                       axis=1))
    with np.errstate(divide='ignore', invalid='ignore'):
        speed_cap = np.maximum(np.array(limits.max_velocity_rad_s), np.abs(qd[0]))
        speed_ratio = float(np.max(np.nan_to_num(np.abs(qd) / speed_cap)))
        accel_ratio = float(np.max(np.nan_to_num(
            np.abs(qdd) / np.array(limits.max_acceleration_rad_s2))))
    return Verdict(float(np.max(np.abs(volts))), float(np.max(excess)), speed_ratio,
                   accel_ratio, times, excess)


def _retimed(pieces, margins, limits: TrajectoryLimits) -> list:
    """Each piece timed again, ``margins`` (V per grid point) held back from its windows."""
    out = []
    for piece, margin in zip(pieces, margins):
        x, _, bus = time_piece(piece.path, piece.grid, piece.terms, limits, piece.start_speed,
                               margin, piece.x, piece.bus, piece.coarse)
        out.append(piece if x is None else dataclasses.replace(piece, x=x, bus=bus))
    return out


def _around(grid_times, times, excess):
    """Per grid point, the largest ``excess`` at ``times`` on the stages either side of it."""
    before = np.searchsorted(times, np.append(grid_times[0], grid_times[:-1]), 'left')
    after = np.searchsorted(times, np.append(grid_times[1:], grid_times[-1]), 'right')
    return np.array([np.max(excess[a:b], initial=0.0) for a, b in zip(before, after)])


def assemble(pieces, start, end) -> Trajectory:
    timed = [Piece.from_profile(p.path, p.grid, p.x) for p in pieces]
    return Trajectory(timed, start, end)


def verified(pieces, start, end, dynamics: ArmDynamics,
             limits: TrajectoryLimits) -> Trajectory:
    """Build the trajectory, check it with the exact model, and tighten until it passes."""
    solve_limits = limits
    margins = [np.zeros(len(piece.grid)) for piece in pieces]
    trajectory = assemble(pieces, start, end)
    for attempt in range(TIGHTENINGS):
        verdict = check(trajectory, dynamics, limits)
        if verdict.passes:
            trajectory.peak_voltage = verdict.peak_voltage
            return trajectory
        solve_limits = dataclasses.replace(
            solve_limits,
            max_velocity_rad_s=tuple(np.array(solve_limits.max_velocity_rad_s)
                                     / max(verdict.speed_ratio, 1.0)),
            max_acceleration_rad_s2=tuple(np.array(solve_limits.max_acceleration_rad_s2)
                                          / max(verdict.accel_ratio, 1.0)))
        # Between grid points the exact model can ask a little more: tighten by the excess
        # (a few volts at most: a bus that would brown out has none to measure it by),
        # around the grid points where it went past, since a whole path held back for one
        # spot is slower everywhere else. Everywhere when that costs more
        # (the bus it leaves can then take the fine timing longer to find), and the last time.
        excess = np.clip(verdict.excess_at, 0.0, 2.0)
        everywhere = [m + float(np.max(excess)) + VOLTAGE_TOLERANCE for m in margins]
        options = [everywhere]
        if attempt < TIGHTENINGS - 1:
            near = [_around(times, verdict.times, excess) for times in trajectory.grid_times()]
            options.insert(0, [m + np.where(e > 0.0, e + VOLTAGE_TOLERANCE, 0.0)
                               for m, e in zip(margins, near)])
        best = None
        for option in options:
            retimed = _retimed(pieces, option, solve_limits)
            candidate = assemble(retimed, start, end)
            if best is None or candidate.duration_s < best[0].duration_s:
                best = candidate, retimed, option
            if candidate.duration_s <= LOCAL_SLOWDOWN * trajectory.duration_s:
                break
        trajectory, pieces, margins = best
    # The last retiming, then as a last resort the whole thing slowed down until the exact
    # check passes (from rest only: stretching time would change a moving start's velocity).
    moving = pieces[0].start_speed > 0.0
    for factor in (1.0,) if moving else (1.0, 1.02, 1.05, 1.1, 1.2, 1.4, 1.7, 2.0, 3.0):
        slower = trajectory.scaled(factor)
        verdict = check(slower, dynamics, limits)
        if verdict.passes:
            slower.peak_voltage = verdict.peak_voltage
            return slower
    raise TrajectoryError(
        f'no trajectory found within the limits: it needs {verdict.excess_v:.2f} V more than '
        f'the {limits.budget[0]:.2f} V (driving) / {limits.budget[1]:.2f} V (braking) at the '
        f'nominal bus and the current limits allow, {verdict.speed_ratio:.2f} times the speed '
        f'cap and {verdict.accel_ratio:.2f} times the acceleration cap')
