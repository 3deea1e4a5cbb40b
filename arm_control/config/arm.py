"""The arm's description: its links, joints, motors, battery, world and presets, read from
the parameters and validated (a bad value names the parameter and its value)."""

from dataclasses import dataclass
import functools
import math
from typing import Any, Mapping

from arm_control.parameters import ParameterError, Reader


JOINT_NAMES = ('shoulder', 'elbow')
FRAME_ID = 'arm_base'


@dataclass(frozen=True)
class MotorDatasheet:
    """One DC motor's datasheet numbers, taken at ``nominal_voltage``."""

    name: str
    stall_torque_nm: float
    stall_current_a: float
    free_speed_rpm: float
    free_current_a: float
    nominal_voltage: float


@functools.lru_cache(maxsize=None)
def wpilib_motors() -> dict[str, MotorDatasheet]:
    """WPILib's DCMotor catalogue (robotpy-wpimath), by the names of its factories."""
    from wpimath.system.plant import DCMotor
    catalogue = {}
    for name in dir(DCMotor):
        factory = getattr(DCMotor, name)
        if name.startswith('_') or not callable(factory):
            continue
        try:
            motor = factory(1)
        except TypeError:               # an instance method, not a factory
            continue
        if isinstance(motor, DCMotor):
            catalogue[name] = MotorDatasheet(
                name, motor.stallTorque, motor.stallCurrent,
                motor.freeSpeed * 60.0 / (2.0 * math.pi), motor.freeCurrent,
                motor.nominalVoltage)
    return catalogue


@dataclass(frozen=True)
class JointConfig:
    """A link, the joint that turns it, its drive and its sensors."""

    name: str
    length_m: float
    mass_kg: float
    com_from_joint_m: float
    inertia_about_com_kgm2: float
    motor: MotorDatasheet
    motor_count: int
    gear_ratio: float
    current_limit_a: float          # per motor; inf when the motor controller has none
    min_angle_rad: float
    max_angle_rad: float
    viscous_friction_nm_s_per_rad: float
    coulomb_friction_nm: float
    potentiometer_noise_rad: float
    velocity_noise_rad_s: float
    encoder_backlash_rad: float


@dataclass(frozen=True)
class BatteryConfig:
    """WPILib's BatterySim: V_bus = V_nominal − R·I_supply; the roboRIO's brownout."""

    nominal_voltage: float
    resistance_ohm: float
    brownout_voltage: float


@dataclass(frozen=True)
class Rectangle:
    """An axis-aligned forbidden region of the arm plane, in arm_base (m)."""

    name: str
    x_min: float
    y_min: float
    x_max: float
    y_max: float


@dataclass(frozen=True)
class WorldConfig:
    """Where the arm may not go, and how finely that is checked."""

    regions: tuple[Rectangle, ...]
    clearance_m: float
    clearance_rad: float
    min_elbow_fold_rad: float
    check_step_rad: float


@dataclass(frozen=True)
class ArmConfig:
    """The arm every node shares: physics, drive, power, sensors, world and named goals."""

    gravity_mps2: float
    battery: BatteryConfig
    shoulder: JointConfig
    elbow: JointConfig
    world: WorldConfig
    presets: tuple[tuple[str, float, float], ...]   # (name, x_m, y_m)

    @property
    def joints(self) -> tuple[JointConfig, JointConfig]:
        return (self.shoulder, self.elbow)

    @property
    def reach_m(self) -> tuple[float, float]:
        """Inner and outer radius of the reachable annulus."""
        return (abs(self.shoulder.length_m - self.elbow.length_m),
                self.shoulder.length_m + self.elbow.length_m)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'ArmConfig':
        read = Reader(params)
        motors = {name: _read_datasheet(read, name) for name in read.strings('motors.names')}
        joints = [_read_joint(read, name, motors) for name in JOINT_NAMES]
        battery = BatteryConfig(
            nominal_voltage=read.positive('battery.nominal_voltage'),
            resistance_ohm=read.nonnegative('battery.resistance_ohm'),
            brownout_voltage=read.nonnegative('battery.brownout_voltage'))
        if battery.brownout_voltage >= battery.nominal_voltage:
            raise ParameterError(
                f"parameter 'battery.brownout_voltage' = {battery.brownout_voltage}: must be "
                f'below battery.nominal_voltage = {battery.nominal_voltage}')
        regions = []
        for name in read.strings('world.forbidden_regions'):
            x_min, y_min, x_max, y_max = read.numbers(f'world.regions.{name}', 4)
            if x_min >= x_max or y_min >= y_max:
                raise ParameterError(
                    f"parameter 'world.regions.{name}' = {[x_min, y_min, x_max, y_max]}: "
                    'expected [x_min, y_min, x_max, y_max] with min < max')
            regions.append(Rectangle(name, x_min, y_min, x_max, y_max))
        world = WorldConfig(
            regions=tuple(regions),
            clearance_m=read.nonnegative('world.clearance_m'),
            clearance_rad=read.number('world.clearance_rad', low=0.0, high=0.2),
            min_elbow_fold_rad=read.number('world.min_elbow_fold_rad', low=0.0, high=math.pi),
            check_step_rad=read.number('world.check_step_rad', low=1e-5, high=0.05),
        )
        presets = tuple((name, *read.numbers(f'presets.{name}', 2))
                        for name in read.strings('presets.names'))
        return cls(gravity_mps2=read.nonnegative('gravity_mps2'), battery=battery,
                   shoulder=joints[0], elbow=joints[1], world=world, presets=presets)


