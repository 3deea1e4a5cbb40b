"""The bus a timed path leaves, and the timing under it.

The bus sags under the trajectory's own draw (``PowerSupply.bus_voltages``), and the volts
each joint may use sag with it. A path is timed with a sag per grid point, the bus computed
along the result, and the sag corrected (``BusSag``) until every grid point's voltage fits
its own bus less the reserves: on a coarse grid first (``bus_profile``), then on the fine
one. Whatever the sag, the rows keep the motors' currents where the bus cannot fall below
the brownout voltage (plus a margin) while the voltages stay within it
(``TrajectoryLimits.lowest_bus_v``), so a timing at that lowest bus always fits (``safe``).
"""

import math

import numpy as np

from arm_control.model.dynamics import COULOMB_SMOOTHING_RAD_S
from arm_control.timing.exact import compile_passes, kernel_array, OnePath
from arm_control.timing.kernels import kernel
from arm_control.timing.limits import TrajectoryLimits, window
from arm_control.timing.path import BUS_GRID, grid_for
from arm_control.timing.rows import (LEAST_HALF_WIDTH_V, PathTerms, rows, speed_caps)

BUS_ITERATIONS = 16
# The bus is found on a coarse grid first, then only raised where it falls short, in at
# most this many timings on the fine grid (twice, the second time from more sag).
FINE_BUS_ITERATIONS = 6
# Volts a grid point's voltage may pass its own bus by in the iteration (the final check on
# dense samples has the last word).
BUS_TOLERANCE_V = 0.02
# ... and by this much in the last timing, before the iteration gives up on it.
NEAR_MISS_V = 0.2
# How far a safe sag moves toward the one its timing would fit exactly (the volts follow the
# bus, but so does the timing: a full step would overshoot).
RELAX = 0.5
# A quick timing stops this many timings after the first that fits.
QUICK_AFTER_FIT = 2


def compile_kernels() -> None:
    """Compile the timing's kernels now (the exact passes and ``_judge``), or load them from
    numba's cache beside these modules: seconds in the first process after an install, a
    tenth of a second after that. A node does it before it serves, so that no goal waits
    for it."""
    compile_passes()
    two, pair = np.ones(2), np.ones((2, 2))
    _judge(two, two, two, np.ones(1), np.ones(12), *[pair] * 8)


class BusSag:
    """The sag per grid point that one path's timing assumes, corrected toward its own.

    Each timing is judged per grid point: its voltages, with the stage that leaves the
    point and with the one that arrives, must fit the bus they leave (``PowerSupply``'s:
    the upper root of V_bus² − V_nominal·V_bus + R_battery·P = 0; the lower of the two)
    less the reserves. Where they do not, the sag is raised to the one at which the joints
    at their voltage's edge would fit their own bus exactly, at the timing's speeds
    (a Newton-like step, since the volts follow the bus there); where the
    bus would fall below the floor (the volts went past it), halfway down to the lowest bus
    the rows allow. Where it fits with the voltage at its edge, the sag is relaxed by
    ``relax`` of the way toward that same bus, never below halfway to a sag found unsafe
    there before. The fastest timing that fits everywhere is kept.

    A sag only narrows the voltage windows (their centres stay), so what a timing leaves
    is worked out from the windows at no sag: a voltage passes the bus less the reserves
    by |V − centre| − half + sag.
    """

    def __init__(self, terms: PathTerms, limits: TrajectoryLimits, grid, sag_v=None,
                 relax=RELAX):
        self.limits = limits
        self.steps = kernel_array(np.diff(grid))
        self.sag = np.zeros(len(grid)) if sag_v is None else np.array(sag_v, float)
        self.unsafe = np.full(len(grid), np.nan)    # the most sag found unsafe, per point
        self.worst_excess_v = np.inf                # of the last timing judged
        self.best = None                   # (duration, x, sag) of the fastest that fits
        if self.stiff:
            return
        supply = limits.supply
        centre, half = window(terms.dq, *limits.budget)     # at no sag
        self._along = [kernel_array(v) for v in (
            terms.a, terms.b, terms.c, terms.d, terms.emf, terms.dq, centre, half)]
        conductance = [m.count / m.resistance_ohm for m in supply.motors]
        self._constants = np.array([
            *limits.reserves_v, *conductance, limits.nominal_voltage, supply.resistance_ohm,
            limits.bus_floor_v, limits.lowest_bus_v(), relax, *terms.coulomb_v,
            COULOMB_SMOOTHING_RAD_S], float)

    @property
    def stiff(self) -> bool:
        return self.limits.supply is None

    def settle(self, x) -> bool:
        """Judge the timing x made with ``sag``; True when it fits and the sag stays, else
        set it for the next timing."""
        if self.stiff:
            self.best = (None, x, self.sag)
            return True
        fits, relaxing, duration, self.worst_excess_v, sag, self.unsafe = _judge(
            kernel_array(x), self.sag, self.unsafe, self.steps, self._constants,
            *self._along)
        if fits and (self.best is None or duration < self.best[0]):
            self.best = (duration, x, self.sag.copy())
        self.sag = sag
        return fits and not relaxing


