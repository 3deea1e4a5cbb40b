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

from arm_control.control.trajectory.exact import OnePath
from arm_control.control.trajectory.limits import TrajectoryLimits, window
from arm_control.control.trajectory.path import clustered
from arm_control.control.trajectory.rows import (LEAST_HALF_WIDTH_V, PathTerms, rows,
                                                 speed_caps)

BUS_ITERATIONS = 16
# The bus is found on this many stages first, then only raised where it falls short, in at
# most this many timings on the fine grid (twice, the second time from more sag).
COARSE_STAGES = 32
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


class BusSag:
    """The sag per grid point that one path's timing assumes, corrected toward its own.

    Each timing is judged per grid point: its voltages, with the stage that leaves the
    point and with the one that arrives, must fit the bus they leave (``PowerSupply``'s:
    the upper root of V_bus² − V_nominal·V_bus + R_battery·P = 0; the lower of the two)
    less the reserves. Where they do not, the sag is raised to the one at which the joints
    at their voltage's edge would fit their own bus exactly, at the timing's speeds
    (``_edge_bus``: a Newton-like step, since the volts follow the bus there); where the
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
        self.terms, self.limits, self.relax = terms, limits, relax
        self.steps = np.diff(grid)
        self.sag = np.zeros(len(grid)) if sag_v is None else np.array(sag_v, float)
        self.unsafe = np.full(len(grid), np.nan)    # the most sag found unsafe, per point
        self.worst_excess_v = np.inf                # of the last timing judged
        self.best = None                   # (duration, x, sag) of the fastest that fits
        if self.stiff:
            return
        supply = limits.supply
        self._centre, self._half = window(terms.dq, *limits.budget)     # at no sag
        self._direction = np.sign(terms.dq)
        self._reserves = limits.reserves_v
        self._conductance = np.array([m.count / m.resistance_ohm for m in supply.motors])
        self._nominal, self._r_battery = limits.nominal_voltage, supply.resistance_ohm
        self._floor, self._lowest = limits.bus_floor_v, limits.lowest_bus_v()
        self._friction = bool(np.any(terms.coulomb_v != 0.0))

    @property
    def stiff(self) -> bool:
        return self.limits.supply is None

    def _volts(self, x):
        """The voltages (2, n, 2) at each grid point under x = ṡ² with s̈ held over each
        stage (with the stage that leaves it, and with the one that arrives:
        ``PathTerms.voltage``), and the back-EMF (n, 2)."""
        terms = self.terms
        speed = np.sqrt(np.maximum(x, 0.0))
        u = np.diff(x) / (2.0 * self.steps)
        held = terms.b * x[:, None] + terms.c + (terms.d + terms.emf) * speed[:, None]
        if self._friction:
            held = held + terms.coulomb(speed)
        leaving = np.concatenate([u, u[-1:]])[:, None]
        arriving = np.concatenate([u[:1], u])[:, None]
        volts = np.stack([terms.a * leaving + held, terms.a * arriving + held])
        return volts, terms.emf * speed[:, None]

    def settle(self, x) -> bool:
        """Judge the timing x made with ``sag``; True when it fits and the sag stays, else
        set it for the next timing."""
        if self.stiff:
            self.best = (None, x, self.sag)
            return True
        nominal, sag = self._nominal, self.sag
        volts, emf = self._volts(x)
        drawn = self._conductance * volts * (volts - emf)          # P of each joint's motors
        with np.errstate(invalid='ignore'):
            stage_bus = 0.5 * (nominal + np.sqrt(nominal * nominal - 4.0 * self._r_battery
                                                 * np.sum(drawn, axis=-1)))
        bus = np.where(np.any(np.isnan(stage_bus), axis=0), np.nan, np.min(stage_bus, axis=0))
        past = np.abs(volts - self._centre) - self._half            # past the window, no sag
        beyond = np.max(past, axis=(0, 2))
        browned = ~(bus >= self._floor)                          # NaN too
        excess = np.where(browned, np.inf,
                          beyond + np.maximum(nominal - np.nan_to_num(bus), 0.0))
        fits = excess <= BUS_TOLERANCE_V
        self.worst_excess_v = float(np.max(excess, initial=0.0))    # no stages: a point
        if np.all(fits):
            duration = float(np.sum(2.0 * self.steps / np.maximum(
                np.sqrt(x[1:]) + np.sqrt(x[:-1]), 1e-12)))
            if self.best is None or duration < self.best[0]:
                self.best = (duration, x, sag.copy())
        target = self._edge_bus(volts, emf, drawn, past, sag)
        falls = browned | ~(target >= self._floor)
        # Where it would brown out, the volts there went past the bus: halfway down to the
        # lowest bus at once. Above its nominal voltage
        # (regenerating) the bus gives nothing more: the commands stop at the nominal voltage.
        halfway = 0.5 * (sag + nominal - self._lowest)
        needed = np.maximum(np.where(falls, np.maximum(sag, halfway), nominal - target), 0.0)
        binding = beyond + np.maximum(sag, 0.0) > -BUS_TOLERANCE_V
        # Never relax to a sag a timing was already found unsafe at: halfway to it at most.
        self.unsafe = np.where(fits, self.unsafe, np.fmax(self.unsafe, sag))
        lowest = np.where(np.isnan(self.unsafe), -np.inf, 0.5 * (sag + self.unsafe))
        relaxed = np.maximum(sag - self.relax * (sag - needed), lowest)
        relax = fits & binding & (relaxed < sag - BUS_TOLERANCE_V)
        self.sag = np.where(fits, np.where(relax, relaxed, sag), np.maximum(sag, needed))
        return bool(np.all(fits) and not np.any(relax))

    def _edge_bus(self, volts, emf, drawn, past, sag):
        """Per grid point, the bus at which the joints whose voltage is at its window's edge
        would sit exactly on it, at the same speeds: V_j = ±(V_bus − reserve_j), the others as
        they are; the upper root of V_bus² − V_nominal·V_bus + R_battery·P = 0, P the
        motors' power (a quadratic in V_bus). The lower of the two stages; NaN where there
        is none (a brownout), the plain bus where nothing is at an edge."""
        along = self._direction * volts >= 0.0
        reserve = np.where(along, *self._reserves)                   # (2, n, 2)
        edge = past + sag[:, None] >= -BUS_TOLERANCE_V
        side = np.sign(volts)
        g = np.where(edge, self._conductance, 0.0)
        r_b = self._r_battery
        a = 1.0 + r_b * np.sum(g, axis=-1)
        b = -self._nominal + r_b * np.sum(g * (-2.0 * reserve - side * emf), axis=-1)
        c = r_b * np.sum(g * (reserve ** 2 + side * emf * reserve)
                         + np.where(edge, 0.0, drawn), axis=-1)
        with np.errstate(invalid='ignore'):
            root = (-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
        return np.where(np.any(np.isnan(root), axis=0), np.nan, np.min(root, axis=0))


def under_the_bus(solve, terms: PathTerms, limits: TrajectoryLimits, grid, sag_v=None,
                  iterations=None, relax=RELAX, give_up=False, after_fit=None):
    """The fastest x = ṡ² from ``solve(sag_v)`` (None: no timing) that fits the bus it
    leaves (``BusSag``, starting from ``sag_v``), after at most ``iterations`` timings (and
    at most ``after_fit`` more once one fits), with the sag it was timed with. When none
    fits, the last timing if it misses by no more than ``NEAR_MISS_V`` (the final check
    tightens it), else None with ``give_up``, else the safe one (``safe``); None when
    ``solve`` finds none."""
    follower = BusSag(terms, limits, grid, sag_v, relax)
    left = math.inf if after_fit is None else after_fit
    for _ in range(1 if follower.stiff else iterations or BUS_ITERATIONS):
        sag = follower.sag
        x = solve(sag)
        if x is None or follower.settle(x) or left <= 0:
            break
        if follower.best is not None:
            left -= 1
    if follower.best is not None:
        _, x, sag = follower.best
        return x, sag
    if x is None or follower.worst_excess_v <= NEAR_MISS_V:
        return x, sag
    if give_up:
        return None, sag
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


def bus_profile(path, dynamics, limits: TrajectoryLimits, margin_v=0.0, start_speed=0.0,
                hint=None):
    """(σ, sag) of the path's exact timing under its own bus, found on a coarse grid
    (``COARSE_STAGES``) from ``hint`` (a like path's (σ, sag)); zero sag when the start
    speed is out of its reach."""
    sigma = clustered(path.length, COARSE_STAGES)
    terms = PathTerms.along(dynamics, path, sigma)
    start = None if hint is None else np.interp(sigma, *hint)
    x, sag = under_the_bus(exact_timing(terms, sigma, limits, margin_v, start_speed),
                           terms, limits, sigma, start)
    if x is None:
        return sigma, np.zeros(len(sigma))
    return sigma, sag
