"""The bus a timed path leaves, and the timing under it.

The bus sags under the trajectory's own draw (``PowerSupply.bus_voltages``), and the volts
each joint may use sag with it. A path is timed with a sag per grid point, the bus computed
along the result, and the sag corrected (a secant step per point toward the sag the timing
itself causes) until every grid point's voltage fits its own bus less the reserves. Where
the bus would fall below the brownout voltage (plus a margin), the motors' currents are held
to what keeps it there (``TrajectoryLimits.floor_current_a``) and the bus taken at that floor.
"""

import numpy as np

from arm_control.control.trajectory.exact import fastest_speeds
from arm_control.control.trajectory.limits import TrajectoryLimits, window
from arm_control.control.trajectory.path import clustered
from arm_control.control.trajectory.rows import PathTerms, rows, speed_caps

BUS_ITERATIONS = 10
# The bus is found on this many stages first, then only raised where it falls short, in at
# most this many timings on the fine grid.
COARSE_STAGES = 32
FINE_BUS_ITERATIONS = 4
# Volts a grid point's voltage may pass its own bus by in the iteration (the final check on
# dense samples has the last word).
BUS_TOLERANCE_V = 0.02
# How far a safe sag moves toward the one its timing would fit exactly (the volts follow the
# bus, but so does the timing: a full step would overshoot).
RELAX = 0.5


def stage_voltages(terms: PathTerms, x, steps):
    """The voltages (2, n, 2) at each grid point under x = ṡ² with s̈ held over each stage:
    with the stage that leaves it, and with the stage that arrives."""
    u = np.diff(x) / (2.0 * np.asarray(steps))
    return np.stack([terms.voltage(np.append(u, u[-1:]), x),
                     terms.voltage(np.insert(u, 0, u[:1]), x)])


def bus_along(terms: PathTerms, limits: TrajectoryLimits, volts, x) -> np.ndarray:
    """The bus (n,) at each grid point for ``stage_voltages``: the lower of the two; NaN
    where the battery cannot give the power."""
    joint_speed = terms.dq * np.sqrt(np.maximum(x, 0.0))[:, None]
    bus = limits.supply.bus_voltages(volts, joint_speed)
    return np.where(np.any(np.isnan(bus), axis=0), np.nan, np.min(bus, axis=0))


def excess_over_bus(terms: PathTerms, limits: TrajectoryLimits, volts, bus) -> np.ndarray:
    """How far (V) each grid point's voltage goes past the bus less the reserves."""
    sag = np.maximum(limits.nominal_voltage - bus, 0.0)
    driving, braking = limits.budget
    centre, half = window(terms.dq, driving - sag[:, None], braking - sag[:, None])
    return np.max(np.abs(volts - centre) - half, axis=(0, 2))