@kernel
def _judge(x, sag, unsafe, steps, constants, a, b, c, d, emf, dq, centre, half):
    """``BusSag.settle``'s verdict on the timing x made with ``sag``, per grid point i
    (compiled: a few dozen points, where numpy's calls cost more than the arithmetic):
    (every point fits, some sag relaxes, the duration, the worst excess, the next sag, the
    most sag found unsafe). ``constants``: the (driving, braking) reserves, each joint's
    conductance, the nominal bus, the battery's resistance, the bus floor, the lowest bus,
    the relaxation, each joint's Coulomb volts and its smoothing speed."""
    reserves, conductance = constants[0:2], constants[2:4]
    nominal, r_battery, floor, lowest, relax = constants[4:9]
    coulomb, smoothing = constants[9:11], constants[11]
    n = len(x)
    if n < 2:                                          # no stages: a point fits
        return True, False, 0.0, 0.0, sag.copy(), unsafe.copy()
    fits_all, relaxing, worst = True, False, 0.0
    new_sag, new_unsafe = sag.copy(), unsafe.copy()
    volts, drawn = np.empty((2, 2)), np.empty((2, 2))
    for i in range(n):
        speed = math.sqrt(max(x[i], 0.0))
        # s̈ held over the stage that leaves point i, and over the one that arrives.
        leaving = (x[min(i + 1, n - 1)] - x[min(i, n - 2)]) / (2.0 * steps[min(i, n - 2)])
        arriving = (x[max(i, 1)] - x[max(i - 1, 0)]) / (2.0 * steps[max(i - 1, 0)])
        bus, beyond = math.inf, -math.inf
        for s in range(2):
            u = leaving if s == 0 else arriving
            power = 0.0
            for j in range(2):
                v = (a[i, j] * u + b[i, j] * x[i] + c[i, j] + (d[i, j] + emf[i, j]) * speed
                     + coulomb[j] * math.tanh(dq[i, j] * speed / smoothing))
                volts[s, j] = v
                drawn[s, j] = conductance[j] * v * (v - emf[i, j] * speed)
                power += drawn[s, j]
                beyond = max(beyond, abs(v - centre[i, j]) - half[i, j])
            root = nominal * nominal - 4.0 * r_battery * power
            if not root >= 0.0:                 # a brownout: no bus
                bus = math.nan
            elif bus == bus:
                bus = min(bus, 0.5 * (nominal + math.sqrt(root)))
        browned = not bus >= floor
        excess = math.inf if browned else beyond + max(nominal - bus, 0.0)
        fits = excess <= BUS_TOLERANCE_V
        fits_all = fits_all and fits
        worst = max(worst, excess)
        # The bus at which the joints at their window's edge would sit exactly on it, at
        # these speeds: the upper root of V_bus² − V_nominal·V_bus + R_battery·P = 0 with
        # V_j = ±(V_bus − reserve_j) at the edge, P the motors' power (the lower of the stages).
        target = math.inf
        for s in range(2):
            qa, qb, qc = 1.0, -nominal, 0.0
            for j in range(2):
                v = volts[s, j]
                if abs(v - centre[i, j]) - half[i, j] + sag[i] >= -BUS_TOLERANCE_V:
                    reserve = reserves[0] if dq[i, j] * v >= 0.0 else reserves[1]
                    side_emf = np.sign(v) * emf[i, j] * speed
                    g = conductance[j]
                    qa += r_battery * g
                    qb += r_battery * g * (-2.0 * reserve - side_emf)
                    qc += r_battery * g * (reserve * reserve + side_emf * reserve)
                else:
                    qc += r_battery * drawn[s, j]
            root = qb * qb - 4.0 * qa * qc
            if not root >= 0.0:
                target = math.nan
            elif target == target:
                target = min(target, (-qb + math.sqrt(root)) / (2.0 * qa))
        falls = browned or not target >= floor
        # Where it would brown out, the volts there went past the bus: halfway down to the
        # lowest bus at once. Above its nominal voltage (regenerating) the bus gives nothing
        # more: the commands stop at the nominal voltage.
        needed = max(max(sag[i], 0.5 * (sag[i] + nominal - lowest)) if falls
                     else nominal - target, 0.0)
        if fits:
            binding = beyond + max(sag[i], 0.0) > -BUS_TOLERANCE_V
            # Never relax to a sag a timing was already found unsafe at: halfway to it.
            least = -math.inf if math.isnan(unsafe[i]) else 0.5 * (sag[i] + unsafe[i])
            relaxed = max(sag[i] - relax * (sag[i] - needed), least)
            if binding and relaxed < sag[i] - BUS_TOLERANCE_V:
                new_sag[i] = relaxed
                relaxing = True
        else:
            new_unsafe[i] = sag[i] if math.isnan(unsafe[i]) else max(unsafe[i], sag[i])
            new_sag[i] = max(sag[i], needed)
    duration = 0.0
    for i in range(n - 1):
        duration += 2.0 * steps[i] / max(math.sqrt(x[i + 1]) + math.sqrt(x[i]), 1e-12)
    return fits_all, relaxing, duration, worst, new_sag, new_unsafe


