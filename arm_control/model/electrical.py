"""The robot's electrical limits: the battery's sag, the motor controllers' current limits and
the roboRIO's brownout (DESIGN.md §4b).

Each joint's motor controller applies V with |V| ≤ V_bus, lowered where needed so that each
motor's stator current I = (V − G·ω/Kv)/R stays within ±current_limit_a. The supply current
follows from the power balance, I_supply = Σ_motors V·I / V_bus (negative while the motors
regenerate), and the battery sags under it, V_bus = V_nominal − R_battery·I_supply, so

    V_bus² − V_nominal·V_bus + R_battery·P = 0,   P = Σ_motors V·I,

whose upper root is the bus voltage. P depends on V_bus only through the joints whose voltage
the bus caps (V = ±V_bus): their P is quadratic in V_bus, so for a given set of capped joints
the bus solves a quadratic; the set is found by trying it. While V_bus would fall below the
brownout voltage every output is 0 V (and the bus returns to V_nominal).
"""

from dataclasses import dataclass
import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.motor import GearMotor


@dataclass(frozen=True)
class PowerState:
    """What the electrical system does with one pair of commands, at one instant."""

    bus_voltage: float
    applied_v: tuple[float, float]          # each joint's motors, as applied
    motor_current_a: tuple[float, float]    # stator current of one motor of each joint
    supply_current_a: float                 # from the battery; negative while regenerating
    browned_out: bool

    @property
    def power_w(self) -> float:
        return self.bus_voltage * self.supply_current_a


