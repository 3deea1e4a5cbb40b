"""The one model of the arm: coupled two-link dynamics driven by DC gearmotors (Pedersen,
"Two jointed arm dynamics"; DESIGN.md §4).

State x = [θa, θb, ωa, ωb] (shoulder, elbow relative to the upper arm; rad, rad/s);
input u = [Va, Vb] (volts applied to each joint's motors).

    M(θ)θ̈ + C(θ, θ̇)θ̇ + τg(θ) = τ_motor(V, θ̇) − τ_friction(θ̇)

with Pedersen's structure M00 = α + 2β·cos θb, M01 = γ + β·cos θb, M11 = γ,
C(θ, θ̇)θ̇ = β·sin θb·[−θ̇b·θ̇a − (θ̇a + θ̇b)·θ̇b, θ̇a²],
τg = [G_upper·cos θa + G_fore·cos(θa + θb), G_fore·cos(θa + θb)],
τ_motor = (V − e·θ̇)/k per joint (``GearMotor``) and τ_friction = b·θ̇ + c·tanh(θ̇/ω_s).

Everything that needs the arm's physics uses this class: the sim integrates ``derivative``,
the Kalman filter predicts with it, the feedforward and the trajectory timing invert it
(``voltage_for``, ``voltages``) and the benches check against it. Each equation has a scalar
form (plain floats: the sim steps it a thousand times a second) and a batch form on arrays of
shape (..., 2) or (..., 4) (the timing evaluates thousands of states at once); a test holds
the two equal.
"""

import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.motor import GearMotor

# Coulomb friction is smoothed as c·tanh(ω/ω_s) so that RK4 sees a continuous function.
COULOMB_SMOOTHING_RAD_S = 0.01
# RK4 decays a mode ẋ = −λx only for h·λ below 2.785; steps keep h·λ within this.
RK4_STABLE_STEP = 2.5


def rk4(f, x, u, dt):
    """One classical Runge-Kutta step of ẋ = f(x, u) with u held over the step, for a state
    as a list of floats."""
    k1 = f(x, u)
    k2 = f([xi + 0.5 * dt * ki for xi, ki in zip(x, k1)], u)
    k3 = f([xi + 0.5 * dt * ki for xi, ki in zip(x, k2)], u)
    k4 = f([xi + dt * ki for xi, ki in zip(x, k3)], u)
    return [xi + dt / 6.0 * (a + 2.0 * b + 2.0 * c + d)
            for xi, a, b, c, d in zip(x, k1, k2, k3, k4)]


def rk4_batch(f, x, u, dt):
    """The same step for states as an array (..., 4)."""
    k1 = f(x, u)
    k2 = f(x + 0.5 * dt * k1, u)
    k3 = f(x + 0.5 * dt * k2, u)
    k4 = f(x + dt * k3, u)
    return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


