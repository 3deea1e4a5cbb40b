"""Each node's settings (sim, controller, planner, recorder), read from the parameters and
validated; ``load`` layers parameter files for tests, benchmarks and tools."""

from dataclasses import dataclass
import math
from typing import Any, Mapping

from arm_control.config.arm import ArmConfig
from arm_control.parameters import ParameterError, read_parameter_files, Reader

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
    holding_rate_hz: float          # the loop's rate while the arm holds still
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

    @property
    def holding_periods(self) -> int:
        """Periods from one tick to the next while the arm holds still."""
        return round(self.loop_rate_hz / self.holding_rate_hz)

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

        loop_rate_hz = read.number('loop_rate_hz', low=0.0, high=1000.0, low_open=True)
        holding_rate_hz = read.number('holding_rate_hz', low=0.0, high=loop_rate_hz,
                                      low_open=True)
        periods = loop_rate_hz / holding_rate_hz
        if abs(periods - round(periods)) > 1e-6 * periods:
            raise ParameterError(f"parameter 'holding_rate_hz' = {holding_rate_hz:g}: "
                                 f'loop_rate_hz ({loop_rate_hz:g}) must be a whole number of '
                                 f'times it (e.g. {loop_rate_hz / 2:g})')
        return cls(
            loop_rate_hz=loop_rate_hz,
            holding_rate_hz=holding_rate_hz,
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
