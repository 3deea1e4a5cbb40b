"""The exact time-optimal timing of paths that start from rest (or a given path speed) and
end at rest, back-EMF kept exactly: the closed-form backward and forward passes of the
classical time-optimal parameterisation on a grid, for many paths at once (the shape search)
or one, compiled with numba (at first use: ``kernels``).
"""

import math

import numpy as np

from arm_control.timing.kernels import kernel


def kernel_array(values) -> np.ndarray:
    """``values`` as C-ordered, writable float64: the one layout the kernels are compiled
    (and cached) for. Another (a read-only view, say) would be compiled anew, for a second
    or more, in the middle of a goal."""
    return np.require(values, float, ['C', 'W'])


def fastest_speeds(A, B, C, D, W, top, steps, start_speed=0.0):
    """The fastest path speeds ṡ (K, n) along K paths sampled on one grid, from
    ``start_speed`` to rest at the end; NaN rows where the start speed is out of reach.

    Rows A·u + B·x + C + D·y within ±W (``rows.rows``; A, B, C, D of shape (K, n, rows)),
    ``top`` (K, n) the speed caps, ``steps`` (n−1,) the grid's stages in σ. The term D·y
    (back-EMF, viscous friction) is kept exactly, not linearised: u is held over each stage
    and the rows are imposed at both its ends (as TOPP-RA's interpolation), so every bound
    is a quadratic in y. For rows j, m with s = sign(A), some u fits both iff
    W_j|A_m| + W_m|A_j| + s_j|A_m|·r_j − s_m|A_j|·r_m ≥ 0 (r = B·x + C + D·y): the top speed
    (maximum velocity curve) is the first root over all pairs, and the speed caps. Backward
    from rest, y_i is the largest y with y² − 2Δ·(W_j + s_j·r_j)/|A_j| ≤ y²ᵢ₊₁ for every row
    at both ends (braking as hard as the rows allow); forward from the start, accelerate as
    hard as they allow at both ends, under that curve.
    """
    A, B, C, D, W, top = (kernel_array(v) for v in (A, B, C, D, W, top))
    return _fastest(A, B, C, D, W, top, 2.0 * np.asarray(steps, float), float(start_speed))


@kernel
def _fastest(A, B, C, D, W, top, twice, start_speed):
    """``fastest_speeds`` compiled (a few dozen points per path, where numpy's calls cost
    more than the arithmetic): per path, the top speed over every ordered pair of rows and
    the speed caps, then the rows of each stage's passes, then ``_passes_one_path``."""
    paths, points, count = A.shape
    speed = np.empty((paths, points))
    highest = np.empty(points)
    backward, forward = np.empty((points - 1, count, 7)), np.empty((points - 1, count, 7))
    sign, size, inverse = np.empty((points, count)), np.empty((points, count)), \
        np.empty((points, count))
    for k in range(paths):
        for i in range(points):
            for r in range(count):
                sign[i, r] = 1.0 if A[k, i, r] >= 0.0 else -1.0
                size[i, r] = abs(A[k, i, r])
                inverse[i, r] = 1.0 / size[i, r] if size[i, r] > 1e-12 else 0.0
            least = top[k, i]
            for j in range(count):
                for m in range(count):
                    if m == j:
                        continue
                    left, right = sign[i, j] * size[i, m], sign[i, m] * size[i, j]
                    alpha = left * B[k, i, j] - right * B[k, i, m]
                    beta = left * D[k, i, j] - right * D[k, i, m]
                    gamma = (W[j] * size[i, m] + W[m] * size[i, j] + left * C[k, i, j]
                             - right * C[k, i, m])
                    root = _first_positive_root(alpha, beta, gamma)
                    if root != root or root < least:
                        least = root
            highest[i] = least
        for i in range(points - 1):
            stage = twice[i]
            for r in range(count):
                # The s̈ bound: slope_x·x + slope_y·y + constant (braking at the stage's end,
                # driving at its start); then α, β, γ and |A| at its other end.
                bounded_end, bounded_start = size[i + 1, r] > 1e-12, size[i, r] > 1e-12
                s_end, s_start = sign[i + 1, r], sign[i, r]
                backward[i, r, 0] = -s_end * B[k, i + 1, r] * inverse[i + 1, r]
                backward[i, r, 1] = -s_end * D[k, i + 1, r] * inverse[i + 1, r]
                backward[i, r, 2] = (-(W[r] + s_end * C[k, i + 1, r]) * inverse[i + 1, r]
                                     if bounded_end else -math.inf)
                backward[i, r, 3] = stage * s_start * B[k, i, r] - size[i, r]
                backward[i, r, 4] = stage * s_start * D[k, i, r]
                backward[i, r, 5] = stage * (W[r] + s_start * C[k, i, r])
                backward[i, r, 6] = size[i, r]
                forward[i, r, 0] = -s_start * B[k, i, r] * inverse[i, r]
                forward[i, r, 1] = -s_start * D[k, i, r] * inverse[i, r]
                forward[i, r, 2] = ((W[r] - s_start * C[k, i, r]) * inverse[i, r]
                                    if bounded_start else math.inf)
                forward[i, r, 3] = -(size[i + 1, r] + stage * s_end * B[k, i + 1, r])
                forward[i, r, 4] = -stage * s_end * D[k, i + 1, r]
                forward[i, r, 5] = stage * (W[r] - s_end * C[k, i + 1, r])
                forward[i, r, 6] = size[i + 1, r]
        path_speed, ceiling = _passes_one_path(backward, forward, highest, twice, start_speed)
        if start_speed > ceiling[0] * (1.0 + 1e-9) + 1e-12:
            speed[k] = math.nan
        else:
            speed[k] = path_speed
    return speed


