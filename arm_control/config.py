"""The arm description and each node's settings, read once from ROS parameters.

Parameters arrive as a flat mapping of dotted names to values -- what a ROS parameter file
holds and what a node's declared parameters give back -- and are validated here, so a bad
value fails at start with a message that names the parameter and its value.
``config/arm.yaml`` is the one source of every default.
"""

from dataclasses import dataclass
import math
from pathlib import Path
import re
from typing import Any, Mapping

import yaml

PACKAGE = 'arm_control'
JOINT_NAMES = ('shoulder', 'elbow')


class ParameterError(ValueError):
    """A parameter is missing, of the wrong type or out of range."""


def default_parameter_file(name: str = 'arm.yaml') -> Path:
    """The installed ``share/arm_control/config/<name>``, else the source tree's copy."""
    try:
        from ament_index_python.packages import get_package_share_directory
        installed = Path(get_package_share_directory(PACKAGE)) / 'config' / name
        if installed.is_file():
            return installed
    except (ImportError, LookupError, OSError, ValueError):
        pass
    return Path(__file__).resolve().parents[1] / 'config' / name


def read_parameter_file(path, node_name: str) -> dict[str, Any]:
    """Flatten a ROS parameter file into ``{dotted.name: value}`` as ``node_name`` sees it.

    The ``/**`` section applies to every node; ``/<node_name>`` (or ``<node_name>``) overrides it.
    """
    try:
        document = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as error:
        raise ParameterError(f'cannot read parameter file {path}: {error}') from error
    if not isinstance(document, dict):
        raise ParameterError(f'parameter file {path} is not a mapping of node sections')
    flat: dict[str, Any] = {}
    for section in ('/**', node_name, '/' + node_name):
        body = document.get(section)
        if body is None:
            continue
        if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
            raise ParameterError(f"section '{section}' of {path} has no ros__parameters mapping")
        _flatten(body['ros__parameters'], '', flat)
    return flat


def parameter_descriptions(path) -> dict[str, str]:
    """Each parameter's description: the comment on its line of the file, else its section's.

    The comments in ``config/arm.yaml`` are the one place a parameter is described.
    """
    descriptions: dict[str, str] = {}
    stack: list[tuple[int, str, str]] = []      # (indent, key, comment) of open sections
    for line in Path(path).read_text().splitlines():
        match = re.match(r'^(\s*)([\w/*]+):\s*([^#]*?)\s*(?:#\s*(.*))?$', line)
        if not match:
            continue
        indent, key, value, comment = len(match[1]), match[2], match[3], match[4] or ''
        while stack and stack[-1][0] >= indent:
            stack.pop()
        if value:
            names = [k for _, k, _ in stack if not k.startswith('/') and k != 'ros__parameters']
            inherited = next((c for _, _, c in reversed(stack) if c), '')
            descriptions['.'.join(names + [key])] = comment or inherited
        else:
            stack.append((indent, key, comment))
    return descriptions


def _flatten(tree: dict, prefix: str, out: dict) -> None:
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            _flatten(value, name + '.', out)
        else:
            out[name] = value


