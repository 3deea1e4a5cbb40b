"""Fit the base parameters to a log: τ_motor(V, θ̇) = Y(θ, θ̇, θ̈)·π, weighted, by instruments.

Signal processing (``filter_log``). The positions are resampled onto a uniform grid (piece
by piece where the log has gaps). At each sample the equation is first made exact for
sampled data: the second difference of θ is the mean of θ̈ under a hat of ±1 period, the
central difference the mean of θ̇, and the mean of the two periods' voltages the mean of V
(commands held, zero-order, from ``lag`` after they were sent; clipped to the battery
voltage where that was logged). The inertia terms take that acceleration with M(θ) at the
Savitzky-Golay-smoothed θ (the raw θ's noise in cos θb would multiply its own in the second
difference: E[n_i·(n_{i+1} − 2n_i + n_{i−1})] = −2σ²); gravity, Coriolis and Coulomb terms
the raw θ at the sample (its noise enters cos θ only at second order, and a smoothed θ is
a distorted one, the more so the longer the window, which gravity's large torque turns
into bias) and the smoothed θ̇ (a quintic: less distortion of the fast steps); the viscous
term the central difference, as the back-EMF does. Then every term is smoothed by the same
Hann window of ``smoothing_window_s``, so both sides of the equation see the same band and
the 50 Hz zero-order hold biases nothing.

The fit (``fit_log``). Each sample gives two rows, shoulder and elbow, weighted by 1/σ of
their joint's residual (two passes). The arm ran in closed loop, so the command carries the
sensors' noise (through the feedback), and the noisy accelerations would pull the inertias
down: least squares is biased. When the log holds the plan the commands were computed for
(``/sysid/reference``), the same regressor built from the plan serves as instruments --
correlated with the motion, not with the sensor noise -- and the estimate is
(ZᵀW²Y)⁻¹ZᵀW²y. A bag without the plan (a real robot's, recorded otherwise) gets least
squares, with that bias. The command-to-motion lag is the most likely of a grid across
±``max_command_lag_s``, refined as a ninth unknown (linearised: kv·V(t − δ) ≈ kv·V −
δ·kv·V̇), so π's uncertainty includes the lag's. Rows of a joint slower than
``min_speed_rad_s`` (by the plan, when there is one) are left out: Coulomb friction needs
the direction of travel.

Uncertainty: the filter makes neighbouring residuals alike, so the covariance is the
Newey-West (HAC) estimate, B·S·Bᵀ with B = (ZᵀX)⁻¹ and S summing score products over four
filter windows of rows (Bartlett weights), not the textbook σ²(XᵀX)⁻¹, which would claim
several times the precision the data hold. Over 12 seeded runs on the demo arm
(``bench/bench_sysid.py --seeds 12``) the estimates spread by 0.4-1.0 of their stated σ,
except α's, by 1.3: its σ is a quarter too small.
"""

from dataclasses import dataclass
import math

import numpy as np
from scipy.signal import savgol_filter

from arm_control.config import ArmConfig
from arm_control.model.dynamics import ArmDynamics
from arm_control.sysid.log import Log
from arm_control.sysid.regressor import base_parameters, PARAMETER_COUNT, regressor

POLYORDER = 5              # the Savitzky-Golay polynomial of the smoothed θ and θ̇
GAP_PERIODS = 2.5          # a step longer than this many sample periods splits the log
LAG_STEPS = 17             # lags tried across ±max_command_lag_s
MIN_SAMPLES = 50
UNEXCITED = 1e-6           # a column this small against the largest is not excited
HAC_WINDOWS = 2             # residuals are taken as correlated over this many filter windows
VISCOUS_COLUMNS = ((0, 4), (1, 6))     # (row, column) of b_a·θ̇a and b_b·θ̇b in Y
PARAMETER_JOINT = (0, 1, 0, 1, 0, 0, 1, 1)  # the joint whose torque each parameter is judged by


def window_samples(window_s: float, period_s: float) -> int:
    """The filter's length in samples: odd, and long enough for the polynomial."""
    window = max(POLYORDER + 3, int(round(window_s / period_s)))
    return window + 1 if window % 2 == 0 else window


def smoothing_weights(window: int) -> np.ndarray:
    """g: a Hann window of ``window`` samples, summing to 1."""
    weights = np.hanning(window + 2)[1:-1]
    return weights / weights.sum()


