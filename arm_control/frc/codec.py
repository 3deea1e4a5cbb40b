"""The contract's double[] layouts to and from plain values (``contract.READING_LAYOUT``,
``VOLTAGE_LAYOUT``, ``PROFILE_HEAD`` + ``PROFILE_POINT``): one place that packs and checks
them, for the robot, the bridge, the tests and the benches."""

from dataclasses import dataclass
import math

from arm_control.frc import contract as nt

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
    """Setpoints k = 0..n-1 for the instants ``time_us + k·period_s``, each with the model's
    feedforward voltage."""

    time_us: int
    period_s: float
    position_rad: tuple[tuple[float, float], ...]
    velocity_rad_s: tuple[tuple[float, float], ...]
    feedforward_v: tuple[tuple[float, float], ...]


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


def encode_profile(profile: ProfileCommand) -> list[float]:
    values = [float(profile.time_us), float(profile.period_s)]
    for point in zip(profile.position_rad, profile.velocity_rad_s, profile.feedforward_v):
        values += [float(v) for pair in point for v in pair]
    return values


def decode_command(values) -> VoltageCommand | ProfileCommand:
    """A voltage pair (3 values) or a profile (2 + 6·n, n ≥ 1); ValueError otherwise."""
    values = [float(v) for v in values]
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f'{nt.COMMAND.name}: expected finite numbers, got {values}')
    time_us = int(values[0])
    if len(values) == nt.VOLTAGE_SIZE:
        return VoltageCommand(time_us, (values[1], values[2]))
    points = len(values) - nt.PROFILE_HEAD_SIZE
    if points <= 0 or points % nt.PROFILE_POINT_SIZE or not values[1] > 0.0:
        raise ValueError(f'{nt.COMMAND.name}: expected 3 values (a voltage pair) or 2 + 6·n '
                         f'with a positive period (a profile), got {len(values)} values, '
                         f'period {values[1] if len(values) > 1 else None}')
    rows = [values[i:i + nt.PROFILE_POINT_SIZE]
            for i in range(nt.PROFILE_HEAD_SIZE, len(values), nt.PROFILE_POINT_SIZE)]
    return ProfileCommand(time_us, values[1], tuple((r[0], r[1]) for r in rows),
                          tuple((r[2], r[3]) for r in rows), tuple((r[4], r[5]) for r in rows))
