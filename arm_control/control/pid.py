"""PID feedback per joint, on the estimated state (arm paper §4.2).

    u = kp·e + ki·∫e dt + kd·ė,   e = θ_setpoint − θ_estimate,  ė = θ̇_setpoint − θ̇_estimate

The derivative term uses the velocity error from the state estimate, not a differentiated
position: the Kalman filter already gives θ̇ with little noise and no lag, and
differentiating a noisy potentiometer at 50 Hz would put that noise on the motors.
Anti-windup: the integral term's voltage stays within ±``integrator_limit_v``, and it stops
growing while the output is saturated in the direction it would push (conditional
integration), so a long saturated move does not leave a charged integrator behind.
"""

from dataclasses import dataclass
import math


@dataclass(frozen=True)
class PidGains:
    """Gains of one joint: kp (V/rad), ki (V/(rad·s)), kd (V·s/rad)."""

    kp: float
    ki: float
    kd: float

    @classmethod
    def from_triple(cls, triple) -> 'PidGains':
        kp, ki, kd = (float(value) for value in triple)
        return cls(kp, ki, kd)


class JointPid:
    """One joint's PID; ``update`` is called once per control period."""

    def __init__(self, gains: PidGains, integrator_limit_v: float):
        self.gains = gains
        self.integrator_limit_v = float(integrator_limit_v)
        self.integral_v = 0.0           # ki·∫e dt, kept in volts so the limit is direct

    def reset(self) -> None:
        self.integral_v = 0.0

    def update(self, error_rad: float, velocity_error_rad_s: float, dt_s: float,
               saturated_sign: int = 0) -> float:
        """The feedback voltage kp·e + ki·∫e + kd·ė for this period.

        ``saturated_sign`` is +1 (or −1) when last period's total command was clamped at
        +max (−max) voltage: the integral then only moves back toward zero.
        """
        if not (math.isfinite(error_rad) and math.isfinite(velocity_error_rad_s)):
            raise ValueError(f'PID error must be finite, got {error_rad}, {velocity_error_rad_s}')
        step_v = self.gains.ki * error_rad * dt_s
        if saturated_sign == 0 or step_v * saturated_sign < 0.0:
            limit = self.integrator_limit_v
            self.integral_v = min(max(self.integral_v + step_v, -limit), limit)
        return (self.gains.kp * error_rad + self.integral_v
                + self.gains.kd * velocity_error_rad_s)


class ArmPid:
    """The shoulder's and the elbow's PID side by side (independent loops)."""

    def __init__(self, shoulder: PidGains, elbow: PidGains, integrator_limit_v: float):
        self.joints = (JointPid(shoulder, integrator_limit_v),
                       JointPid(elbow, integrator_limit_v))

    @classmethod
    def from_config(cls, controller_config) -> 'ArmPid':
        return cls(PidGains.from_triple(controller_config.shoulder_pid),
                   PidGains.from_triple(controller_config.elbow_pid),
                   controller_config.integrator_limit_v)

    def retune(self, controller_config) -> None:
        """New gains and integrator limit from the next update on; the integrals are kept
        (within the new limit), so a change does not kick the arm."""
        for joint, triple in zip(self.joints, (controller_config.shoulder_pid,
                                               controller_config.elbow_pid)):
            joint.gains = PidGains.from_triple(triple)
            joint.integrator_limit_v = float(controller_config.integrator_limit_v)
            limit = joint.integrator_limit_v
            joint.integral_v = min(max(joint.integral_v, -limit), limit)

    def reset(self) -> None:
        for joint in self.joints:
            joint.reset()

    @property
    def integral_v(self) -> tuple[float, float]:
        return tuple(joint.integral_v for joint in self.joints)

    def update(self, error_rad, velocity_error_rad_s, dt_s: float,
               saturated_sign=(0, 0)) -> tuple[float, float]:
        return tuple(joint.update(e, ed, dt_s, s) for joint, e, ed, s
                     in zip(self.joints, error_rad, velocity_error_rad_s, saturated_sign))
