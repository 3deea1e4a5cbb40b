"""The arm's limits along a path, as rows in the path speed: what both timings impose.

Along q(σ), with y = ṡ, x = ṡ² and u = s̈: q̇ = q'·y and q̈ = q'·u + q''·x, so each joint's
motor torque, in volts of its motors (k = R/(n·G·Kt), ``ArmDynamics.volts_per_nm``), is

    T = k·(M q̈ + C q̇ + τg + τ_friction) = a·u + b·x + c + d·y + k·c_coulomb·tanh(q'y/ω_s),
    a = k·M q',  b = k·(M q'' + C(q, q')q'),  c = k·τg,  d = k·b_viscous·q',

from ``ArmDynamics``' batch forms. The motor voltage is V = T + e·q'·y (e: back-EMF volts
per rad/s) and each motor's current I = T/R. The rows, each A·u + B·x + C + D·y within ±W:

- voltage: V within the (driving, braking) window of the bus less the reserves (W = 1);
- current: T within the window of I_limit·R less the reserves (W = 1; no row without a
  limit);
- supply: Σ n·|I| = |n_a·T_a/R_a ± n_b·T_b/R_b| within what keeps the bus above the floor
  (``TrajectoryLimits.supply_current_a``; no rows when the current limits already do);
- acceleration: q̈ within its cap (W = the cap; no row when the cap is inf).

Coulomb friction enters as c·sign(q'), its value at speed, or as its tanh at given speeds.
"""

import numpy as np

from arm_control.model.dynamics import ArmDynamics, COULOMB_SMOOTHING_RAD_S
from arm_control.timing.limits import TrajectoryLimits, window

# A window never narrower than this (V) in the rows: a bus sagging to nothing is refused by
# the final check, not divided by.
LEAST_HALF_WIDTH_V = 1e-3


class PathTerms:
    """a, b, c, d of T and e·q' of the back-EMF at path samples q, q', q'' of shape
    (..., n, 2)."""

    def __init__(self, dynamics: ArmDynamics, q, dq, ddq):
        self.dynamics = dynamics
        self.q, self.dq, self.ddq = q, dq, ddq
        k = np.array(dynamics.volts_per_nm)
        self.a = k * dynamics.mass_times(q, dq)
        self.b = k * (dynamics.mass_times(q, ddq) + dynamics.coriolis(q, dq))
        self.c = k * dynamics.gravity(q)
        self.d = k * np.array(dynamics.viscous) * dq
        self.emf = np.array(dynamics.emf_v_per_rad_s) * dq
        self.coulomb_v = k * np.array(dynamics.coulomb)

    @classmethod
    def along(cls, dynamics: ArmDynamics, path, grid) -> 'PathTerms':
        return cls(dynamics, path(grid), path(grid, 1), path(grid, 2))

    def coulomb(self, speed=None):
        """k·c·tanh(q'ṡ/ω_s) at path speeds ``speed`` (..., n); c·sign(q') when None."""
        if speed is None:
            return self.coulomb_v * np.sign(self.dq)
        return self.coulomb_v * np.tanh(self.dq * speed[..., None] / COULOMB_SMOOTHING_RAD_S)

    def torque_volts(self, u, x):
        """T (..., n, 2) for s̈ = u and ṡ² = x on the samples, friction exact."""
        speed = np.sqrt(np.maximum(x, 0.0))
        return (self.a * u[..., None] + self.b * x[..., None] + self.c
                + self.d * speed[..., None] + self.coulomb(speed))

    def voltage(self, u, x):
        """V = T + e·q'·ṡ (..., n, 2): ``ArmDynamics.voltages`` along the path."""
        return self.torque_volts(u, x) + self.emf * np.sqrt(np.maximum(x, 0.0))[..., None]


def rows(terms: PathTerms, limits: TrajectoryLimits, sag_v=0.0, margin_v=0.0,
         coulomb_speed=None, per_point=False):
    """The rows (A, B, C, D of shape (..., n, rows); W (rows,)) of every limit at once.

    ``sag_v`` (scalar or (..., n)): how far the bus sits below its nominal voltage;
    ``margin_v`` (scalar or (..., n)): volts kept back from every voltage and current
    window besides the reserves (the final check's tightening); ``coulomb_speed``: the
    speeds at which Coulomb friction is taken (None: at speed, c·sign(q')). ``per_point``:
    the two voltage rows (the first two) left in volts, W then (..., n, rows) with their
    half-widths as they are, not held above the least (``exact.OnePath`` narrows them by a
    sag per point).
    """
    dq, ddq = terms.dq, terms.ddq
    friction = terms.coulomb(coulomb_speed)
    torque = (terms.a, terms.b, terms.c + friction, terms.d)     # T's u, x, 1 and y terms
    driving, braking = limits.budget
    margin_v = np.asarray(margin_v, float)
    sag = np.asarray(sag_v, float)[..., None] + margin_v[..., None]
    centre, half = window(dq, driving - sag, braking - sag)
    scale = 1.0 if per_point else np.maximum(half, LEAST_HALF_WIDTH_V)
    A, B = [terms.a / scale], [terms.b / scale]
    C, D = [(torque[2] - centre) / scale], [(terms.d + terms.emf) / scale]
    W = [half if per_point else np.ones(2)]
    for j, (drive, brake) in enumerate(limits.current_budget_v):
        if np.isfinite(drive):
            centre_j, half_j = window(dq[..., j], drive - margin_v, brake - margin_v)
            half_j = np.maximum(half_j, LEAST_HALF_WIDTH_V)[..., None]
            for out, term in zip((A, B, C, D), torque):
                out.append(term[..., j:j + 1] / half_j)
            C[-1] = C[-1] - centre_j[..., None] / half_j
            W.append(np.ones(1))
    total = limits.supply_current_a()
    if np.isfinite(total):
        amps = np.array([m.count / m.resistance_ohm for m in limits.supply.motors]) / total
        for sides in ((1.0, 1.0), (1.0, -1.0)):
            weights = amps * sides
            for out, term in zip((A, B, C, D), torque):
                out.append(np.sum(term * weights, axis=-1, keepdims=True))
            W.append(np.ones(1))
    for j, cap in enumerate(limits.max_acceleration_rad_s2):
        if np.isfinite(cap):
            A.append(dq[..., j:j + 1])
            B.append(ddq[..., j:j + 1])
            C.append(np.zeros_like(dq[..., j:j + 1]))
            D.append(np.zeros_like(dq[..., j:j + 1]))
            W.append(np.full(1, float(cap)))
    A, B, C, D = (np.concatenate(v, axis=-1) for v in (A, B, C, D))
    if per_point:
        W = np.concatenate([np.broadcast_to(w, A.shape[:-1] + w.shape[-1:]) for w in W],
                           axis=-1)
    else:
        W = np.concatenate(W)
    return A, B, C, D, W


def speed_caps(limits: TrajectoryLimits, dq) -> np.ndarray:
    """The fastest path speed the joint speed caps allow at each sample (inf: no cap)."""
    caps = np.array(limits.max_velocity_rad_s, float)
    with np.errstate(divide='ignore'):
        return np.min(np.where(np.abs(dq) > 1e-12, caps / np.abs(dq), np.inf), axis=-1)