def bus_at_the_edge(terms: PathTerms, limits: TrajectoryLimits, volts, x, sag):
    """Per grid point, the bus at which the joints whose voltage is at its window's edge
    would sit exactly on it, at the same speeds: V_j = ±(V_bus − reserve_j), the others as
    they are; the upper root of V_bus² − V_nominal·V_bus + R_battery·P(V_bus) = 0, P the
    motors' power (a quadratic in V_bus). For ``stage_voltages`` (2, n, 2): the lower of
    the two; NaN where there is none (a brownout), the plain bus where nothing is at an
    edge."""
    supply = limits.supply
    speed = np.sqrt(np.maximum(x, 0.0))[:, None]
    emf = terms.emf * speed                                       # (n, 2)
    driving, braking = limits.budget
    centre, half = window(terms.dq, driving - sag[:, None], braking - sag[:, None])
    along = np.sign(terms.dq) * volts >= 0.0
    reserve = np.where(along, *limits.reserves_v)                  # (2, n, 2)
    edge = np.abs(volts - centre) >= half - BUS_TOLERANCE_V
    side = np.sign(volts)
    conductance = np.array([m.count / m.resistance_ohm for m in supply.motors])
    free_power = np.sum(np.where(edge, 0.0, conductance * volts * (volts - emf)), axis=-1)
    g = np.where(edge, conductance, 0.0)
    r_b = supply.resistance_ohm
    a = 1.0 + r_b * np.sum(g, axis=-1)
    b = -supply.nominal_voltage + r_b * np.sum(g * (-2.0 * reserve - side * emf), axis=-1)
    c = r_b * (np.sum(g * (reserve ** 2 + side * emf * reserve), axis=-1) + free_power)
    with np.errstate(invalid='ignore'):
        root = (-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    return np.where(np.any(np.isnan(root), axis=0), np.nan, np.min(root, axis=0))


class BusSag:
    """The sag per grid point that one path's timing assumes, corrected toward its own.

    Each timing is judged per grid point: does its voltage fit the bus it leaves, less the
    reserves? The next sag is the one at which the joints at their voltage's edge would
    fit their own bus exactly, at the timing's speeds (``bus_at_the_edge``: a Newton-like
    step, since the volts follow the bus there); where the bus would fall below the floor,
    every motor's current is held to ``floor_current_a`` from then on and the bus taken at
    the floor. The fastest timing that fits everywhere is kept.
    """

    def __init__(self, terms: PathTerms, limits: TrajectoryLimits, grid, sag_v=None,
                 current_cap_a=None, relax=RELAX):
        self.terms, self.limits, self.relax = terms, limits, relax
        self.steps = np.diff(grid)
        self.sag = np.zeros(len(grid)) if sag_v is None else np.array(sag_v, float)
        self.current_cap_a = None if current_cap_a is None else np.array(current_cap_a, float)
        self.unsafe = np.full(len(grid), np.nan)    # the most sag found unsafe, per point
        self.best = None                   # (duration, x, sag, cap) of the fastest that fits

    @property
    def stiff(self) -> bool:
        return self.limits.supply is None

    def settle(self, x) -> bool:
        """Judge the timing x made with ``sag`` and ``current_cap_a``; True when it fits
        and the sag stays, else set them for the next timing."""
        if self.stiff:
            self.best = (None, x, self.sag, None)
            return True
        limits, sag = self.limits, self.sag
        volts = stage_voltages(self.terms, x, self.steps)
        bus = bus_along(self.terms, limits, volts, x)
        browned = ~(bus >= limits.bus_floor_v)                 # NaN too
        fits = ~browned & (excess_over_bus(self.terms, limits, volts,
                                           np.nan_to_num(bus)) <= BUS_TOLERANCE_V)
        cap = None if self.current_cap_a is None else self.current_cap_a.copy()
        if np.all(fits):
            duration = float(np.sum(2.0 * self.steps / np.maximum(
                np.sqrt(x[1:]) + np.sqrt(x[:-1]), 1e-12)))
            if self.best is None or duration < self.best[0]:
                self.best = (duration, x, sag.copy(), cap)
        target = bus_at_the_edge(self.terms, limits, volts, x, sag)
        falls = browned | ~(target >= limits.bus_floor_v)
        if np.any(falls):
            if self.current_cap_a is None:
                self.current_cap_a = np.full(len(sag), np.inf)
            self.current_cap_a[falls] = limits.floor_current_a()
        # Above its nominal voltage (regenerating) the bus gives nothing more: the commands
        # stop at the nominal voltage.
        needed = np.maximum(limits.nominal_voltage - np.where(falls, limits.bus_floor_v,
                                                              target), 0.0)
        binding = excess_over_bus(self.terms, limits, volts,
                                  limits.nominal_voltage - sag) > -BUS_TOLERANCE_V
        # Never relax to a sag a timing was already found unsafe at: halfway to it at most.
        self.unsafe = np.where(fits, self.unsafe, np.fmax(self.unsafe, sag))
        lowest = np.where(np.isnan(self.unsafe), -np.inf, 0.5 * (sag + self.unsafe))
        relaxed = np.maximum(sag - self.relax * (sag - needed), lowest)
        relax = fits & binding & (relaxed < sag - BUS_TOLERANCE_V)
        self.sag = np.where(fits, np.where(relax, relaxed, sag), np.maximum(sag, needed))
        return bool(np.all(fits) and not np.any(relax))


def under_the_bus(solve, terms: PathTerms, limits: TrajectoryLimits, grid, sag_v=None,
                  current_cap_a=None, iterations=BUS_ITERATIONS, relax=RELAX):
    """The fastest x = ṡ² from ``solve(sag_v, current_cap_a)`` (None: no timing) that fits
    the bus it leaves (``BusSag``, starting from ``sag_v`` and ``current_cap_a``), after at
    most ``iterations`` timings, with the sag and the current caps it was timed with; else
    the last timing (the final check has the last word), or None when ``solve`` finds
    none."""
    follower = BusSag(terms, limits, grid, sag_v, current_cap_a, relax)
    sag, cap = follower.sag, follower.current_cap_a
    for _ in range(1 if follower.stiff else iterations):
        sag = follower.sag
        cap = None if follower.current_cap_a is None else follower.current_cap_a.copy()
        x = solve(sag, cap)
        if x is None or follower.settle(x):
            break
    if follower.best is None:
        return x, sag, cap
    _, x, sag, cap = follower.best
    return x, sag, cap


def exact_timing(terms: PathTerms, grid, limits: TrajectoryLimits, margin_v: float = 0.0,
                 start_speed: float = 0.0):
    """solve(sag_v, current_cap_a) -> x = ṡ² of the exact timing (``exact``) on this grid
    from ``start_speed`` to rest, or None when there is none."""
    steps = np.diff(grid)
    top = speed_caps(limits, terms.dq)[None]

    def solve(sag_v, current_cap_a):
        A, B, C, D, W = rows(terms, limits, sag_v, current_cap_a, margin_v)
        speed = fastest_speeds(A[None], B[None], C[None], D[None], W, top, steps,
                               start_speed)[0]
        if not np.all(np.isfinite(speed)) or np.any(speed[1:] + speed[:-1] <= 0.0):
            return None
        return speed ** 2

    return solve


def on_grid(grid, sigma, values):
    """A profile over σ on another grid, inf staying inf (None stays None)."""
    if values is None:
        return None
    finite = np.isfinite(values)
    out = np.interp(grid, sigma, np.where(finite, values, 0.0))
    return np.where(np.interp(grid, sigma, (~finite).astype(float)) > 0.0, np.inf, out)


def bus_profile(path, dynamics, limits: TrajectoryLimits, margin_v=0.0, start_speed=0.0,
                hint=None):
    """(σ, sag, current cap) of the path's exact timing under its own bus, found on a coarse
    grid (``COARSE_STAGES``) from ``hint`` (a like path's (σ, sag, current cap)); zero sag
    when the start speed is out of its reach."""
    sigma = clustered(path.length, COARSE_STAGES)
    terms = PathTerms.along(dynamics, path, sigma)
    start = (None, None) if hint is None else (np.interp(sigma, hint[0], hint[1]),
                                               on_grid(sigma, hint[0], hint[2]))
    x, sag, cap = under_the_bus(exact_timing(terms, sigma, limits, margin_v, start_speed),
                                terms, limits, sigma, *start)
    if x is None:
        return sigma, np.zeros(len(sigma)), None
    return sigma, sag, cap