def _filter(samples, weights):
    """Σ_i g_i·x_{k−m+i} for every sample k with a whole window: (n, ...) → (n − 2m, ...)."""
    windows = np.lib.stride_tricks.sliding_window_view(samples, len(weights), axis=0)
    return windows @ weights


def applied_voltage(log: Log, start_s, end_s, lag_s: float):
    """The mean voltage over [start_s, end_s] (arrays): commands held (zero-order) from
    ``lag_s`` after they were sent, clipped to the battery voltage where it was logged;
    ``inside`` is False before the first command, after the last one's period, and over a
    gap in the commands (one held more than ``GAP_PERIODS`` periods: the node stalled, and
    the robot timed out to 0 V meanwhile, which the log does not hold)."""
    edges = log.command_time_s + lag_s
    volts = log.voltage_v
    held = np.diff(edges)
    integral = np.vstack([np.zeros(2), np.cumsum(volts[:-1] * held[:, None], axis=0)])

    def area(t):
        k = np.clip(np.searchsorted(edges, t, side='right') - 1, 0, len(edges) - 1)
        return integral[k] + volts[k] * (t - edges[k])[:, None]

    mean = (area(end_s) - area(start_s)) / (end_s - start_s)[:, None]
    last_hold = float(np.median(held)) if len(held) else 0.0
    stalled = np.concatenate([[0], np.cumsum(np.append(held > GAP_PERIODS * last_hold, False))])
    first = np.clip(np.searchsorted(edges, start_s, side='right') - 1, 0, len(edges) - 1)
    last = np.clip(np.searchsorted(edges, end_s, side='left') - 1, 0, len(edges) - 1)
    inside = ((start_s >= edges[0]) & (end_s <= edges[-1] + last_hold)
              & (stalled[last + 1] == stalled[first]))
    if len(log.battery_v):
        bus = np.interp((start_s + end_s) / 2.0, log.battery_time_s, log.battery_v)
        mean = np.clip(mean, -bus[:, None], bus[:, None])
    return mean, inside


def motor_coefficients(dynamics: ArmDynamics):
    """Per joint (torque per volt kv, back-EMF torque per rad/s kω): τ = kv·V − kω·ω."""
    out = []
    for motor in dynamics.motors:
        at_rest = motor.torque_nm(0.0, 0.0)
        out.append((motor.torque_nm(1.0, 0.0) - at_rest, at_rest - motor.torque_nm(0.0, 1.0)))
    return np.array(out)


@dataclass(frozen=True)
class FilteredLog:
    """The filtered equation at each usable sample k, kv·g⊛V − kω·g⊛ω = design·π
    (design (N, 2, 8)); the voltage side is computed per command lag tried."""

    time_s: np.ndarray               # (N,)
    design: np.ndarray               # (N, 2, 8)
    back_emf_velocity: np.ndarray    # (N, 2): g⊛ω, ω = (θ_{i+1} − θ_{i−1})/2T
    velocity: np.ndarray             # (N, 2): the smoothed velocity
    sample_times_s: list             # per piece: the samples the filter runs over
    weights: np.ndarray              # g
    period_s: float

    def voltage(self, log: Log, lag_s: float):
        """g⊛V at each sample for a lag, its rate of change, and whether the sample's whole
        window was commanded."""
        volts, rates, inside = [], [], []
        for t in self.sample_times_s:
            # ∫Λ·V/T² over the hat Λ(s) = T − |s|: the mean of the two periods about a sample.
            before, covered_before = applied_voltage(log, t - self.period_s, t, lag_s)
            after, covered_after = applied_voltage(log, t, t + self.period_s, lag_s)
            smooth = _filter((before + after) / 2.0, self.weights)
            volts.append(smooth)
            rates.append(np.gradient(smooth, self.period_s, axis=0))
            whole = (covered_before & covered_after).astype(float)
            inside.append(_filter(whole, np.ones(len(self.weights))) > len(self.weights) - 0.5)
        return np.concatenate(volts), np.concatenate(rates), np.concatenate(inside)