class _Reader:
    """Typed, range-checked access to a flat parameter mapping."""

    def __init__(self, params: Mapping[str, Any]):
        self.params = params

    def _raw(self, name):
        if name not in self.params or self.params[name] is None:
            raise ParameterError(f"parameter '{name}' is missing")
        return self.params[name]

    def number(self, name, *, low=-math.inf, high=math.inf, low_open=False) -> float:
        value = self._raw(name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected a number")
        value = float(value)
        too_low = value <= low if low_open else value < low
        if not math.isfinite(value) or too_low or value > high:
            bound = f"{'>' if low_open else '>='} {low}" if too_low else f'<= {high}'
            if not math.isfinite(value):
                bound = 'finite'
            raise ParameterError(f"parameter '{name}' = {value!r}: must be {bound}")
        return value

    def positive(self, name) -> float:
        return self.number(name, low=0.0, low_open=True)

    def nonnegative(self, name) -> float:
        return self.number(name, low=0.0)

    def integer(self, name, *, low=-(2 ** 63)) -> int:
        value = self._raw(name)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected an integer")
        if value < low:
            raise ParameterError(f"parameter '{name}' = {value!r}: must be >= {low}")
        return value

    def boolean(self, name) -> bool:
        value = self._raw(name)
        if not isinstance(value, bool):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected true or false")
        return value

    def numbers(self, name, length: int) -> tuple[float, ...]:
        value = self._raw(name)
        if (isinstance(value, (str, bytes)) or not hasattr(value, '__len__')
                or len(value) != length):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected {length} numbers")
        out = []
        for item in value:
            if isinstance(item, bool) or not isinstance(item, (int, float)) \
                    or not math.isfinite(item):
                raise ParameterError(f"parameter '{name}' = {value!r}: expected finite numbers")
            out.append(float(item))
        return tuple(out)

    def strings(self, name) -> tuple[str, ...]:
        value = self._raw(name)
        if isinstance(value, str) or not all(isinstance(item, str) for item in value):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected a list of names")
        return tuple(item for item in value if item)


@dataclass(frozen=True)
class MotorConfig:
    """One DC motor's datasheet numbers."""

    stall_torque_nm: float
    stall_current_a: float
    free_speed_rpm: float
    free_current_a: float
    datasheet_voltage: float


@dataclass(frozen=True)
class JointConfig:
    """A link, the joint that turns it, its drive and its sensors."""

    name: str
    length_m: float
    mass_kg: float
    com_from_joint_m: float
    inertia_about_com_kgm2: float
    motor_count: int
    gear_ratio: float
    min_angle_rad: float
    max_angle_rad: float
    viscous_friction_nm_s_per_rad: float
    coulomb_friction_nm: float
    potentiometer_noise_rad: float
    velocity_noise_rad_s: float
    encoder_backlash_rad: float


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
    """Where the arm may not go."""

    regions: tuple[Rectangle, ...]
    clearance_m: float
    clearance_rad: float
    min_elbow_fold_rad: float


@dataclass(frozen=True)
class ArmConfig:
    """The arm every node shares: physics, drive, sensors, world and named goals."""

    gravity_mps2: float
    max_voltage: float
    motor: MotorConfig
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
        read = _Reader(params)
        motor = MotorConfig(
            stall_torque_nm=read.positive('motor.stall_torque_nm'),
            stall_current_a=read.positive('motor.stall_current_a'),
            free_speed_rpm=read.positive('motor.free_speed_rpm'),
            free_current_a=read.nonnegative('motor.free_current_a'),
            datasheet_voltage=read.positive('motor.datasheet_voltage'),
        )
        if motor.free_current_a >= motor.stall_current_a:
            raise ParameterError(
                f"parameter 'motor.free_current_a' = {motor.free_current_a}: "
                f'must be below motor.stall_current_a = {motor.stall_current_a}')
        joints = [_read_joint(read, name) for name in JOINT_NAMES]
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
        )
        presets = tuple((name, *read.numbers(f'presets.{name}', 2))
                        for name in read.strings('presets.names'))
        return cls(
            gravity_mps2=read.nonnegative('gravity_mps2'),
            max_voltage=read.positive('max_voltage'),
            motor=motor, shoulder=joints[0], elbow=joints[1], world=world, presets=presets,
        )


