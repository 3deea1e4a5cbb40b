"""The arm description and each node's settings: frozen, validated, read once.

Parameters arrive as a flat mapping of dotted names to values (``arm_control.parameters``),
what a ROS parameter file holds and what a node's declared parameters give back. They are
validated here, so a bad value fails at start with a message naming the parameter and its
value. ``config/arm.yaml`` is the one source of every default.
"""

from dataclasses import dataclass
import functools
import math
from typing import Any, Mapping

from arm_control.parameters import ParameterError, read_parameter_files, Reader

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


# When the sim applies a command: at the robot loop's next instant, or the instant it arrives.
COMMAND_TIMINGS = ('robot_loop', 'on_arrival')
# What the controller sends on voltage_command: a profile (model/profile.py), or plain volts.
COMMAND_MODES = ('profile', 'volts')


@dataclass(frozen=True)
class SimConfig:
    """The simulator's timing, start and noise seed."""

    publish_rate_hz: float
    ground_truth_rate_hz: float     # the true state's samples, published with each reading
    physics_step_s: float
    command_timeout_s: float
    initial_position: tuple[float, float]
    rest_until_first_command: bool
    random_seed: int
    sim_time_factor: float          # 0: the node's clock; else /clock at this × real time
    realtime_priority: int          # SCHED_FIFO priority of the stepping thread; 0: normal
    command_timing: str = 'robot_loop'  # or 'on_arrival' (COMMAND_TIMINGS)
    robot_loop_phase_s: float = 0.0     # the loop's instants, past each whole period

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'SimConfig':
        read = Reader(params)
        publish_rate_hz = read.number('publish_rate_hz', low=0.0, high=1000.0, low_open=True)
        timing = read.text('command_timing')
        if timing not in COMMAND_TIMINGS:
            raise ParameterError(f"parameter 'command_timing' = {timing!r}: expected one of "
                                 f'{list(COMMAND_TIMINGS)}')
        return cls(
            publish_rate_hz=publish_rate_hz,
            ground_truth_rate_hz=read.number('ground_truth_rate_hz', low=publish_rate_hz,
                                             high=1000.0),
            physics_step_s=read.number('physics_step_s', low=0.0, high=0.001, low_open=True),
            command_timeout_s=read.positive('command_timeout_s'),
            initial_position=read.numbers('initial_position', 2),
            rest_until_first_command=read.boolean('rest_until_first_command'),
            random_seed=read.integer('random_seed', low=-1),
            sim_time_factor=read.number('sim_time_factor', low=0.0, high=100.0),
            realtime_priority=read.integer('realtime_priority', low=0, high=98),
            command_timing=timing,
            robot_loop_phase_s=read.number('robot_loop_phase_s', low=0.0,
                                           high=1.0 / publish_rate_hz, low_open=False),
        )