def filter_log(time_s, position, arm: ArmConfig, window_s: float) -> FilteredLog:
    """The regressor and velocities, filtered with g over a log's joint samples.

    At each sample i the second difference is exact: (θ_{i+1} − 2θ_i + θ_{i−1})/T² is the
    mean of θ̈ under the hat Λ(s) = T − |s| (/T²), and so are the central difference of θ
    for ω and the mean of the two periods' voltages for V. The inertia terms take that
    acceleration with M at the Savitzky-Golay-smoothed θ_i (M changes little in ±T);
    gravity, Coriolis and Coulomb terms the raw θ_i and the smoothed θ̇ (whose kernel gives
    θ_i no weight); the viscous term the central difference, as the back-EMF does. Then
    every term is smoothed by the same g.
    """
    time_s, position = np.asarray(time_s, float), np.asarray(position, float)
    period = float(np.median(np.diff(time_s)))
    window = window_samples(window_s, period)
    weights = smoothing_weights(window)
    m = window // 2
    breaks = np.flatnonzero(np.diff(time_s) > GAP_PERIODS * period) + 1
    parts = {k: [] for k in ('t', 'design', 'emf', 'qd', 'samples')}
    for index in np.split(np.arange(len(time_s)), breaks):
        t = time_s[index]
        count = int(math.floor((t[-1] - t[0]) / period + 1e-6)) + 1
        if count < window + 4:
            continue
        grid = t[0] + period * np.arange(count)
        q = np.column_stack([np.interp(grid, t, position[index, j]) for j in range(2)])
        smooth, speed = (savgol_filter(q, window, POLYORDER, deriv=order, delta=period,
                                       axis=0, mode='interp') for order in (0, 1))
        inner = slice(1, count - 1)
        acceleration = (q[2:] - 2.0 * q[1:-1] + q[:-2]) / period ** 2
        central = (q[2:] - q[:-2]) / (2.0 * period)
        q_i, zero = smooth[inner], np.zeros_like(acceleration)
        rows = regressor(arm, q[inner], speed[inner], zero)     # gravity, Coriolis, friction
        for row, column in VISCOUS_COLUMNS:
            rows[:, row, column] = central[:, row]
        inertial = regressor(arm, q_i, zero, acceleration) - regressor(arm, q_i, zero, zero)
        rows += inertial
        centre = slice(1 + m, count - 1 - m)
        parts['design'].append(_filter(rows, weights))
        parts['emf'].append(_filter(central, weights))
        parts['t'].append(grid[centre])
        parts['qd'].append(speed[centre])
        parts['samples'].append(grid[inner])
    if not parts['t']:
        raise ValueError(f'the log has no stretch of joint states longer than the '
                         f'{window * period:.2f} s smoothing window')
    return FilteredLog(
        time_s=np.concatenate(parts['t']), design=np.concatenate(parts['design']),
        back_emf_velocity=np.concatenate(parts['emf']),
        velocity=np.concatenate(parts['qd']), sample_times_s=parts['samples'],
        weights=weights, period_s=period)


def weighted_least_squares(design, target, weights, instruments=None):
    """π minimising Σ w²(Yπ − y)² over rows (M, 8), (M,); with ``instruments`` Z, the
    instrumental-variable estimate (ZᵀW²Y)⁻¹ZᵀW²y instead. Returns (π, residuals)."""
    if instruments is None:
        estimate, *_ = np.linalg.lstsq(design * weights[:, None], target * weights,
                                       rcond=None)
    else:
        z = instruments * weights[:, None] ** 2
        estimate = np.linalg.solve(z.T @ design, z.T @ target)
    return estimate, target - design @ estimate


def hac_covariance(design, residual, rows_per_lag: int, instruments=None) -> np.ndarray:
    """Newey-West covariance of a least-squares (or, with ``instruments``, an
    instrumental-variable) estimate whose residuals are correlated over up to
    ``rows_per_lag`` neighbouring rows (Bartlett weights)."""
    instruments = design if instruments is None else instruments
    scores = instruments * residual[:, None]
    meat = scores.T @ scores
    for lag in range(1, rows_per_lag + 1):
        weight = 1.0 - lag / (rows_per_lag + 1.0)
        cross = scores[lag:].T @ scores[:-lag]
        meat += weight * (cross + cross.T)
    bread = np.linalg.inv(instruments.T @ design)
    return bread @ meat @ bread.T