def _read_joint(read: _Reader, name: str) -> JointConfig:
    joint = JointConfig(
        name=name,
        length_m=read.positive(f'{name}.length_m'),
        mass_kg=read.nonnegative(f'{name}.mass_kg'),
        com_from_joint_m=read.nonnegative(f'{name}.com_from_joint_m'),
        inertia_about_com_kgm2=read.nonnegative(f'{name}.inertia_about_com_kgm2'),
        motor_count=read.integer(f'{name}.motor_count', low=1),
        gear_ratio=read.positive(f'{name}.gear_ratio'),
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


@dataclass(frozen=True)
class SimConfig:
    """The simulator's timing, start and noise seed."""

    publish_rate_hz: float
    physics_step_s: float
    command_timeout_s: float
    initial_position: tuple[float, float]
    rest_until_first_command: bool
    random_seed: int

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'SimConfig':
        read = _Reader(params)
        return cls(
            publish_rate_hz=read.number('publish_rate_hz', low=0.0, high=1000.0, low_open=True),
            physics_step_s=read.number('physics_step_s', low=0.0, high=0.001, low_open=True),
            command_timeout_s=read.positive('command_timeout_s'),
            initial_position=read.numbers('initial_position', 2),
            rest_until_first_command=read.boolean('rest_until_first_command'),
            random_seed=read.integer('random_seed', low=-1),
        )


@dataclass(frozen=True)
class ControllerConfig:
    """The controller's loop, tolerances, limits, gains and safety rules."""

    loop_rate_hz: float
    goal_tolerance_rad: float
    settled_velocity_rad_s: float
    dwell_s: float
    goal_queue_size: int
    clamp_unreachable_goals: bool
    tracking_error_limit_rad: float
    tracking_error_time_s: float
    estop_holds_arm: bool
    joint_state_timeout_s: float
    planner_timeout_s: float
    feedback_voltage_reserve: float
    driving_voltage_reserve: float
    max_velocity_rad_s: tuple[float, float]
    max_acceleration_rad_s2: tuple[float, float]
    shoulder_pid: tuple[float, float, float]
    elbow_pid: tuple[float, float, float]
    integrator_limit_v: float
    driver_max_speed_mps: float
    driver_command_timeout_s: float
    process_noise_rad_s2: float

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'ControllerConfig':
        read = _Reader(params)

        def positive_pair(name):
            pair = read.numbers(name, 2)
            if min(pair) <= 0.0:
                raise ParameterError(f"parameter '{name}' = {list(pair)}: must be > 0")
            return pair

        def gains(name):
            triple = read.numbers(name, 3)
            if min(triple) < 0.0:
                raise ParameterError(f"parameter '{name}' = {list(triple)}: gains must be >= 0")
            return triple

        return cls(
            loop_rate_hz=read.number('loop_rate_hz', low=0.0, high=1000.0, low_open=True),
            goal_tolerance_rad=read.positive('goal_tolerance_rad'),
            settled_velocity_rad_s=read.positive('settled_velocity_rad_s'),
            dwell_s=read.nonnegative('dwell_s'),
            goal_queue_size=read.integer('goal_queue_size', low=1),
            clamp_unreachable_goals=read.boolean('clamp_unreachable_goals'),
            tracking_error_limit_rad=read.positive('tracking_error_limit_rad'),
            tracking_error_time_s=read.nonnegative('tracking_error_time_s'),
            estop_holds_arm=read.boolean('estop_holds_arm'),
            joint_state_timeout_s=read.positive('joint_state_timeout_s'),
            planner_timeout_s=read.positive('planner_timeout_s'),
            feedback_voltage_reserve=read.nonnegative('feedback_voltage_reserve'),
            driving_voltage_reserve=read.nonnegative('driving_voltage_reserve'),
            max_velocity_rad_s=positive_pair('max_velocity_rad_s'),
            max_acceleration_rad_s2=positive_pair('max_acceleration_rad_s2'),
            shoulder_pid=gains('shoulder_pid'),
            elbow_pid=gains('elbow_pid'),
            integrator_limit_v=read.nonnegative('integrator_limit_v'),
            driver_max_speed_mps=read.positive('driver_max_speed_mps'),
            driver_command_timeout_s=read.positive('driver_command_timeout_s'),
            process_noise_rad_s2=read.positive('process_noise_rad_s2'),
        )


@dataclass(frozen=True)
class PlannerConfig:
    """The configuration-space grid and the collision-check step."""

    grid_resolution_rad: float
    check_step_rad: float

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'PlannerConfig':
        read = _Reader(params)
        return cls(
            grid_resolution_rad=read.number('grid_resolution_rad', low=0.001, high=0.2),
            check_step_rad=read.number('check_step_rad', low=1e-5, high=0.05),
        )


@dataclass(frozen=True)
class RecorderConfig:
    """Where the recorder writes its bag, and how often it flushes it."""

    output_dir: str
    flush_period_s: float

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'RecorderConfig':
        read = _Reader(params)
        output_dir = read._raw('output_dir')
        if not isinstance(output_dir, str):
            raise ParameterError(f"parameter 'output_dir' = {output_dir!r}: expected a "
                                 'directory name, or empty for one named by the time')
        return cls(output_dir=output_dir, flush_period_s=read.positive('flush_period_s'))


# The nodes whose settings have a class here: checked before a launch starts any node.
NODE_CONFIGS = {'sim': SimConfig, 'controller': ControllerConfig, 'planner': PlannerConfig,
                'recorder': RecorderConfig}


def load(node_name: str, path=None):
    """``(ArmConfig, <node's config>)`` from a parameter file, for tests and benchmarks."""
    params = read_parameter_file(path or default_parameter_file(), node_name)
    node_config = NODE_CONFIGS[node_name]
    return ArmConfig.from_parameters(params), node_config.from_parameters(params)