@kernel
def _first_positive_root(alpha, beta, gamma):
    """The least y > 0 with α·y² + β·y + γ = 0, for γ ≥ 0 (α·y² + β·y + γ ≥ 0 on [0, y]);
    inf when there is none, 0 when γ < 0. Written y = 2γ/(√(β² − 4αγ) − β): no cancellation,
    and it covers α = 0."""
    if gamma < 0.0:
        return 0.0
    discriminant = beta * beta - 4.0 * alpha * gamma
    denominator = math.sqrt(discriminant) - beta if discriminant >= 0.0 else math.nan
    return 2.0 * gamma / denominator if denominator > 0.0 else math.inf


class OnePath:
    """``fastest_speeds`` for one path on one grid, under many bus sags (the bus iteration
    times a path again and again): what does not depend on the sag is worked out once.

    Rows as ``rows.rows(..., per_point=True)``: the first ``voltage_rows`` are the motors'
    volts with W (n, rows) their half-widths at no sag; a sag per grid point narrows those
    to W − sag, never below ``least``. The same speeds as ``fastest_speeds`` with the rows
    ``rows.rows`` gives at that sag.
    """

    def __init__(self, A, B, C, D, W, top, steps, voltage_rows=2, least=1e-3):
        self.voltage_rows, self.least = voltage_rows, float(least)
        self.W, self.top = kernel_array(W), kernel_array(top)
        sign = np.where(A >= 0.0, 1.0, -1.0)
        size = np.abs(A)
        self.sign_c = sign * C
        self.bounded = size > 1e-12
        with np.errstate(divide='ignore'):
            self.inverse = np.where(self.bounded, 1.0 / size, 0.0)
        j, m = np.nonzero(~np.eye(A.shape[-1], dtype=bool))     # every ordered pair of rows
        left, right = sign[:, j] * size[:, m], sign[:, m] * size[:, j]
        self.pairs = (np.require(j, np.int64, ['C', 'W']), np.require(m, np.int64, ['C', 'W']),
                      *(kernel_array(v) for v in (
                          size[:, m], size[:, j], left * B[:, j] - right * B[:, m],
                          left * D[:, j] - right * D[:, m], left * C[:, j] - right * C[:, m])))
        twice = 2.0 * np.asarray(steps, float)
        stage = twice[:, None]
        self.twice = twice
        inverse = self.inverse
        slope_x, slope_y = -sign * B * inverse, -sign * D * inverse
        # Per stage and row, as ``fastest_speeds``: slopes, constant (set per sag), α, β,
        # γ (set per sag) and |A| of the other end.
        self.backward = np.stack([slope_x[1:], slope_y[1:], slope_x[1:],
                                  stage * sign[:-1] * B[:-1] - size[:-1],
                                  stage * sign[:-1] * D[:-1], slope_x[1:], size[:-1]],
                                 axis=-1)
        self.forward = np.stack([slope_x[:-1], slope_y[:-1], slope_x[:-1],
                                 -(size[1:] + stage * sign[1:] * B[1:]),
                                 -stage * sign[1:] * D[1:], slope_x[:-1], size[1:]],
                                axis=-1)

    def speeds(self, sag_v=None, start_speed: float = 0.0) -> np.ndarray:
        """The fastest path speeds ṡ (n,) from ``start_speed`` to rest with the bus
        ``sag_v`` (n,) below its nominal voltage (None: none); NaN where the start speed is
        out of reach."""
        narrowed = sag_v is not None
        sag = kernel_array(sag_v if narrowed else np.zeros(len(self.twice) + 1))
        return _one_path(self.W, sag, narrowed, self.voltage_rows, self.least, *self.pairs,
                         self.top, self.sign_c, self.bounded, self.inverse, self.twice,
                         self.backward, self.forward, float(start_speed))