class PowerSupply:
    """The battery and the two joints' motor controllers."""

    def __init__(self, arm: ArmConfig, motors: tuple[GearMotor, GearMotor]):
        battery = arm.battery
        self.nominal_voltage = battery.nominal_voltage
        self.resistance_ohm = battery.resistance_ohm
        self.brownout_voltage = battery.brownout_voltage
        self.motors = motors
        self.current_limit_a = tuple(joint.current_limit_a for joint in arm.joints)
        self.counts = tuple(motor.count for motor in motors)
        self.resistances = tuple(motor.resistance_ohm for motor in motors)
        # Volts either side of the back-EMF that drive the current limit through one motor.
        self.current_window_v = tuple(limit * motor.resistance_ohm
                                      for limit, motor in zip(self.current_limit_a, motors))
        self._emf_pair = tuple(m.back_emf_v_per_rad_s for m in motors)
        # ... and the same as arrays, for the batch forms.
        self._window_v = np.array(self.current_window_v)
        self._emf_v_per_rad_s = np.array([m.back_emf_v_per_rad_s for m in motors])
        self._conductance = np.array([m.count / m.resistance_ohm for m in motors])

    def applied_at(self, command_v, speed_rad_s, bus_voltage: float) -> tuple[float, float]:
        """What the motor controllers apply for ``command_v`` at a known bus voltage (the
        roboRIO reads its own): within the current limit, then capped at ±V_bus."""
        (e0, e1), (w0, w1) = self._emf_pair, self.current_window_v
        emf0, emf1 = e0 * speed_rad_s[0], e1 * speed_rad_s[1]
        v0 = min(max(min(max(command_v[0], emf0 - w0), emf0 + w0), -bus_voltage), bus_voltage)
        v1 = min(max(min(max(command_v[1], emf1 - w1), emf1 + w1), -bus_voltage), bus_voltage)
        return v0, v1

    def _within_current_limit(self, joint: int, command: float, speed: float) -> float:
        """The command moved into [emf − I_limit·R, emf + I_limit·R]."""
        emf = self.motors[joint].back_emf_v(speed)
        window = self.current_window_v[joint]
        return min(max(command, emf - window), emf + window)

    def solve(self, command_v, speed_rad_s) -> PowerState:
        """The bus voltage, applied voltages and currents for ``command_v`` at joint speeds
        ``speed_rad_s``, consistent with each other.

        A joint is capped by the bus once V_bus < |v| (v: its command within the current
        limit), so P(V_bus) is one quadratic between those thresholds and grows with V_bus:
        the upper root is found interval by interval from the top.
        """
        nominal, r_battery = self.nominal_voltage, self.resistance_ohm
        emf = [motor.back_emf_v(speed) for motor, speed in zip(self.motors, speed_rad_s)]
        free = [self._within_current_limit(j, command_v[j], speed_rad_s[j]) for j in range(2)]
        thresholds = sorted((abs(v) for v in free), reverse=True) + [0.0]
        bus, upper = math.nan, math.inf
        for lower in thresholds:
            # P = fixed + a·V_bus² + b·V_bus: a capped joint's motors give n·V·(V − emf)/R
            # with V = ±V_bus.
            fixed = a = b = 0.0
            for j in range(2):
                n, r = self.counts[j], self.resistances[j]
                if abs(free[j]) > lower:
                    a += n / r
                    b -= n * math.copysign(1.0, free[j]) * emf[j] / r
                else:
                    fixed += n * free[j] * (free[j] - emf[j]) / r
            root = _upper_root(1.0 + r_battery * a, r_battery * b - nominal,
                               r_battery * fixed)
            if lower <= root <= upper or (root > upper and upper == math.inf):
                bus = root
                break
            upper = lower
        if not bus >= self.brownout_voltage:               # also NaN: no bus at all
            return self._brownout(speed_rad_s)
        applied = tuple(min(max(v, -bus), bus) for v in free)
        currents = ((applied[0] - emf[0]) / self.resistances[0],
                    (applied[1] - emf[1]) / self.resistances[1])
        power = (self.counts[0] * applied[0] * currents[0]
                 + self.counts[1] * applied[1] * currents[1])
        return PowerState(bus, applied, currents, power / bus, False)

    def _brownout(self, speed_rad_s) -> PowerState:
        """Every output at 0 V: the motors' back-EMF drives a braking current through the
        motor controllers' bridges, which draws nothing from the battery."""
        currents = tuple(motor.current_a(0.0, speed)
                         for motor, speed in zip(self.motors, speed_rad_s))
        return PowerState(self.nominal_voltage, (0.0, 0.0), currents, 0.0, True)

    def solve_many(self, command_v, speed_rad_s):
        """The batch form of ``solve``: commands and joint speeds of shape (..., 2); returns
        (bus voltage (...), applied volts (..., 2), browned out (...)). The same intervals:
        neither joint capped by the bus (tried first: the usual case), the one with the
        larger command, or both."""
        command_v, speed_rad_s = np.asarray(command_v, float), np.asarray(speed_rad_s, float)
        nominal, r_battery = self.nominal_voltage, self.resistance_ohm
        emf = self._emf_v_per_rad_s * speed_rad_s
        free = np.clip(command_v, emf - self._window_v, emf + self._window_v)
        size = np.abs(free)
        high = np.max(size, axis=-1)
        with np.errstate(invalid='ignore'):
            bus = 0.5 * (nominal + np.sqrt(nominal * nominal - 4.0 * r_battery * np.sum(
                self._conductance * free * (free - emf), axis=-1)))
            if not np.all(bus >= high):
                bus = np.where(bus >= high, bus, np.nan)
                low = np.min(size, axis=-1)
                for lower, upper in ((low, high), (np.zeros_like(low), low)):
                    capped = size > lower[..., None]
                    g = np.where(capped, self._conductance, 0.0)
                    a = 1.0 + r_battery * np.sum(g, axis=-1)
                    b = r_battery * np.sum(-g * np.sign(free) * emf, axis=-1) - nominal
                    drawn = np.where(capped, 0.0, self._conductance * free * (free - emf))
                    c = r_battery * np.sum(drawn, axis=-1)
                    root = (-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
                    bus = np.where(np.isnan(bus) & (lower <= root) & (root <= upper), root,
                                   bus)
        browned = ~(bus >= self.brownout_voltage)
        bus = np.where(browned, nominal, bus)
        cap = bus[..., None]
        applied = np.where(browned[..., None], 0.0, np.clip(free, -cap, cap))
        return bus, applied, browned

    def bus_voltages(self, applied_v, speed_rad_s) -> np.ndarray:
        """The batch form of the bus for voltages the motor controllers apply as commanded
        (within the current limits and ±V_bus: ``solve`` then lowers nothing and gives the
        same bus): applied_v and speed_rad_s of shape (..., 2), the bus (...,), the upper
        root of V_bus² − V_nominal·V_bus + R_battery·P = 0 with P = Σ n·V·(V − e·ω)/R. NaN
        where there is none: the battery cannot give that power at any voltage."""
        applied_v, speed_rad_s = np.asarray(applied_v, float), np.asarray(speed_rad_s, float)
        power = np.sum(self._conductance * applied_v
                       * (applied_v - self._emf_v_per_rad_s * speed_rad_s), axis=-1)
        discriminant = self.nominal_voltage ** 2 - 4.0 * self.resistance_ohm * power
        with np.errstate(invalid='ignore'):
            return 0.5 * (self.nominal_voltage + np.sqrt(discriminant))

    def min_bus_voltage(self) -> float:
        """The lowest bus voltage the current limits allow: with |V| ≤ V_bus each motor's
        share of the supply current is at most its stator current, so
        V_bus ≥ V_nominal − R_battery·Σ n·I_limit."""
        total = sum(m.count * limit for m, limit in zip(self.motors, self.current_limit_a))
        return self.nominal_voltage - self.resistance_ohm * total


def _upper_root(a: float, b: float, c: float) -> float:
    """The larger root of a·x² + b·x + c = 0 (a > 0); NaN when there is none."""
    discriminant = b * b - 4.0 * a * c
    if discriminant < 0.0:
        return math.nan
    return (-b + math.sqrt(discriminant)) / (2.0 * a)
