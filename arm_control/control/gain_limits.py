"""How much PID gain a joint's loop can hold at its rate with one period of delay.

Each joint alone, as its motors see it: the inertia J about the joint, the least over the
elbow's angles with the other joint free (J = 1/(M⁻¹)ᵢᵢ = det M / Mⱼⱼ: a lighter load is a
larger loop gain), driven through the motor model τ = (V − e·θ̇)/k (``GearMotor``):

    J·θ̈ = V/k − (e/k + b)·θ̇            (b: viscous friction)

Gravity and Coulomb friction are offsets that the feedforward and the integrator take; they
do not move the poles. The command is held over each period T (zero-order hold), so with
x = [θ, θ̇], x[k+1] = Φ·x[k] + Γ·u[k], (Φ, Γ) = the exact discretisation. One period of
delay: the command applied over period k was computed from the reading of period k − 1. The
PID on that reading, holding θ = 0 (the integral kept in volts, as ``JointPid`` does):

    v[k] = −kp·θ[k] − kd·θ̇[k] + z[k],   z[k+1] = z[k] − ki·T·θ[k],   u[k+1] = v[k]

The closed loop's state is [θ, θ̇, u, z] and it is stable iff every eigenvalue of

    [[Φ,              Γ, 0],
     [−kp, −kd,       0, 1],
     [−ki·T, 0,       0, 1]]

lies inside the unit circle. ``instability_scale`` is the least s > 0 at which s·(kp, ki, kd)
is unstable, and gains are accepted only below it (s > 1). The margin is in the model: the
least inertia, and a whole period of delay where the real loop's is a fraction of one (the
estimate is predicted to when the command acts). The simulated arm's hold stays stable up to
about twice this bound and rings at the battery's volts at three times it
(``test_gain_limits``).
"""

import math
from typing import Optional

import numpy as np
from scipy.linalg import expm

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.model.dynamics import ArmDynamics
from arm_control.parameters import ParameterError

# The elbow angles over which the least inertia is sought (rad), and the scales searched.
ELBOW_SAMPLES = 73
SMALLEST_SCALE, LARGEST_SCALE, SCALE_STEP = 1e-9, 1e6, 2.0
STABLE_RADIUS = 1.0


def least_inertia_kgm2(dynamics: ArmDynamics) -> tuple[float, float]:
    """Each joint's least inertia over the elbow's angles, the other joint free (kg·m²)."""
    elbows = np.linspace(-math.pi, math.pi, ELBOW_SAMPLES)
    least = [math.inf, math.inf]
    for elbow in elbows:
        m = dynamics.mass_matrix((0.0, elbow))
        det = m[0, 0] * m[1, 1] - m[0, 1] ** 2
        least = [min(least[0], det / m[1, 1]), min(least[1], det / m[0, 0])]
    return least[0], least[1]


class JointLoop:
    """One joint's discrete loop at ``period_s``: ``radius(gains)``, the largest pole's
    magnitude; ``instability_scale(gains)``."""

    def __init__(self, inertia_kgm2: float, volts_per_nm: float, emf_v_per_rad_s: float,
                 viscous_nm_s_per_rad: float, period_s: float):
        b_v = 1.0 / (volts_per_nm * inertia_kgm2)                  # rad/s² per volt
        a_s = (emf_v_per_rad_s / volts_per_nm + viscous_nm_s_per_rad) / inertia_kgm2
        continuous = np.zeros((3, 3))
        continuous[0, 1], continuous[1, 1], continuous[1, 2] = 1.0, -a_s, b_v
        discrete = expm(continuous * period_s)       # [Φ Γ; 0 1]: the held command
        self.phi, self.gamma = discrete[:2, :2], discrete[:2, 2]
        self.period_s = period_s

    def radius(self, gains) -> float:
        kp, ki, kd = gains
        closed = np.zeros((4, 4))
        closed[:2, :2], closed[:2, 2] = self.phi, self.gamma
        closed[2] = (-kp, -kd, 0.0, 1.0)
        closed[3] = (-ki * self.period_s, 0.0, 0.0, 1.0)
        # A state nothing feeds back is no part of the loop: the integral without ki, the
        # angle without kp and ki (damping alone leaves where the arm rests free).
        keep = [i for i, used in enumerate((kp or ki, True, True, ki)) if used]
        closed = closed[np.ix_(keep, keep)]
        return float(np.max(np.abs(np.linalg.eigvals(closed))))

    def instability_scale(self, gains) -> float:
        """The least s with s·gains unstable, from s = 1 doubled or halved to the edge, then
        bisected: inf if none up to LARGEST_SCALE, 0 if unstable down to SMALLEST_SCALE."""
        gains = np.asarray(gains, float)
        if not np.any(gains):
            return math.inf                          # no feedback: nothing to bound
        low = high = 1.0
        if self.radius(gains) < STABLE_RADIUS:
            while self.radius(high * gains) < STABLE_RADIUS:
                low, high = high, high * SCALE_STEP
                if high > LARGEST_SCALE:
                    return math.inf
        else:
            while self.radius(low * gains) >= STABLE_RADIUS:
                low, high = low / SCALE_STEP, low
                if low < SMALLEST_SCALE:
                    return 0.0
        for _ in range(40):
            middle = math.sqrt(low * high)
            if self.radius(middle * gains) < STABLE_RADIUS:
                low = middle
            else:
                high = middle
        return high


def joint_loops(arm: ArmConfig, period_s: float) -> tuple[JointLoop, JointLoop]:
    dynamics = ArmDynamics(arm)
    return tuple(JointLoop(inertia, k, e, b, period_s) for inertia, k, e, b in zip(
        least_inertia_kgm2(dynamics), dynamics.volts_per_nm, dynamics.emf_v_per_rad_s,
        dynamics.viscous))


def gain_problem(arm: ArmConfig, config: ControllerConfig) -> Optional[str]:
    """Why a joint's gains are more than its loop holds (the parameter, its value and the
    bound), or None."""
    for joint, loop, name in zip(arm.joints, joint_loops(arm, config.period_s),
                                 ('shoulder_pid', 'elbow_pid')):
        gains = getattr(config, name)
        scale = loop.instability_scale(gains)
        if scale > 1.0:
            continue
        if scale == 0.0:
            return (f"parameter '{name}' = {list(gains)}: the {joint.name}'s loop at "
                    f'{config.loop_rate_hz:g} Hz is unstable at any scale of these gains')
        bound = [float(f'{g * scale:.4g}') for g in gains]
        return (f"parameter '{name}' = {list(gains)}: the {joint.name}'s loop at "
                f'{config.loop_rate_hz:g} Hz with one period of delay goes unstable at '
                f'{scale:.4g} times these gains, {bound}: keep below that')
    return None


def check_gains(arm: ArmConfig, config: ControllerConfig) -> None:
    """Raise ``ParameterError`` with ``gain_problem``'s reason."""
    problem = gain_problem(arm, config)
    if problem is not None:
        raise ParameterError(problem)
