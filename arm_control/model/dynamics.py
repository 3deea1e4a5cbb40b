"""Coupled two-link arm dynamics driven by DC gearmotors (Pedersen, "Two jointed arm dynamics").

State x = [θa, θb, ωa, ωb] (shoulder, elbow relative to the upper arm; rad, rad/s);
input u = [Va, Vb] (volts at each joint's motors).

    M(θ)θ̈ + C(θ, θ̇)θ̇ + τg(θ) = τ_motor(V, θ̇) − τ_friction(θ̇)

The simulator integrates ``derivative``; the feedforward inverts the same model
(``voltage_for``) and the Kalman filter predicts with it.
"""

import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.motor import GearMotor

# Coulomb friction is smoothed as c·tanh(ω/ω_s) so that RK4 sees a continuous function.
COULOMB_SMOOTHING_RAD_S = 0.01


def rk4(f, x, u, dt):
    """One classical Runge-Kutta step of ẋ = f(x, u) with u held over the step."""
    k1 = f(x, u)
    k2 = f([xi + 0.5 * dt * ki for xi, ki in zip(x, k1)], u)
    k3 = f([xi + 0.5 * dt * ki for xi, ki in zip(x, k2)], u)
    k4 = f([xi + dt * ki for xi, ki in zip(x, k3)], u)
    return [xi + dt / 6.0 * (a + 2.0 * b + 2.0 * c + d)
            for xi, a, b, c, d in zip(x, k1, k2, k3, k4)]


class ArmDynamics:
    """M, C, τg of the arm, its motors and friction; forward and inverse dynamics."""

    def __init__(self, arm: ArmConfig):
        self.arm = arm
        upper, fore = arm.shoulder, arm.elbow
        ma, mb = upper.mass_kg, fore.mass_kg
        ra, rb = upper.com_from_joint_m, fore.com_from_joint_m
        la = upper.length_m
        self.gravity = arm.gravity_mps2
        # M00 = _m_base + 2·_m_coupling·cos θb, M01 = _m_elbow + _m_coupling·cos θb, M11 = _m_elbow
        self._m_base = (ma * ra ** 2 + mb * (la ** 2 + rb ** 2)
                        + upper.inertia_about_com_kgm2 + fore.inertia_about_com_kgm2)
        self._m_coupling = mb * la * rb
        self._m_elbow = mb * rb ** 2 + fore.inertia_about_com_kgm2
        self._g_shoulder = self.gravity * (ma * ra + mb * la)
        self._g_elbow = self.gravity * mb * rb
        self.motors = tuple(
            GearMotor.from_datasheet(arm.motor, joint.motor_count, joint.gear_ratio)
            for joint in arm.joints)
        self._viscous = tuple(j.viscous_friction_nm_s_per_rad for j in arm.joints)
        self._coulomb = tuple(j.coulomb_friction_nm for j in arm.joints)

    def mass_matrix(self, q) -> np.ndarray:
        m00, m01, m11 = self._mass(q[1])
        return np.array([[m00, m01], [m01, m11]])

    def _mass(self, elbow):
        coupling = self._m_coupling * math.cos(elbow)
        return self._m_base + 2.0 * coupling, self._m_elbow + coupling, self._m_elbow

    def coriolis_torque(self, q, qd) -> tuple[float, float]:
        """C(θ, θ̇)θ̇ with C = h·[[−θ̇b, −(θ̇a + θ̇b)], [θ̇a, 0]], h = mb·La·rb·sin θb."""
        h = self._m_coupling * math.sin(q[1])
        return (-h * qd[1] * qd[0] - h * (qd[0] + qd[1]) * qd[1], h * qd[0] * qd[0])

    def gravity_torque(self, q) -> tuple[float, float]:
        """τg = [g cos θa (ma ra + mb La) + mb rb g cos(θa+θb), mb rb g cos(θa+θb)]."""
        outer = self._g_elbow * math.cos(q[0] + q[1])
        return (self._g_shoulder * math.cos(q[0]) + outer, outer)

    def friction_torque(self, qd) -> tuple[float, float]:
        """Torque friction takes from each joint: b·ω + c·tanh(ω/ω_s) (elbow ω relative)."""
        return tuple(b * w + c * math.tanh(w / COULOMB_SMOOTHING_RAD_S)
                     for b, c, w in zip(self._viscous, self._coulomb, qd))

    def motor_torque(self, qd, voltage) -> tuple[float, float]:
        return (self.motors[0].torque_nm(voltage[0], qd[0]),
                self.motors[1].torque_nm(voltage[1], qd[1]))

    def joint_torque(self, qd, voltage) -> tuple[float, float]:
        """Net drive torque at each joint: motors less friction."""
        motor, friction = self.motor_torque(qd, voltage), self.friction_torque(qd)
        return motor[0] - friction[0], motor[1] - friction[1]

    def acceleration(self, q, qd, torque) -> tuple[float, float]:
        """Forward dynamics: θ̈ = M⁻¹(τ − Cθ̇ − τg)."""
        m00, m01, m11 = self._mass(q[1])
        cor, grav = self.coriolis_torque(q, qd), self.gravity_torque(q)
        r0 = torque[0] - cor[0] - grav[0]
        r1 = torque[1] - cor[1] - grav[1]
        det = m00 * m11 - m01 * m01
        return (m11 * r0 - m01 * r1) / det, (m00 * r1 - m01 * r0) / det

    def inverse_dynamics(self, q, qd, qdd) -> tuple[float, float]:
        """τ = M(θ)θ̈ + C(θ, θ̇)θ̇ + τg(θ): the net joint torque a motion needs."""
        m00, m01, m11 = self._mass(q[1])
        cor, grav = self.coriolis_torque(q, qd), self.gravity_torque(q)
        return (m00 * qdd[0] + m01 * qdd[1] + cor[0] + grav[0],
                m01 * qdd[0] + m11 * qdd[1] + cor[1] + grav[1])

    def voltage_for(self, q, qd, qdd) -> tuple[float, float]:
        """Feedforward: the motor voltages that produce θ̈ at (θ, θ̇), friction included."""
        needed = self.inverse_dynamics(q, qd, qdd)
        friction = self.friction_torque(qd)
        return (self.motors[0].voltage_for(needed[0] + friction[0], qd[0]),
                self.motors[1].voltage_for(needed[1] + friction[1], qd[1]))

    def derivative(self, x, u) -> list[float]:
        """f(x, u) = [θ̇, θ̈] with u the motor voltages."""
        qd = (x[2], x[3])
        acc = self.acceleration(x, qd, self.joint_torque(qd, u))
        return [x[2], x[3], acc[0], acc[1]]

    def derivative_with_torque(self, x, torque) -> list[float]:
        """f(x, τ) = [θ̇, θ̈] with τ applied directly at the joints (no motor, no friction)."""
        acc = self.acceleration(x, (x[2], x[3]), torque)
        return [x[2], x[3], acc[0], acc[1]]

    def energy_j(self, x) -> float:
        """Kinetic ½θ̇ᵀMθ̇ plus potential energy (zero at the shoulder's height)."""
        m00, m01, m11 = self._mass(x[1])
        kinetic = 0.5 * (m00 * x[2] ** 2 + 2.0 * m01 * x[2] * x[3] + m11 * x[3] ** 2)
        potential = (self._g_shoulder * math.sin(x[0])
                     + self._g_elbow * math.sin(x[0] + x[1]))
        return kinetic + potential