class ArmDynamics:
    """M, C, τg of the arm, its motors and friction; forward and inverse dynamics."""

    def __init__(self, arm: ArmConfig):
        self.arm = arm
        upper, fore = arm.shoulder, arm.elbow
        ma, mb = upper.mass_kg, fore.mass_kg
        ra, rb = upper.com_from_joint_m, fore.com_from_joint_m
        la = upper.length_m
        g = arm.gravity_mps2
        self.alpha = (ma * ra ** 2 + mb * (la ** 2 + rb ** 2)
                      + upper.inertia_about_com_kgm2 + fore.inertia_about_com_kgm2)
        self.beta = mb * la * rb
        self.gamma = mb * rb ** 2 + fore.inertia_about_com_kgm2
        self.g_upper = g * (ma * ra + mb * la)
        self.g_fore = g * mb * rb
        self.motors = tuple(GearMotor.from_datasheet(joint.motor, joint.motor_count,
                                                     joint.gear_ratio) for joint in arm.joints)
        self.viscous = tuple(j.viscous_friction_nm_s_per_rad for j in arm.joints)
        self.coulomb = tuple(j.coulomb_friction_nm for j in arm.joints)
        self.volts_per_nm = tuple(m.volts_per_nm for m in self.motors)          # k
        self.emf_v_per_rad_s = tuple(m.back_emf_v_per_rad_s for m in self.motors)  # e
        self._k = np.array(self.volts_per_nm)
        self._e = np.array(self.emf_v_per_rad_s)
        self._b = np.array(self.viscous)
        self._c = np.array(self.coulomb)
        self._scalars = (self.volts_per_nm, self.emf_v_per_rad_s, self.viscous, self.coulomb)

    # ---------------------------------------------------------------- scalar forms

    def _mass(self, elbow):
        coupling = self.beta * math.cos(elbow)
        return self.alpha + 2.0 * coupling, self.gamma + coupling, self.gamma

    def mass_matrix(self, q) -> np.ndarray:
        m00, m01, m11 = self._mass(q[1])
        return np.array([[m00, m01], [m01, m11]])

    def coriolis_torque(self, q, qd) -> tuple[float, float]:
        """C(θ, θ̇)θ̇ with C = h·[[−θ̇b, −(θ̇a + θ̇b)], [θ̇a, 0]], h = β·sin θb."""
        h = self.beta * math.sin(q[1])
        return (-h * qd[1] * qd[0] - h * (qd[0] + qd[1]) * qd[1], h * qd[0] * qd[0])

    def gravity_torque(self, q) -> tuple[float, float]:
        """τg = [G_upper·cos θa + G_fore·cos(θa+θb), G_fore·cos(θa+θb)]."""
        fore = self.g_fore * math.cos(q[0] + q[1])
        return (self.g_upper * math.cos(q[0]) + fore, fore)

    def friction_torque(self, qd) -> tuple[float, float]:
        """Torque friction takes from each joint: b·ω + c·tanh(ω/ω_s) (elbow ω relative)."""
        return tuple(b * w + c * math.tanh(w / COULOMB_SMOOTHING_RAD_S)
                     for b, c, w in zip(self.viscous, self.coulomb, qd))

    def motor_torque(self, qd, voltage) -> tuple[float, float]:
        return (self.motors[0].torque_nm(voltage[0], qd[0]),
                self.motors[1].torque_nm(voltage[1], qd[1]))

    def acceleration(self, q, qd, torque) -> tuple[float, float]:
        """Forward dynamics: θ̈ = M⁻¹(τ − Cθ̇ − τg), τ the net drive torque."""
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
        """f(x, u) = [θ̇, θ̈] with u the applied motor voltages: ``acceleration`` of the
        motor torque (V − e·ω)/k less the friction, written out in one body (the sim and
        the filter evaluate it thousands of times a second; a test holds it to the parts)."""
        q0, q1, w0, w1 = x[0], x[1], x[2], x[3]
        (k0, k1), (e0, e1), (b0, b1), (c0, c1) = self._scalars
        torque0 = (u[0] - e0 * w0) / k0 - (b0 * w0 + c0 * math.tanh(w0 / COULOMB_SMOOTHING_RAD_S))
        torque1 = (u[1] - e1 * w1) / k1 - (b1 * w1 + c1 * math.tanh(w1 / COULOMB_SMOOTHING_RAD_S))
        coupling = self.beta * math.cos(q1)
        m00, m01, m11 = self.alpha + 2.0 * coupling, self.gamma + coupling, self.gamma
        h = self.beta * math.sin(q1)
        fore = self.g_fore * math.cos(q0 + q1)
        r0 = torque0 - (-h * w1 * w0 - h * (w0 + w1) * w1) - (self.g_upper * math.cos(q0) + fore)
        r1 = torque1 - h * w0 * w0 - fore
        det = m00 * m11 - m01 * m01
        return [w0, w1, (m11 * r0 - m01 * r1) / det, (m00 * r1 - m01 * r0) / det]

    def derivative_with_torque(self, x, torque) -> list[float]:
        """f(x, τ) = [θ̇, θ̈] with τ applied directly at the joints (no motor, no friction)."""
        acc = self.acceleration(x, (x[2], x[3]), torque)
        return [x[2], x[3], acc[0], acc[1]]

    def energy_j(self, x) -> float:
        """Kinetic ½θ̇ᵀMθ̇ plus potential energy (zero at the shoulder's height)."""
        m00, m01, m11 = self._mass(x[1])
        kinetic = 0.5 * (m00 * x[2] ** 2 + 2.0 * m01 * x[2] * x[3] + m11 * x[3] ** 2)
        potential = self.g_upper * math.sin(x[0]) + self.g_fore * math.sin(x[0] + x[1])
        return kinetic + potential

    def stiffest_rate_per_s(self, samples: int = 73) -> float:
        """The fastest decay of the arm near rest, the largest λ of D v = λ M(θb) v over the
        elbow's angle, D = diag(b + c/ω_s + e/k): Coulomb friction's slope c/ω_s at ω = 0,
        viscous friction and the motors' back-EMF, each a damping (N m s/rad)."""
        damping = self._b + self._c / COULOMB_SMOOTHING_RAD_S + self._e / self._k
        fastest = 0.0
        for elbow in np.linspace(-math.pi, math.pi, samples):
            m00, m01, m11 = self._mass(elbow)
            mass = np.array([[m00, m01], [m01, m11]])
            fastest = max(fastest, float(np.max(np.real(np.linalg.eigvals(
                np.linalg.solve(mass, np.diag(damping)))))))
        return fastest

    def stable_step_s(self, max_step_s: float) -> float:
        """The longest RK4 step up to ``max_step_s`` with h·λ ≤ ``RK4_STABLE_STEP`` at the
        stiffest rate: longer ones grow, not damp, the speed near rest."""
        return min(float(max_step_s), RK4_STABLE_STEP / self.stiffest_rate_per_s())

    def free_speed_rad_s(self, voltage: float) -> np.ndarray:
        """Per joint, the speed at which ``voltage`` only balances the motors' back-EMF."""
        return np.array([motor.free_speed_rad_s(voltage) for motor in self.motors])

    # ---------------------------------------------------------------- batch forms

    def mass_times(self, q, v) -> np.ndarray:
        """M(q)·v for arrays q, v of shape (..., 2)."""
        cos_b = np.cos(q[..., 1])
        m00, m01 = self.alpha + 2.0 * self.beta * cos_b, self.gamma + self.beta * cos_b
        return np.stack([m00 * v[..., 0] + m01 * v[..., 1],
                         m01 * v[..., 0] + self.gamma * v[..., 1]], axis=-1)

    def coriolis(self, q, qd) -> np.ndarray:
        """C(q, q̇)q̇, (..., 2)."""
        h = self.beta * np.sin(q[..., 1])
        return np.stack([-h * qd[..., 1] * qd[..., 0] - h * (qd[..., 0] + qd[..., 1])
                         * qd[..., 1], h * qd[..., 0] ** 2], axis=-1)

    def gravity(self, q) -> np.ndarray:
        """τg(q), (..., 2)."""
        fore = self.g_fore * np.cos(q[..., 0] + q[..., 1])
        return np.stack([self.g_upper * np.cos(q[..., 0]) + fore, fore], axis=-1)

    def friction(self, qd) -> np.ndarray:
        """b·q̇ + c·tanh(q̇/ω_s), (..., 2)."""
        return self._b * qd + self._c * np.tanh(qd / COULOMB_SMOOTHING_RAD_S)

    def _friction_column(self, joint: int, w):
        """b·ω + c·tanh(ω/ω_s) of one joint, for a column of speeds."""
        b, c = self.viscous[joint], self.coulomb[joint]
        return b * w + c * np.tanh(w / COULOMB_SMOOTHING_RAD_S) if c else b * w

    def voltages(self, q, qd, qdd) -> np.ndarray:
        """``voltage_for`` on arrays (..., 2): V = k·(M q̈ + C q̇ + τg + τ_friction) + e·q̇."""
        q, qd, qdd = (np.asarray(v, float) for v in (q, qd, qdd))
        q0, q1, w0, w1, a0, a1 = q[..., 0], q[..., 1], qd[..., 0], qd[..., 1], qdd[..., 0], \
            qdd[..., 1]
        cos_b = np.cos(q1)
        h = self.beta * np.sin(q1)
        fore = self.g_fore * np.cos(q0 + q1)
        m01 = self.gamma + self.beta * cos_b
        torque0 = ((self.alpha + 2.0 * self.beta * cos_b) * a0 + m01 * a1
                   - h * w1 * (2.0 * w0 + w1) + self.g_upper * np.cos(q0) + fore
                   + self._friction_column(0, w0))
        torque1 = m01 * a0 + self.gamma * a1 + h * w0 * w0 + fore + self._friction_column(1, w1)
        out = np.empty(np.broadcast_shapes(q.shape, qd.shape, qdd.shape))
        out[..., 0] = self.volts_per_nm[0] * torque0 + self.emf_v_per_rad_s[0] * w0
        out[..., 1] = self.volts_per_nm[1] * torque1 + self.emf_v_per_rad_s[1] * w1
        return out

    def accelerations(self, x, u) -> np.ndarray:
        """q̈ (..., 2) for states x (..., 4) and applied volts u (..., 2):
        M q̈ = (V − e·q̇)/k − τ_friction − C q̇ − τg."""
        q0, q1, w0, w1 = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
        cos_b = np.cos(q1)
        h = self.beta * np.sin(q1)
        fore = self.g_fore * np.cos(q0 + q1)
        (k0, k1), (e0, e1) = self.volts_per_nm, self.emf_v_per_rad_s
        drive0 = ((u[..., 0] - e0 * w0) / k0 - self._friction_column(0, w0)
                  + h * w1 * (2.0 * w0 + w1) - self.g_upper * np.cos(q0) - fore)
        drive1 = (u[..., 1] - e1 * w1) / k1 - self._friction_column(1, w1) - h * w0 * w0 - fore
        m00, m01 = self.alpha + 2.0 * self.beta * cos_b, self.gamma + self.beta * cos_b
        det = m00 * self.gamma - m01 * m01
        out = np.empty(np.broadcast_shapes(x.shape[:-1] + (2,), np.shape(u)))
        out[..., 0] = (self.gamma * drive0 - m01 * drive1) / det
        out[..., 1] = (m00 * drive1 - m01 * drive0) / det
        return out

    def derivatives(self, x, u) -> np.ndarray:
        """f(x, u) for states (..., 4) and volts (..., 2): [q̇, q̈], (..., 4)."""
        out = np.empty(x.shape)
        out[..., :2] = x[..., 2:]
        out[..., 2:] = self.accelerations(x, u)
        return out
