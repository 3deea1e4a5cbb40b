"""Readings and commands between NT values and the numbers the ROS side uses."""

import math

from arm_control.model.dynamics import ArmDynamics


def joint_pair(values, topic: str) -> tuple[float, float]:
    """[shoulder, elbow] as two finite floats; ValueError naming the topic otherwise."""
    values = list(values)
    if len(values) != 2 or not all(
            isinstance(v, (int, float)) and math.isfinite(v) for v in values):
        raise ValueError(f'{topic}: expected [shoulder, elbow], two finite numbers, '
                         f'got {values}')
    return float(values[0]), float(values[1])


def finite_number(value, topic: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise ValueError(f'{topic}: expected a finite number, got {value!r}')
    return float(value)


def clamp_voltage(voltage, max_voltage: float) -> tuple[float, float]:
    """Each voltage within ±max_voltage, as a motor controller on the battery applies it."""
    return tuple(min(max(float(v), -max_voltage), max_voltage) for v in voltage)


def joint_effort_nm(motor_current_a, dynamics: ArmDynamics) -> tuple[float, float]:
    """Torque of each joint's motors, from one motor's stator current: τ = n·G·Kt·I.

    The sim reports the same torque as ``effort`` (τ = n·G·Kt·(V − G·ω/Kv)/R, the current
    being (V − G·ω/Kv)/R).
    """
    return tuple(motor.count * motor.gear_ratio * motor.kt_nm_per_a * current
                 for motor, current in zip(dynamics.motors, motor_current_a))


def battery_state_current_a(supply_current_a: float) -> float:
    """The FRC convention (the PDH's current, positive while drawing from the battery) to
    sensor_msgs/BatteryState's: negative while discharging."""
    return -supply_current_a


def ros_stamp_ns(value_time_us: int, nt_now_us: int, ros_now_ns: int) -> int:
    """When an NT value was set, on the ROS clock: now, less the value's age on NT's clock."""
    return ros_now_ns - 1000 * (nt_now_us - value_time_us)


def commanding(voltage) -> bool:
    """A controller's command of exactly 0 V on both joints means "not commanding" (disabled,
    no sensors, an e-stop at 0 V); any loop that is closing sends something else."""
    return any(v != 0.0 for v in voltage)


class SetpointFeedforward:
    """Mode setpoint: the voltage the model needs for the controller's setpoint motion,
    V_ff = motor⁻¹(M θ̈ + C θ̇ + τg + τ_friction) at (θ_sp, θ̇_sp, θ̈_sp).

    The controller publishes position and velocity; θ̈_sp is their backward difference over
    the setpoints' stamps (half a period late), and 0 after a gap or at the first one.
    """

    def __init__(self, dynamics: ArmDynamics, max_voltage: float, max_gap_s: float = 0.1):
        self.dynamics = dynamics
        self.max_voltage = max_voltage
        self.max_gap_s = max_gap_s
        self.last = None            # (stamp_s, velocity)

    def __call__(self, stamp_s: float, position, velocity) -> tuple[float, float]:
        acceleration = (0.0, 0.0)
        if self.last is not None and 0.0 < stamp_s - self.last[0] <= self.max_gap_s:
            dt = stamp_s - self.last[0]
            acceleration = tuple((v - v0) / dt for v, v0 in zip(velocity, self.last[1]))
        self.last = (stamp_s, tuple(velocity))
        return clamp_voltage(self.dynamics.voltage_for(position, velocity, acceleration),
                             self.max_voltage)