def _read_datasheet(read: Reader, name: str) -> MotorDatasheet:
    key = f'motors.{name}'
    stall_torque, stall_current, free_rpm, free_current, volts = read.numbers(key, 5)
    if min(stall_torque, stall_current, free_rpm, volts) <= 0.0 or free_current < 0.0 \
            or free_current >= stall_current:
        raise ParameterError(
            f"parameter '{key}' = {[stall_torque, stall_current, free_rpm, free_current, volts]}"
            ': expected [stall torque N m, stall current A, free speed rpm, free current A, '
            'volts], all positive, the free current below the stall current')
    return MotorDatasheet(name, stall_torque, stall_current, free_rpm, free_current, volts)


def _catalogue_motor(key: str, motor_name: str, motors: dict) -> MotorDatasheet:
    """A motor the file does not give: WPILib's catalogue, needed (and imported) only then."""
    try:
        catalogue = wpilib_motors()
    except ImportError as error:
        raise ParameterError(
            f"parameter '{key}' = {motor_name!r}: not a motor of motors.names "
            f"({', '.join(sorted(motors))}); WPILib's DCMotor catalogue needs robotpy-wpimath "
            f'({error.name or error}): pip install robotpy-wpimath, or give the motor datasheet '
            'under motors.names') from None
    if motor_name not in catalogue:
        raise ParameterError(
            f"parameter '{key}' = {motor_name!r}: not a motor of motors.names nor of "
            f"WPILib's DCMotor catalogue ({', '.join(sorted({*motors, *catalogue}))})")
    return catalogue[motor_name]


def _read_joint(read: Reader, name: str, motors: dict) -> JointConfig:
    motor_name = read.text(f'{name}.motor')
    motor = motors.get(motor_name) or _catalogue_motor(f'{name}.motor', motor_name, motors)
    current_limit = read.nonnegative(f'{name}.current_limit_a')
    joint = JointConfig(
        name=name,
        length_m=read.positive(f'{name}.length_m'),
        mass_kg=read.nonnegative(f'{name}.mass_kg'),
        com_from_joint_m=read.nonnegative(f'{name}.com_from_joint_m'),
        inertia_about_com_kgm2=read.nonnegative(f'{name}.inertia_about_com_kgm2'),
        motor=motor,
        motor_count=read.integer(f'{name}.motor_count', low=1),
        gear_ratio=read.positive(f'{name}.gear_ratio'),
        current_limit_a=current_limit if current_limit > 0.0 else math.inf,
        min_angle_rad=read.number(f'{name}.min_angle_rad'),
        max_angle_rad=read.number(f'{name}.max_angle_rad'),
        viscous_friction_nm_s_per_rad=read.nonnegative(f'{name}.viscous_friction_nm_s_per_rad'),
        coulomb_friction_nm=read.nonnegative(f'{name}.coulomb_friction_nm'),
        potentiometer_noise_rad=read.nonnegative(f'{name}.potentiometer_noise_rad'),
        velocity_noise_rad_s=read.nonnegative(f'{name}.velocity_noise_rad_s'),
        encoder_backlash_rad=read.nonnegative(f'{name}.encoder_backlash_rad'),
    )
    if joint.mass_kg * joint.com_from_joint_m ** 2 + joint.inertia_about_com_kgm2 <= 0.0:
        raise ParameterError(
            f"parameter '{name}.inertia_about_com_kgm2' = {joint.inertia_about_com_kgm2}: "
            f'the {name} link has no inertia about its joint, so its acceleration is undefined')
    if joint.min_angle_rad >= joint.max_angle_rad:
        raise ParameterError(
            f"parameter '{name}.min_angle_rad' = {joint.min_angle_rad}: "
            f'must be below {name}.max_angle_rad = {joint.max_angle_rad}')
    return joint
