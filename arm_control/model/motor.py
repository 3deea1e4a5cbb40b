"""DC gearmotors from their datasheet numbers (WPILib's DCMotor model)."""

from dataclasses import dataclass
import math

from arm_control.config import MotorConfig


@dataclass(frozen=True)
class GearMotor:
    """``count`` identical DC motors driving one joint through a ``gear_ratio``:1 reduction.

    From the datasheet at voltage V_n: R = V_n / I_stall, Kv = ω_free / (V_n − R·I_free),
    Kt = τ_stall / I_stall. At the joint, turning at ω with V applied,
    τ = n·G·Kt·(V − G·ω/Kv) / R.
    """

    resistance_ohm: float
    kv_rad_per_s_per_v: float
    kt_nm_per_a: float
    count: int = 1
    gear_ratio: float = 1.0

    @classmethod
    def from_datasheet(cls, motor: MotorConfig, count: int = 1, gear_ratio: float = 1.0):
        resistance = motor.datasheet_voltage / motor.stall_current_a
        free_speed_rad_s = motor.free_speed_rpm * 2.0 * math.pi / 60.0
        kv = free_speed_rad_s / (motor.datasheet_voltage - resistance * motor.free_current_a)
        kt = motor.stall_torque_nm / motor.stall_current_a
        return cls(resistance, kv, kt, count, gear_ratio)

    def back_emf_v(self, joint_speed_rad_s: float) -> float:
        return self.gear_ratio * joint_speed_rad_s / self.kv_rad_per_s_per_v

    def current_a(self, voltage: float, joint_speed_rad_s: float) -> float:
        """Total current of all ``count`` motors: n·(V − G·ω/Kv)/R."""
        return self.count * (voltage - self.back_emf_v(joint_speed_rad_s)) / self.resistance_ohm

    def torque_nm(self, voltage: float, joint_speed_rad_s: float) -> float:
        """Torque at the joint: n·G·Kt·(V − G·ω/Kv)/R."""
        return self.gear_ratio * self.kt_nm_per_a * self.current_a(voltage, joint_speed_rad_s)

    def voltage_for(self, torque_nm: float, joint_speed_rad_s: float) -> float:
        """The voltage that makes ``torque_nm`` at the joint: V = τ·R/(n·G·Kt) + G·ω/Kv."""
        return (torque_nm * self.resistance_ohm / (self.count * self.gear_ratio * self.kt_nm_per_a)
                + self.back_emf_v(joint_speed_rad_s))
