"""Fit the base parameters to a log: τ_motor(V, θ̇) = Y(θ, θ̇, θ̈)·π by weighted least squares.

Signal processing. The positions are resampled onto a uniform grid (piece by piece where
the log has gaps) and the accelerations come from a Savitzky-Golay filter (cubic,
``smoothing_window_s``, zero-phase, so no lag). That filter's second derivative is a
weighted mean of the true acceleration, Σ_j w_j·θ̈_j over the sample intervals j of its
window, with w the integral of its Peano kernel over each interval (``acceleration_kernel``).
Every other term of the equation is filtered with the same w -- the voltage, as each
interval's mean of the commands held (zero-order) from ``lag`` after they were sent, clipped
to the battery voltage where that was logged; the back-EMF and viscous terms with each
interval's mean velocity Δθ/T; gravity, Coriolis and Coulomb terms at the interval's middle,
from the smoothed positions and velocities -- so both sides see the same band and the 50 Hz
zero-order hold biases nothing (parallel filtering with the kernel the data impose). The
lag -- the command-to-motion delay of the robot's loop and bus -- is searched within
±``max_command_lag_s``, and the most likely one kept.

The fit. Each sample gives two rows (shoulder, elbow). Rows are weighted by 1/σ of their
joint's residual (two passes), and solved by ``numpy.linalg.lstsq``. Uncertainty: the
filter makes neighbouring residuals alike, so the covariance is the Newey-West (HAC)
estimate, (XᵀX)⁻¹·S·(XᵀX)⁻¹ with S summing residual products over twice the filter's
window (Bartlett weights), not the textbook σ²(XᵀX)⁻¹, which would claim several times the
precision the data hold.
"""

from dataclasses import dataclass
import math

import numpy as np
from scipy.signal import savgol_filter

from arm_control.config import ArmConfig
from arm_control.model.dynamics import ArmDynamics
from arm_control.sysid.log import Log
from arm_control.sysid.regressor import base_parameters, PARAMETER_COUNT, regressor

POLYORDER = 3
GAP_PERIODS = 2.5          # a step longer than this many sample periods splits the log
LAG_STEPS = 17             # lags tried across ±max_command_lag_s
MIN_SAMPLES = 50
MIN_SPEED_RAD_S = 0.1
VISCOUS_COLUMNS = ((0, 4), (1, 6))     # (row, column) of b_a·θ̇a and b_b·θ̇b in Y


def window_samples(window_s: float, period_s: float) -> int:
    """The filter's length in samples: odd, and long enough for a cubic."""
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
    ``inside`` is False before the first command and after the last one's period."""
    edges = log.command_time_s + lag_s
    volts = log.voltage_v
    held = np.diff(edges)
    integral = np.vstack([np.zeros(2), np.cumsum(volts[:-1] * held[:, None], axis=0)])

    def area(t):
        k = np.clip(np.searchsorted(edges, t, side='right') - 1, 0, len(edges) - 1)
        return integral[k] + volts[k] * (t - edges[k])[:, None]

    mean = (area(end_s) - area(start_s)) / (end_s - start_s)[:, None]
    last_hold = float(np.median(held)) if len(held) else 0.0
    inside = (start_s >= edges[0]) & (end_s <= edges[-1] + last_hold)
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
        """g⊛V at each sample for a lag, and whether its whole window was commanded."""
        volts, inside = [], []
        for t in self.sample_times_s:
            # ∫Λ·V/T² over the hat Λ(s) = T − |s|: the mean of the two periods about a sample.
            before, _ = applied_voltage(log, t - self.period_s, t, lag_s)
            after, covered = applied_voltage(log, t, t + self.period_s, lag_s)
            _, covered_before = applied_voltage(log, t - self.period_s, t, lag_s)
            volts.append(_filter((before + after) / 2.0, self.weights))
            whole = (covered & covered_before).astype(float)
            inside.append(_filter(whole, np.ones(len(self.weights))) > len(self.weights) - 0.5)
        return np.concatenate(volts), np.concatenate(inside)


def filter_log(log: Log, arm: ArmConfig, window_s: float) -> FilteredLog:
    """The regressor and velocities, filtered with g over the log's samples.

    At each sample i the second difference is exact: (θ_{i+1} − 2θ_i + θ_{i−1})/T² is the
    mean of θ̈ under the hat Λ(s) = T − |s| (/T²), and so are the central difference of θ
    for ω and the mean of the two periods' voltages for V. The inertia terms take that
    acceleration with M(θ_i) (M changes little in ±T); gravity, Coriolis and Coulomb terms
    the Savitzky-Golay-smoothed θ and θ̇; the viscous term the central difference, as the
    back-EMF does. Then every term is smoothed by the same g.
    """
    time_s, position = log.joint_time_s, log.position_rad
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
        rows = regressor(arm, q_i, speed[inner], zero)       # gravity, Coriolis, friction
        for row, column in VISCOUS_COLUMNS:
            rows[:, row, column] = central[:, row]
        rows += regressor(arm, q_i, zero, acceleration) - regressor(arm, q_i, zero, zero)
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


