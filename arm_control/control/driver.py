"""Driver mode: the tool moved by a driver's velocity command, through the damped Jacobian.

Each control period decides the joint velocity at the period's end, q̇ = J⁻¹v (damped least
squares near a singularity), within the speed and acceleration the motors surely give; the
setpoint ramps to it with q̈ constant over the period. The arm brakes instead when moving on
and then braking would meet forbidden space, so it stops short of it; when the commands stop
for ``driver_command_timeout_s`` it brakes to rest.
"""

import numpy as np

from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace

# Damping of the Jacobian's inverse (m): bounded joint speed near a singularity (arm straight
# or folded), exact far from one.
DRIVER_DAMPING_M = 0.05
# Driver mode stops this much short of forbidden space, on top of the braking distance.
DRIVER_STOP_MARGIN_RAD = 0.03


class DriverMode:
    """The driver's setpoint, decided once per period."""

    def __init__(self, kinematics: TwoLinkKinematics, forbidden: ForbiddenSpace,
                 max_velocity_rad_s, max_acceleration_rad_s2, period_s: float,
                 max_speed_mps: float, command_timeout_s: float):
        self.kinematics = kinematics
        self.forbidden = forbidden
        self.max_velocity = np.asarray(max_velocity_rad_s, float)
        self.max_acceleration = np.asarray(max_acceleration_rad_s2, float)
        self.period_s = period_s
        self.max_speed_mps = max_speed_mps
        self.command_timeout_s = command_timeout_s
        self.tool_velocity_mps = np.zeros(2)
        self.command_s = -np.inf
        self.t0_s, self.q0, self.qd0, self.qdd = 0.0, np.zeros(2), np.zeros(2), np.zeros(2)

    def take_over(self, now_s: float, q, qd) -> None:
        """Start from the setpoint (q, q̇) the arm is following now."""
        self.t0_s, self.q0, self.qd0 = now_s, np.asarray(q, float), np.asarray(qd, float)
        self.qdd = np.zeros(2)

    def command(self, now_s: float, vx_mps: float, vy_mps: float) -> None:
        velocity = np.array([vx_mps, vy_mps], float)
        speed = float(np.hypot(*velocity))
        if speed > self.max_speed_mps:
            velocity *= self.max_speed_mps / speed
        self.tool_velocity_mps, self.command_s = velocity, now_s

    def sample(self, t_s: float):
        """(q, q̇, q̈): q̈ constant over the period decided at t0, q̇ constant after it."""
        tau = max(t_s - self.t0_s, 0.0)
        ramp = min(tau, self.period_s)
        qd_end = self.qd0 + self.qdd * ramp
        q = self.q0 + self.qd0 * ramp + 0.5 * self.qdd * ramp ** 2 + qd_end * (tau - ramp)
        return q, qd_end, (self.qdd.copy() if tau < self.period_s else np.zeros(2))

    def fresh(self, now_s: float) -> bool:
        return now_s - self.command_s <= self.command_timeout_s

    def decide(self, now_s: float) -> None:
        """The joint velocity at the end of this period, within the limits, braking where
        going on would not stop free of forbidden space."""
        q, qd, _ = self.sample(now_s)
        tool_velocity = self.tool_velocity_mps if self.fresh(now_s) else np.zeros(2)
        target = self.kinematics.joint_velocity_for(q, tool_velocity, DRIVER_DAMPING_M)
        scale = float(np.max(np.abs(target) / self.max_velocity))
        if scale > 1.0:
            target = target / scale
        dt = self.period_s
        new_qd = qd + np.clip(target - qd, -self.max_acceleration * dt,
                              self.max_acceleration * dt)
        if not self._stops_free(q, new_qd):
            new_qd = self._braked(qd)
        self.t0_s, self.q0, self.qd0 = now_s, q, qd
        self.qdd = (new_qd - qd) / dt

    def idle(self, now_s: float) -> bool:
        """The commands stopped and the arm has come to rest."""
        _, qd, _ = self.sample(now_s)
        return not self.fresh(now_s) and not np.any(qd) and not np.any(self.qdd)

    def _braked(self, qd) -> np.ndarray:
        """One period of braking along the same direction at the acceleration limit."""
        need = float(np.max(np.abs(qd) / self.max_acceleration))
        if need <= self.period_s:
            return np.zeros(2)
        return qd * (1.0 - self.period_s / need)

    def _stops_free(self, q, qd) -> bool:
        """Ramping to q̇ over one period and then braking, does the arm stay free, with
        ``DRIVER_STOP_MARGIN_RAD`` to spare?"""
        stop_s = float(np.max(np.abs(qd) / self.max_acceleration))
        travel = qd * (self.period_s + 0.5 * stop_s)
        length = float(np.max(np.abs(travel)))
        if length == 0.0:
            return True
        end = q + travel * (1.0 + DRIVER_STOP_MARGIN_RAD / length)
        return self.forbidden.segment_is_free(q, end, 5 * self.forbidden.check_step_rad)
