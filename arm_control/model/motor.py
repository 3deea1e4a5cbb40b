"""DC gearmotors from their datasheet numbers (WPILib's DCMotor model)."""

from dataclasses import dataclass
import math

from arm_control.config import MotorDatasheet


@dataclass(frozen=True)
class GearMotor:
    """``count`` identical DC motors driving one joint through a ``gear_ratio``:1 reduction.

    From the datasheet at voltage V_n: R = V_n / I_stall, Kv = ω_free / (V_n − R·I_free),
    Kt = τ_stall / I_stall. At the joint, turning at ω with V applied, each motor carries
    I = (V − G·ω/Kv)/R and together they give τ = n·G·Kt·I.
    """

    resistance_ohm: float
    kv_rad_per_s_per_v: float
    kt_nm_per_a: float
    count: int = 1
    gear_ratio: float = 1.0

    @classmethod
    def from_datasheet(cls, motor: MotorDatasheet, count: int = 1, gear_ratio: float = 1.0):
        resistance = motor.nominal_voltage / motor.stall_current_a
        free_speed_rad_s = motor.free_speed_rpm * 2.0 * math.pi / 60.0
        kv = free_speed_rad_s / (motor.nominal_voltage - resistance * motor.free_current_a)
        kt = motor.stall_torque_nm / motor.stall_current_a
        return cls(resistance, kv, kt, count, gear_ratio)

    @property
    def volts_per_nm(self) -> float:
        """k = R/(n·G·Kt): volts above back-EMF per newton-metre at the joint."""
        return self.resistance_ohm / (self.count * self.gear_ratio * self.kt_nm_per_a)

    @property
    def back_emf_v_per_rad_s(self) -> float:
        """e = G/Kv: back-EMF volts per rad/s of the joint."""
        return self.gear_ratio / self.kv_rad_per_s_per_v

    def back_emf_v(self, joint_speed_rad_s: float) -> float:
        return self.back_emf_v_per_rad_s * joint_speed_rad_s

    def free_speed_rad_s(self, voltage: float) -> float:
        """The joint speed at which ``voltage`` only balances the back-EMF."""
        return voltage / self.back_emf_v_per_rad_s

    def current_a(self, voltage: float, joint_speed_rad_s: float) -> float:
        """Stator current of each motor: (V − G·ω/Kv)/R."""
        return (voltage - self.back_emf_v(joint_speed_rad_s)) / self.resistance_ohm

    def torque_nm(self, voltage: float, joint_speed_rad_s: float) -> float:
        """Torque at the joint: n·G·Kt·(V − G·ω/Kv)/R."""
        return (voltage - self.back_emf_v(joint_speed_rad_s)) / self.volts_per_nm

    def voltage_for(self, torque_nm: float, joint_speed_rad_s: float) -> float:
        """The voltage that makes ``torque_nm`` at the joint: V = k·τ + G·ω/Kv."""
        return self.volts_per_nm * torque_nm + self.back_emf_v(joint_speed_rad_s)