@kernel
def _one_path(W, sag, narrowed, voltage_rows, least, j, m, size_m, size_j, alpha, beta,
              constant, top, sign_c, bounded, inverse, twice, backward, forward,
              start_speed):
    """``OnePath.speeds`` compiled: the voltage rows' half-widths narrowed by the sag, the
    top speed over every pair of rows, the constants of the passes' rows that depend on
    them (in ``backward`` and ``forward``), then ``_passes_one_path``."""
    points, count = W.shape
    width = np.empty(count)
    low, high = np.empty((points, count)), np.empty((points, count))
    highest = np.empty(points)
    for i in range(points):
        for r in range(count):
            w = W[i, r]
            if narrowed and r < voltage_rows:
                w = w - sag[i]
                if w < least:
                    w = least
            width[r] = w
            low[i, r], high[i, r] = w + sign_c[i, r], w - sign_c[i, r]
        lowest_top = top[i]
        for p in range(len(j)):
            root = _first_positive_root(alpha[i, p], beta[i, p], width[j[p]] * size_m[i, p]
                                        + width[m[p]] * size_j[i, p] + constant[i, p])
            if root != root or root < lowest_top:
                lowest_top = root
        highest[i] = lowest_top
    for i in range(points - 1):
        for r in range(count):
            backward[i, r, 2] = -low[i + 1, r] * inverse[i + 1, r] if bounded[i + 1, r] \
                else -math.inf
            backward[i, r, 5] = twice[i] * low[i, r]
            forward[i, r, 2] = high[i, r] * inverse[i, r] if bounded[i, r] else math.inf
            forward[i, r, 5] = twice[i] * high[i + 1, r]
    speed, ceiling = _passes_one_path(backward, forward, highest, twice, start_speed)
    if start_speed > ceiling[0] * (1.0 + 1e-9) + 1e-12:
        speed[:] = math.nan
    return speed


def compile_passes() -> None:
    """Compile the passes now, for the arrays they are given (``bus.compile_kernels``)."""
    rows = np.zeros((1, 1, 1, 7))
    _passes_one_path(rows[0], rows[0], np.ones(2), np.ones(1), 0.0)
    one = np.ones((1, 2, 1))
    _fastest(one, one, one, one, np.ones(1), np.ones((1, 2)), np.ones(1), 0.0)
    path = OnePath(one[0], one[0], one[0], one[0], one[0], np.ones(2), np.ones(1), 1)
    path.speeds(np.ones(2))


@kernel
def _passes_one_path(backward, forward, top, twice, start_speed):
    """``fastest_speeds``' backward and forward passes for one path (compiled: a scalar
    recursion, stage after stage, that numpy cannot vectorise). Per stage and row: the s̈
    bound's slopes in x and y and its constant (braking at the stage's end for the backward
    pass, driving at its start for the forward one), then α, β, γ and |A| of the quadratic
    that bounds the speed at the stage's other end."""
    stages = len(top)
    inf = math.inf
    ceiling = np.zeros(stages)
    for i in range(stages - 2, -1, -1):
        y = ceiling[i + 1]
        x = y * y
        bound = top[i]
        brake = -inf
        for r in range(backward.shape[1]):
            slope_x, slope_y, constant, alpha, beta, gamma, size = backward[i, r]
            value = slope_x * x + slope_y * y + constant
            if value > brake:
                brake = value
            gamma += size * x
            discriminant = beta * beta - 4.0 * alpha * gamma
            if discriminant >= 0.0:
                denominator = math.sqrt(discriminant) - beta
                if denominator > 0.0 and 2.0 * gamma < bound * denominator:
                    bound = 2.0 * gamma / denominator
        slowest = x - twice[i] * brake
        slowest = math.sqrt(slowest) if slowest > 0.0 else 0.0
        ceiling[i] = bound if bound < slowest else slowest
    speed = np.zeros(stages)
    speed[0] = start_speed
    for i in range(stages - 1):
        y = speed[i]
        x = y * y
        push = inf
        reach = ceiling[i + 1]
        for r in range(forward.shape[1]):
            slope_x, slope_y, constant, alpha, beta, gamma, size = forward[i, r]
            value = slope_x * x + slope_y * y + constant
            if value < push:
                push = value
            gamma += size * x
            discriminant = beta * beta - 4.0 * alpha * gamma
            if discriminant >= 0.0:
                denominator = math.sqrt(discriminant) - beta
                if denominator > 0.0 and 2.0 * gamma < reach * denominator:
                    reach = 2.0 * gamma / denominator
        fastest = x + twice[i] * push
        top_next = ceiling[i + 1] * ceiling[i + 1]
        if fastest > top_next:
            fastest = top_next
        fastest = math.sqrt(fastest) if fastest > 0.0 else 0.0
        speed[i + 1] = fastest if fastest < reach else reach
    return speed, ceiling


def durations(steps, speeds):
    """Σ 2Δ/(ṡ_i + ṡ_i+1) per row; inf where the speed stalls (or is NaN)."""
    mean = speeds[:, 1:] + speeds[:, :-1]
    stalls = ~np.all(mean > 0.0, axis=1)
    return np.where(stalls, np.inf, np.sum(2.0 * np.asarray(steps) / np.where(
        stalls[:, None], 1.0, mean), axis=1))
