"""The filter's step, linearised: A = ∂f/∂x of the arm's model (``ArmDynamics``) at the
step's start, and what RK4's substeps make of ẋ = f(x₀) + A (x − x₀): the covariance's F
and, near rest, the mean itself (``ArmEstimator``, estimator.py)."""

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.dynamics import COULOMB_SMOOTHING_RAD_S

# Relative finite-difference step of the Jacobian ∂f/∂x.
JACOBIAN_STEP = 1e-6
# A = ∂f/∂x is kept from an earlier step while the joints, the command and the bus stay
# within these of where it was taken (rad, rad/s, V): A moves with cos θ, with ω (the
# Coriolis terms) and with the torque (∂M⁻¹/∂θb·τ), each by under 1 % of itself there, and
# a held arm does not pay five model calls a period for it (test_estimator: the estimate
# moves by under 1e-5 of a unit). Coulomb friction's tanh(ω/ω_s) bends A within ω_s of 0:
# with it, ω must stay within a tenth of ω_s.
F_KEPT_RAD, F_KEPT_RAD_S, F_KEPT_V = 1e-3, 5e-2, 0.25
# Steps this close in length are the same step: a step's two ends are often one robot instant
# found two ways (the learned loop, a reading's stamp), which on a clock of ~1e9 s differ by
# rounding, ~1e-7 s (the state moves by ω times it).
SAME_STEP_S = 1e-6


class StepLinearisation:
    """A (4×4) kept while the step stays within ``bounds`` of where it was taken
    ([θa, θb, ωa, ωb, Va, Vb, V_bus]); the maps of RK4's substeps on it."""

    def __init__(self, arm: ArmConfig):
        speed = F_KEPT_RAD_S if not any(j.coulomb_friction_nm for j in arm.joints) \
            else min(F_KEPT_RAD_S, 0.1 * COULOMB_SMOOTHING_RAD_S)
        self.bounds = (F_KEPT_RAD,) * 2 + (speed,) * 2 + (F_KEPT_V,) * 3
        self._lower = [j.min_angle_rad for j in arm.joints]
        self._upper = [j.max_angle_rad for j in arm.joints]
        self.at = self.a = None         # (supply, (joints, command, bus)), its A
        self._maps = None               # ((A, step, substeps), (F, Φ, Γ)) of the last

    def moved(self, f, joint, voltage, substeps):
        """RK4's substeps on ẋ = f(x₀) + A (x − x₀) from x₀ = ``joint``: x − x₀ = Σₖ Φᵏ Γ f(x₀)
        over k < n, Φ and Γ a substep's (``transition``); None where the step ends beyond
        A's bounds or past a stop."""
        _, phi, gamma = self._maps[1]
        step = gamma @ np.array(f(joint, voltage))
        moved = step
        for _ in range(substeps - 1):
            moved = phi @ moved + step
        end = [a + b for a, b in zip(joint, moved.tolist())]
        at = self.at[1]
        for i in range(4):
            if abs(end[i] - at[i]) > self.bounds[i]:
                return None
        for i in range(2):
            if not self._lower[i] <= end[i] <= self._upper[i]:
                return None
        return end

    def transition(self, f, joint, voltage, bus, supply, step_s, substeps) -> np.ndarray:
        """The 6×6 F of RK4 substeps from ``joint`` [θa, θb, ωa, ωb] under ``voltage``.

        A = ∂f/∂x by finite differences at the step's start, kept from an earlier step while
        the joints, the command and the bus stay within the ``bounds`` of where it was
        taken (same supply). One substep of ẋ ≈ A x maps by Φ = I + Ah + (Ah)²/2 + (Ah)³/6 +
        (Ah)⁴/24 (RK4 on a linear system), so F = Φⁿ; plain numpy, cheaper and steadier
        under load than scipy's expm. Γ = h (I + Ah/2 + (Ah)²/6 + (Ah)³/24) is what a
        substep adds of a constant ẋ. The same A over the same substeps (within
        SAME_STEP_S) gives the same maps.
        """
        at = (*joint, *voltage, bus)
        if self.at is None or self.at[0] is not supply or any(
                abs(a - b) > bound for a, b, bound in zip(at, self.at[1], self.bounds)):
            self.at, self.a = (supply, at), self.jacobian(f, joint, voltage)
        if self._maps is not None:
            (a, kept_step_s, kept_substeps), maps = self._maps
            if a is self.a and kept_substeps == substeps and \
                    abs(kept_step_s - step_s) * substeps <= SAME_STEP_S:
                return maps[0]
        ah = self.a * step_s
        ah2 = ah @ ah
        gamma = step_s * (_EYE4 + ah / 2.0 + ah2 @ (_EYE4 / 6.0 + ah / 24.0))
        phi = _EYE4 + ah @ (gamma / step_s)
        transition = _EYE6.copy()
        transition[:4, :4] = np.linalg.matrix_power(phi, substeps)
        self._maps = (self.a, step_s, substeps), (transition, phi, gamma)
        return transition

    @staticmethod
    def jacobian(f, joint, voltage) -> np.ndarray:
        """A = ∂f/∂x (4×4) at ``joint`` under ``voltage``, by forward differences."""
        f0 = f(joint, voltage)
        columns = []
        for i in range(4):
            delta = JACOBIAN_STEP * max(1.0, abs(joint[i]))
            shifted = list(joint)
            shifted[i] += delta
            columns.append([(a - b) / delta for a, b in zip(f(shifted, voltage), f0)])
        return np.array(columns).T


_EYE4, _EYE6 = np.eye(4), np.eye(6)