def under_the_bus(solve, terms: PathTerms, limits: TrajectoryLimits, grid, sag_v=None,
                  iterations=None, relax=RELAX, give_up=False, after_fit=None):
    """The fastest x = ṡ² from ``solve(sag_v)`` (None: no timing) that fits the bus it
    leaves (``BusSag``, starting from ``sag_v``), after at most ``iterations`` timings (and
    at most ``after_fit`` more once one fits), with the sag it was timed with. When none
    fits, the last timing if it misses by no more than ``NEAR_MISS_V`` (the final check
    tightens it), else None with ``give_up``, else the closest miss within ``NEAR_MISS_V``
    (the iteration need not converge: a later timing can miss by more than an earlier one),
    else the safe one (``safe``: the lowest bus, much slower); None when ``solve`` finds
    none."""
    follower = BusSag(terms, limits, grid, sag_v, relax)
    left = math.inf if after_fit is None else after_fit
    closest = (math.inf, None, None)        # (worst excess V, x, sag) of the closest miss
    for _ in range(1 if follower.stiff else iterations or BUS_ITERATIONS):
        sag = follower.sag
        x = solve(sag)
        if x is None or follower.settle(x) or left <= 0:
            break
        if follower.worst_excess_v < closest[0]:
            closest = (follower.worst_excess_v, x, sag)
        if follower.best is not None:
            left -= 1
    if follower.best is not None:
        _, x, sag = follower.best
        return x, sag
    if x is None or follower.worst_excess_v <= NEAR_MISS_V:
        return x, sag
    if give_up:
        return None, sag
    if closest[0] <= NEAR_MISS_V:
        return closest[1], closest[2]
    sag = safe(limits, len(grid))
    return solve(sag), sag


def safe(limits: TrajectoryLimits, count: int):
    """A sag at which any timing within the rows fits its bus: down to the lowest bus."""
    return np.full(count, limits.nominal_voltage - limits.lowest_bus_v())


def exact_timing(terms: PathTerms, grid, limits: TrajectoryLimits, margin_v: float = 0.0,
                 start_speed: float = 0.0):
    """solve(sag_v) -> x = ṡ² of the exact timing (``exact``) on this grid from
    ``start_speed`` to rest, or None when there is none; sag_v a scalar or one per point."""
    A, B, C, D, W = rows(terms, limits, 0.0, margin_v, per_point=True)
    path = OnePath(A, B, C, D, W, speed_caps(limits, terms.dq), np.diff(grid),
                   least=LEAST_HALF_WIDTH_V)
    count = len(grid)

    def solve(sag_v):
        speed = path.speeds(np.broadcast_to(np.asarray(sag_v, float), (count,)), start_speed)
        if not np.all(np.isfinite(speed)) or np.any(speed[1:] + speed[:-1] <= 0.0):
            return None
        return speed ** 2

    return solve


def along(grid, margin_v):
    """A margin as ``bus_profile`` takes it: volts, or (σ, volts) at the ``grid`` points."""
    return (np.asarray(grid), np.asarray(margin_v)) if np.ndim(margin_v) else margin_v


def bus_profile(path, dynamics, limits: TrajectoryLimits, margin_v=0.0, start_speed=0.0,
                hint=None):
    """(σ, sag) of the path's exact timing under its own bus, found on a coarse grid
    (``BUS_GRID``: few stages, the blends cut finely) from ``hint`` (a like path's (σ,
    sag)); zero sag when the start speed is out of its reach. ``margin_v``: volts, or
    (σ, volts) along the path."""
    return bus_timing(path, dynamics, limits, margin_v, start_speed, hint)[:2]


def bus_timing(path, dynamics, limits: TrajectoryLimits, margin_v=0.0, start_speed=0.0,
               hint=None):
    """``bus_profile``'s (σ, sag) and the timing x = ṡ² under it (None with the zero sag)."""
    sigma = grid_for(path, BUS_GRID)
    terms = PathTerms.along(dynamics, path, sigma)
    if isinstance(margin_v, tuple):
        margin_v = np.interp(sigma, *margin_v)
    start = None if hint is None else np.interp(sigma, *hint)
    x, sag = under_the_bus(exact_timing(terms, sigma, limits, margin_v, start_speed),
                           terms, limits, sigma, start)
    if x is None:
        return sigma, np.zeros(len(sigma)), None
    return sigma, sag, x