@dataclass(frozen=True)
class ControllerConfig:
    """The controller's loop, tolerances, limits, gains and safety rules."""

    loop_rate_hz: float
    realtime_priority: int          # SCHED_FIFO priority of the loop's thread; 0: normal
    planning_priority: int          # SCHED_FIFO priority of a goal's quick timing; 0: normal
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
    max_velocity_rad_s: tuple[float, float]         # inf: no cap beyond the motors'
    max_acceleration_rad_s2: tuple[float, float]    # inf: no cap beyond the motors'
    shoulder_pid: tuple[float, float, float]
    elbow_pid: tuple[float, float, float]
    integrator_limit_v: float
    driver_max_speed_mps: float
    driver_command_timeout_s: float
    process_noise_rad_s2: float
    command_mode: str = 'profile'           # or 'volts' (COMMAND_MODES)
    robot_feedback_share: float = 0.25      # of the PD gains, closed by the robot in a profile

    @property
    def period_s(self) -> float:
        return 1.0 / self.loop_rate_hz

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'ControllerConfig':
        read = Reader(params)

        def caps(name):
            pair = read.numbers(name, 2)
            if min(pair) < 0.0:
                raise ParameterError(f"parameter '{name}' = {list(pair)}: must be >= 0 "
                                     '(0: no cap beyond what the motors give)')
            return tuple(v if v > 0.0 else math.inf for v in pair)

        mode = read.text('command_mode')
        if mode not in COMMAND_MODES:
            raise ParameterError(f"parameter 'command_mode' = {mode!r}: expected one of "
                                 f'{list(COMMAND_MODES)}')

        def gains(name):
            triple = read.numbers(name, 3)
            if min(triple) < 0.0:
                raise ParameterError(f"parameter '{name}' = {list(triple)}: gains must be >= 0")
            return triple

        return cls(
            loop_rate_hz=read.number('loop_rate_hz', low=0.0, high=1000.0, low_open=True),
            realtime_priority=read.integer('realtime_priority', low=0, high=98),
            planning_priority=read.integer('planning_priority', low=0, high=98),
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
            max_velocity_rad_s=caps('max_velocity_rad_s'),
            max_acceleration_rad_s2=caps('max_acceleration_rad_s2'),
            shoulder_pid=gains('shoulder_pid'),
            elbow_pid=gains('elbow_pid'),
            integrator_limit_v=read.nonnegative('integrator_limit_v'),
            driver_max_speed_mps=read.positive('driver_max_speed_mps'),
            driver_command_timeout_s=read.positive('driver_command_timeout_s'),
            process_noise_rad_s2=read.positive('process_noise_rad_s2'),
            command_mode=mode,
            robot_feedback_share=read.number('robot_feedback_share', low=0.0, high=1.0),
        )

    def check_against(self, arm: ArmConfig) -> None:
        """Settings that only make sense for this arm: each reserve leaves the trajectory
        some of the battery's volts."""
        for name in ('driving_voltage_reserve', 'feedback_voltage_reserve'):
            reserve = getattr(self, name)
            if reserve >= arm.battery.nominal_voltage:
                raise ParameterError(
                    f"parameter '{name}' = {reserve}: leaves nothing of "
                    f'battery.nominal_voltage = {arm.battery.nominal_voltage} V for the '
                    'trajectory')


@dataclass(frozen=True)
class PlannerConfig:
    """The configuration-space grid, and the planner's priority once prepared."""

    grid_resolution_rad: float
    realtime_priority: int = 0      # SCHED_FIFO priority once prepared; 0: normal

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'PlannerConfig':
        read = Reader(params)
        return cls(grid_resolution_rad=read.number('grid_resolution_rad', low=0.001, high=0.2),
                   realtime_priority=read.integer('realtime_priority', low=0, high=98))


@dataclass(frozen=True)
class RecorderConfig:
    """Where the recorder writes its bag, and how often it flushes it."""

    output_dir: str
    flush_period_s: float

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'RecorderConfig':
        read = Reader(params)
        output_dir = read.params.get('output_dir')
        if not isinstance(output_dir, str):
            raise ParameterError(f"parameter 'output_dir' = {output_dir!r}: expected a "
                                 'directory name, or empty for one named by the time')
        return cls(output_dir=output_dir, flush_period_s=read.positive('flush_period_s'))


# The nodes whose settings have a class here: checked before a launch starts any node.
NODE_CONFIGS = {'sim': SimConfig, 'controller': ControllerConfig, 'planner': PlannerConfig,
                'recorder': RecorderConfig}


def load(node_name: str, *paths):
    """``(ArmConfig, <node's config>)`` from the defaults with ``paths`` layered over them,
    for tests, benchmarks and tools (nodes read their declared parameters instead)."""
    params = read_parameter_files(paths, node_name)
    arm = ArmConfig.from_parameters(params)
    node_config = NODE_CONFIGS[node_name].from_parameters(params)
    if isinstance(node_config, ControllerConfig):
        node_config.check_against(arm)
    return arm, node_config
