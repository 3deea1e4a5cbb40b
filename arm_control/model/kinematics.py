"""Planar two-link kinematics in arm_base: x forward, y up, angles counter-clockwise.

Joint angles q = (shoulder, elbow): shoulder from +x, elbow relative to the upper arm.
"""

from dataclasses import dataclass
import math

import numpy as np


class UnreachableError(ValueError):
    """The point lies outside the annulus the arm can reach."""


def wrap_angle(angle: float) -> float:
    """The same angle in [−π, π)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class TwoLinkKinematics:
    """Forward and inverse kinematics and the Jacobian of links ``upper_m`` and ``fore_m``."""

    upper_m: float
    fore_m: float

    @property
    def reach_m(self) -> tuple[float, float]:
        return abs(self.upper_m - self.fore_m), self.upper_m + self.fore_m

    def elbow_point(self, q) -> tuple[float, float]:
        return self.upper_m * math.cos(q[0]), self.upper_m * math.sin(q[0])

    def forward(self, q) -> tuple[float, float]:
        """(x, y) = (La cos θa + Lb cos(θa+θb), La sin θa + Lb sin(θa+θb))."""
        x_elbow, y_elbow = self.elbow_point(q)
        heading = q[0] + q[1]
        return x_elbow + self.fore_m * math.cos(heading), y_elbow + self.fore_m * math.sin(heading)

    def tool_pose(self, q) -> tuple[float, float, float]:
        """(x, y, yaw) with yaw = θa + θb, the forearm's heading: one-to-one with q."""
        x, y = self.forward(q)
        return x, y, wrap_angle(q[0] + q[1])

    def configuration_from_pose(self, x: float, y: float, yaw: float) -> tuple[float, float]:
        """Invert ``tool_pose``: the elbow sits ``fore_m`` behind the tool along yaw."""
        x_elbow, y_elbow = x - self.fore_m * math.cos(yaw), y - self.fore_m * math.sin(yaw)
        shoulder = math.atan2(y_elbow, x_elbow)
        return shoulder, wrap_angle(yaw - shoulder)

    def is_reachable(self, x: float, y: float, tolerance_m: float = 1e-9) -> bool:
        inner, outer = self.reach_m
        radius = math.hypot(x, y)
        return inner - tolerance_m <= radius <= outer + tolerance_m

    def inverse(self, x: float, y: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """Both solutions, elbow-positive first: θb = ±acos((x²+y²−La²−Lb²)/(2·La·Lb)),
        θa = atan2(y, x) − atan2(Lb sin θb, La + Lb cos θb).

        Raises UnreachableError, naming the point and the reach, outside the annulus.
        """
        if not (math.isfinite(x) and math.isfinite(y)):
            raise UnreachableError(f'point ({x}, {y}) is not finite')
        if not self.is_reachable(x, y):
            inner, outer = self.reach_m
            raise UnreachableError(
                f'point ({x:.3f}, {y:.3f}) m is {math.hypot(x, y):.3f} m from the shoulder; '
                f'the arm reaches {inner:.3f} to {outer:.3f} m')
        la, lb = self.upper_m, self.fore_m
        cos_elbow = (x * x + y * y - la * la - lb * lb) / (2.0 * la * lb)
        elbow = math.acos(min(1.0, max(-1.0, cos_elbow)))
        solutions = []
        for branch_elbow in (elbow, -elbow):
            shoulder = math.atan2(y, x) - math.atan2(lb * math.sin(branch_elbow),
                                                     la + lb * math.cos(branch_elbow))
            solutions.append((wrap_angle(shoulder), branch_elbow))
        return solutions[0], solutions[1]

    def jacobian(self, q) -> np.ndarray:
        """J = ∂(x, y)/∂(θa, θb)."""
        s_a, c_a = math.sin(q[0]), math.cos(q[0])
        s_ab, c_ab = math.sin(q[0] + q[1]), math.cos(q[0] + q[1])
        la, lb = self.upper_m, self.fore_m
        return np.array([[-la * s_a - lb * s_ab, -lb * s_ab],
                         [la * c_a + lb * c_ab, lb * c_ab]])

    def joint_velocity_for(self, q, tool_velocity, damping: float = 0.05) -> np.ndarray:
        """Damped least squares: q̇ = Jᵀ(J Jᵀ + λ²I)⁻¹ v, bounded near a singularity
        (arm straight or folded), exact (λ → 0) far from one."""
        jac = self.jacobian(q)
        return jac.T @ np.linalg.solve(jac @ jac.T + damping ** 2 * np.eye(2),
                                       np.asarray(tool_velocity, dtype=float))