@dataclass(frozen=True)
class FitResult:
    """The identified base parameters and how well they explain the log."""

    parameters: np.ndarray               # π (8,)
    covariance: np.ndarray               # (8, 8)
    lag_s: float
    lag_sigma_s: float
    instrumented: bool                   # instruments from the logged plan, else least squares
    residual_rms_nm: np.ndarray          # per joint
    residual_rms_v: np.ndarray           # the same, as motor voltage
    measured_rms_v: np.ndarray           # the (filtered) voltage's own spread, per joint
    samples: int                         # samples that entered the fit (either joint)
    duration_s: float
    condition_number: float              # of the weighted regressor, columns scaled to 1
    column_rms: np.ndarray               # (8,) RMS of each column over its joint's rows used
    torque_rms_nm: np.ndarray            # (2,) RMS of each joint's torque over its rows used
    moving_samples: np.ndarray           # (2, 2) per joint, samples used moving − and +
    time_s: np.ndarray                   # for the plot: every commanded sample ...
    measured_v: np.ndarray               # ... the voltage the arm got (filtered)
    predicted_v: np.ndarray              # ... the identified model's
    nominal_v: np.ndarray                # ... the robot file's

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))


def fit_log(log: Log, arm: ArmConfig, window_s: float, max_lag_s: float,
            min_speed_rad_s: float = 0.1) -> FitResult:
    """Identify π from a log; ``arm`` (the robot file) gives La, g and the motors.

    The command lag is found in two steps: the most likely of a grid across ±``max_lag_s``,
    then refined with π as one more unknown δ, linearised -- kv·V(t − δ) ≈ kv·V − δ·kv·V̇ --
    so π's uncertainty includes the lag's (the inertias are sensitive to it: 5 ms moves γ by
    several per cent). ``max_lag_s`` = 0 holds the lag at 0.

    A joint's rows are left out where its smoothed speed is under ``min_speed_rad_s``:
    Coulomb friction's tanh(ω/ω_s) needs the direction of travel, which the noise hides
    near rest (and would bias c toward 0 and b up).
    """
    filtered = filter_log(log.joint_time_s, log.position_rad, arm, window_s)
    coefficients = motor_coefficients(ArmDynamics(arm))
    base_rows = filtered.design.reshape(-1, PARAMETER_COUNT)
    speed, planned = filtered.velocity, None
    if log.has_reference():
        planned = filter_log(log.joint_time_s, log.reference_at(log.joint_time_s), arm,
                             window_s)
        if planned.design.shape != filtered.design.shape:
            planned = None
    if planned is not None:
        speed = planned.velocity
    back_emf = coefficients[:, 1] * filtered.back_emf_velocity
    with_lag = max_lag_s > 0.0
    nominal = base_parameters(arm)

    def solve(lag):
        volts, rates, inside = filtered.voltage(log, lag)
        use = inside[:, None] & (np.abs(speed) >= min_speed_rad_s)
        if use.sum() < 2 * MIN_SAMPLES:
            return None
        target = (coefficients[:, 0] * volts - back_emf).reshape(-1)
        rows = use.reshape(-1)                  # sample k: row 2k shoulder, 2k + 1 elbow
        weights = np.ones(len(target))
        # A column the samples used never excite (a joint that never moved) is no unknown:
        # its parameter keeps the robot file's value, with no information (σ = ∞).
        norms = np.linalg.norm(base_rows[rows], axis=0)
        excited = norms > UNEXCITED * np.max(norms)
        target = target - base_rows[:, ~excited] @ nominal[~excited]
        design_rows = base_rows
        instrument_rows = None if planned is None else planned.design.reshape(-1,
                                                                              PARAMETER_COUNT)
        solution = None
        for step in range(3):
            if step == 2 and with_lag:
                # δ's column kv·V̇; its instrument the rate of the voltage the plan needs by
                # the estimate so far (the command itself carries the feedback's noise).
                design_rows = np.hstack([base_rows, (coefficients[:, 0] * rates).reshape(-1, 1)])
                if planned is not None:
                    needed = ((planned.design @ solution[:PARAMETER_COUNT])
                              + coefficients[:, 1] * planned.back_emf_velocity)
                    instrument_rows = np.hstack([
                        instrument_rows,
                        np.gradient(needed, filtered.period_s, axis=0).reshape(-1, 1)])
            extra = design_rows.shape[1] - PARAMETER_COUNT
            columns = np.concatenate([excited, np.ones(extra, bool)])
            solution = np.append(nominal, np.zeros(extra))
            solution[~columns] = 0.0
            solution[columns], _ = weighted_least_squares(
                design_rows[rows][:, columns], target[rows], weights[rows],
                None if instrument_rows is None else instrument_rows[rows][:, columns])
            residual = target - design_rows @ solution
            solution[~columns] = nominal[~excited]
            spread = np.array([np.sqrt(np.mean(residual.reshape(-1, 2)[use[:, j], j] ** 2))
                               if np.any(use[:, j]) else 1.0 for j in range(2)])
            weights = np.tile(1.0 / np.maximum(spread, 1e-12), len(inside))
        # The likelihood of Gaussian residuals with a variance per joint: Σ_j n_j·log σ_j.
        cost = float(np.sum(use.sum(axis=0) * np.log(np.maximum(spread, 1e-300))))
        return cost, solution, residual, weights, volts, use, inside, design_rows, \
            instrument_rows, columns

    lags = np.linspace(-max_lag_s, max_lag_s, LAG_STEPS) if with_lag else np.zeros(1)
    solutions = [(lag, solve(lag)) for lag in lags]
    solutions = [(lag, s) for lag, s in solutions if s is not None]
    if not solutions:
        raise ValueError(f'too few samples with both joint states and commands '
                         f'(at least {MIN_SAMPLES} needed)')
    best = min(solutions, key=lambda solution: solution[1][0])
    lag, (_, estimate, residual, weights, volts, use, inside, design_rows, instrument_rows,
          columns) = best
    rows = use.reshape(-1)
    weighted = design_rows * (weights * rows)[:, None]
    covariance = np.diag(np.where(columns, 0.0, np.inf))
    covariance[np.ix_(columns, columns)] = hac_covariance(
        weighted[:, columns], residual * weights * rows,
        HAC_WINDOWS * 2 * len(filtered.weights),
        None if instrument_rows is None else
        instrument_rows[:, columns] * (weights * rows)[:, None])
    weighted = weighted[:, :PARAMETER_COUNT][:, columns[:PARAMETER_COUNT]]
    lag_sigma = math.sqrt(covariance[-1, -1]) if with_lag else 0.0
    if with_lag:
        lag += estimate[-1]
    estimate, covariance = estimate[:PARAMETER_COUNT], \
        covariance[:PARAMETER_COUNT, :PARAMETER_COUNT]
    scaled = weighted[rows] / np.linalg.norm(weighted[rows], axis=0)
    target = (coefficients[:, 0] * volts - back_emf).reshape(-1)
    joint_of_row = np.tile([0, 1], len(use))

    def rms(values):
        return float(np.sqrt(np.mean(values ** 2))) if len(values) else math.nan
    column_rms = np.array([rms(base_rows[rows & (joint_of_row == j), k])
                           for k, j in enumerate(PARAMETER_JOINT)])
    torque_rms = np.array([rms(target[rows & (joint_of_row == j)]) for j in range(2)])
    moving = np.array([[np.sum(use[:, j] & (speed[:, j] < 0.0)),
                        np.sum(use[:, j] & (speed[:, j] > 0.0))] for j in range(2)])
    residual_nm = np.array([np.sqrt(np.mean(residual.reshape(-1, 2)[use[:, j], j] ** 2))
                            if np.any(use[:, j]) else math.nan for j in range(2)])

    def as_voltage(parameters):        # at the grid lag (the refinement is within a step)
        torque = (filtered.design @ parameters)[inside]
        return (torque + back_emf[inside]) / coefficients[:, 0]

    measured = volts[inside]
    times = filtered.time_s[inside]
    return FitResult(
        parameters=estimate, covariance=covariance, lag_s=float(lag), lag_sigma_s=lag_sigma,
        instrumented=planned is not None,
        residual_rms_nm=residual_nm, residual_rms_v=residual_nm / coefficients[:, 0],
        measured_rms_v=np.std(measured, axis=0), samples=int(np.any(use, axis=1).sum()),
        duration_s=float(times[-1] - times[0]),
        condition_number=float(np.linalg.cond(scaled)), column_rms=column_rms,
        torque_rms_nm=torque_rms, moving_samples=moving,
        time_s=times - log.joint_time_s[0], measured_v=measured,
        predicted_v=as_voltage(estimate), nominal_v=as_voltage(base_parameters(arm)))
