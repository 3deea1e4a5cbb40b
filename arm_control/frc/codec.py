"""The contract's double[] layouts to and from plain values (``contract.READING_LAYOUT``,
``VOLTAGE_LAYOUT``, ``PROFILE_HEAD`` + ``PROFILE_POINT``): one place that packs and checks
them, for the robot, the bridge, the tests and the benches.

A profile on NT is ``arm_control.model.profile``'s layout with its start (data[0]) as the
NT server clock's µs instead of the sender's seconds; decoded, it is a ``Profile`` whose
``start_s`` is on the NT server clock, which the robot plays with ``ProfilePlayer``.
"""

from dataclasses import dataclass, replace
import math

from arm_control.frc import contract as nt
from arm_control.model import profile as profiles

NAN_PAIR = (math.nan, math.nan)


@dataclass(frozen=True)
class Reading:
    """One robot loop's readings, all from the instant ``time_us`` (NT server clock)."""

    time_us: int
    enabled: bool
    position_rad: tuple[float, float]
    velocity_rad_s: tuple[float, float]
    encoder_rad: tuple[float, float] = NAN_PAIR
    motor_current_a: tuple[float, float] = NAN_PAIR
    bus_voltage_v: float = math.nan
    supply_current_a: float = math.nan
    applied_voltage_v: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class VoltageCommand:
    """Motor voltages to apply from ``time_us`` on (NT server clock)."""

    time_us: int
    voltage_v: tuple[float, float]


@dataclass(frozen=True)
class ProfileCommand:
    """A profile whose setpoint 0 is for ``time_us`` (NT server clock): ``profile.start_s``
    is the same instant in seconds."""

    time_us: int
    profile: profiles.Profile

    @property
    def end_us(self) -> int:
        """When its last setpoint applies."""
        return self.time_us + round((len(self.profile.setpoints) - 1) * self.profile.step_s
                                    * 1e6)


def profile_command(time_us: int, profile: profiles.Profile) -> ProfileCommand:
    """``profile`` (its start on any clock) as a command for ``time_us`` on NT's."""
    return ProfileCommand(int(time_us), replace(profile, start_s=time_us * 1e-6))


def encode_reading(reading: Reading) -> list[float]:
    values = [0.0] * nt.READING_SIZE
    for field in nt.READING_LAYOUT:
        value = getattr(reading, field.name)
        values[field.indices] = [float(v) for v in value] if field.size > 1 else [float(value)]
    return values


def decode_reading(values) -> Reading:
    """A ``Reading``; ValueError naming what is wrong (length, a required value not finite)."""
    values = list(values)
    if len(values) != nt.READING_SIZE:
        raise ValueError(f'{nt.READING.name}: expected {nt.READING_SIZE} values, got '
                         f'{len(values)}')
    fields = {}
    for field in nt.READING_LAYOUT:
        part = tuple(float(v) for v in values[field.indices])
        fields[field.name] = part if field.size > 1 else part[0]
    for name in ('time_us', 'enabled', 'position_rad', 'velocity_rad_s', 'applied_voltage_v'):
        value = fields[name]
        if not all(math.isfinite(v) for v in (value if isinstance(value, tuple) else (value,))):
            raise ValueError(f'{nt.READING.name}: {name} must be finite, got {value}')
    fields['time_us'] = int(fields['time_us'])
    fields['enabled'] = fields['enabled'] != 0.0
    return Reading(**fields)


def encode_voltage(time_us: int, voltage_v) -> list[float]:
    return [float(time_us), float(voltage_v[0]), float(voltage_v[1])]


def encode_profile(command: ProfileCommand) -> list[float]:
    data = profiles.encode(command.profile)[2]
    return [float(command.time_us)] + data[1:]


def decode_command(values) -> VoltageCommand | ProfileCommand:
    """A voltage pair (3 values) or a profile (6 + 6·n, n ≥ 1); ValueError otherwise."""
    values = [float(v) for v in values]
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f'{nt.COMMAND.name}: expected finite numbers, got {values}')
    time_us = int(values[0])
    if len(values) == nt.VOLTAGE_SIZE:
        return VoltageCommand(time_us, (values[1], values[2]))
    points = (len(values) - nt.PROFILE_HEAD_SIZE) // nt.PROFILE_POINT_SIZE
    dims = [(profiles.SETPOINT_LABEL, points, 6 * points), (profiles.FIELDS_LABEL, 6, 6)]
    try:
        profile = profiles.decode([time_us * 1e-6] + values[1:], dims, profiles.DATA_OFFSET)
    except profiles.ProfileError as error:
        raise ValueError(f'{nt.COMMAND.name}: not 3 values (a voltage pair) nor a profile: '
                         f'{error}') from error
    return ProfileCommand(time_us, profile)