def weighted_least_squares(design, target, weights):
    """π minimising Σ w²(Yπ − y)² over rows (M, 8), (M,); returns (π, residuals)."""
    estimate, *_ = np.linalg.lstsq(design * weights[:, None], target * weights, rcond=None)
    return estimate, target - design @ estimate


def hac_covariance(design, residual, rows_per_lag: int) -> np.ndarray:
    """Newey-West covariance of a least-squares estimate whose residuals are correlated
    over up to ``rows_per_lag`` neighbouring rows (Bartlett weights)."""
    scores = design * residual[:, None]
    meat = scores.T @ scores
    for lag in range(1, rows_per_lag + 1):
        weight = 1.0 - lag / (rows_per_lag + 1.0)
        cross = scores[lag:].T @ scores[:-lag]
        meat += weight * (cross + cross.T)
    bread = np.linalg.inv(design.T @ design)
    return bread @ meat @ bread


@dataclass(frozen=True)
class FitResult:
    """The identified base parameters and how well they explain the log."""

    parameters: np.ndarray               # π (8,)
    covariance: np.ndarray               # (8, 8)
    lag_s: float
    residual_rms_nm: np.ndarray          # per joint
    residual_rms_v: np.ndarray           # the same, as motor voltage
    measured_rms_v: np.ndarray           # the (filtered) voltage's own spread, per joint
    samples: int                         # samples that entered the fit
    duration_s: float
    condition_number: float              # of the weighted regressor, columns scaled to 1
    time_s: np.ndarray                   # for the plot: the fitted samples ...
    measured_v: np.ndarray               # ... the voltage the arm got (filtered)
    predicted_v: np.ndarray              # ... the identified model's
    nominal_v: np.ndarray                # ... the robot file's

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))


def fit_log(log: Log, arm: ArmConfig, window_s: float, max_lag_s: float) -> FitResult:
    """Identify π from a log; ``arm`` (the robot file) gives La, g and the motors."""
    filtered = filter_log(log, arm, window_s)
    coefficients = motor_coefficients(ArmDynamics(arm))
    design_rows = filtered.design.reshape(-1, PARAMETER_COUNT)
    back_emf = coefficients[:, 1] * filtered.back_emf_velocity

    def solve(lag):
        volts, inside = filtered.voltage(log, lag)
        use = inside[:, None] & (np.abs(filtered.velocity) >= MIN_SPEED_RAD_S)
        if use.sum() < 2 * MIN_SAMPLES:
            return None
        target = (coefficients[:, 0] * volts - back_emf).reshape(-1)
        rows = use.reshape(-1)                  # sample k: row 2k shoulder, 2k + 1 elbow
        weights = np.ones(len(target))
        for _ in range(2):
            estimate, _ = weighted_least_squares(design_rows[rows], target[rows],
                                                 weights[rows])
            residual = target - design_rows @ estimate
            spread = np.array([np.sqrt(np.mean(residual.reshape(-1, 2)[use[:, j], j] ** 2))
                               for j in range(2)])
            weights = np.tile(1.0 / np.maximum(spread, 1e-12), len(inside))
        # The likelihood of Gaussian residuals with a variance per joint: Σ_j n_j·log σ_j.
        cost = float(np.sum(use.sum(axis=0) * np.log(np.maximum(spread, 1e-300))))
        return cost, estimate, residual, weights, volts, use

    lags = np.linspace(-max_lag_s, max_lag_s, LAG_STEPS) if max_lag_s > 0 else np.zeros(1)
    solutions = [(lag, solve(lag)) for lag in lags]
    solutions = [(lag, s) for lag, s in solutions if s is not None]
    if not solutions:
        raise ValueError(f'too few samples with both joint states and commands '
                         f'(at least {MIN_SAMPLES} needed)')
    lag, (_, estimate, residual, weights, volts, use) = min(solutions, key=lambda s: s[1][0])
    rows = use.reshape(-1)
    weighted = design_rows * (weights * rows)[:, None]
    covariance = hac_covariance(weighted, residual * weights * rows,
                                4 * len(filtered.weights))
    scaled = weighted[rows] / np.linalg.norm(weighted[rows], axis=0)
    residual_nm = np.array([np.sqrt(np.mean(residual.reshape(-1, 2)[use[:, j], j] ** 2))
                            for j in range(2)])
    inside = np.any(use, axis=1)

    def as_voltage(parameters):
        torque = (filtered.design @ parameters)[inside]
        return (torque + back_emf[inside]) / coefficients[:, 0]

    measured = volts[inside]
    times = filtered.time_s[inside]
    return FitResult(
        parameters=estimate, covariance=covariance, lag_s=float(lag),
        residual_rms_nm=residual_nm, residual_rms_v=residual_nm / coefficients[:, 0],
        measured_rms_v=np.std(measured, axis=0), samples=int(inside.sum()),
        duration_s=float(times[-1] - times[0]),
        condition_number=float(np.linalg.cond(scaled)),
        time_s=times - log.joint_time_s[0], measured_v=measured,
        predicted_v=as_voltage(estimate), nominal_v=as_voltage(base_parameters(arm)))
