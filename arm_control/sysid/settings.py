"""The ``sysid`` node's settings, validated, from its section of config/arm.yaml."""

from dataclasses import dataclass
from typing import Any, Mapping

from arm_control.parameters import ParameterError, Reader


@dataclass(frozen=True)
class SysIdConfig:
    """How the excitation moves the arm, how it is tracked, and how the log is fitted."""

    loop_rate_hz: float
    realtime_priority: int
    hand_over_timeout_s: float
    rest_rad: tuple[float, float]
    max_stall_s: float
    output_directory: str
    fit_only_bag: str
    wpilog_entries: tuple[str, str, str, str]
    centre_rad: tuple[float, float]
    quasistatic_range_rad: tuple[float, float]
    quasistatic_acceleration_rad_s2: float
    fast_sweep_acceleration_rad_s2: float
    dynamic_step_rad: tuple[float, float]
    dynamic_step_time_s: float
    multisine_amplitude_rad: tuple[float, float]
    multisine_band_hz: tuple[float, float]
    multisine_time_s: float
    margin_rad: float
    max_current_a: float
    stage_one_current_share: float
    stage_two_current_share: float
    shoulder_pd: tuple[float, float]
    elbow_pd: tuple[float, float]
    abort_tracking_error_rad: float
    joint_state_timeout_s: float
    smoothing_window_s: float
    max_command_lag_s: float
    min_speed_rad_s: float
    random_seed: int

    @property
    def pd_gains(self) -> tuple[tuple[float, float], tuple[float, float]]:
        return (self.shoulder_pd, self.elbow_pd)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'SysIdConfig':
        read = Reader(params)

        def nonnegative_pair(name):
            pair = read.numbers(name, 2)
            if min(pair) < 0.0:
                raise ParameterError(f"parameter '{name}' = {list(pair)}: must be >= 0")
            return pair

        def text(name):
            value = params.get(name, '')
            if not isinstance(value, str):
                raise ParameterError(f"parameter '{name}' = {value!r}: expected a path")
            return value

        band = nonnegative_pair('multisine_band_hz')
        if not 0.0 < band[0] < band[1]:
            raise ParameterError(f"parameter 'multisine_band_hz' = {list(band)}: "
                                 'expected [low, high] with 0 < low < high')
        entries = params.get('wpilog_entries', ())
        if (not isinstance(entries, (list, tuple)) or len(entries) != 4
                or not all(isinstance(e, str) for e in entries) or not entries[0]
                or not entries[2]):
            raise ParameterError(f"parameter 'wpilog_entries' = {entries!r}: expected four "
                                 'entry names [positions, velocities, applied volts, bus '
                                 "volts], the first and third not ''")
        output_directory = text('output_directory')
        if not output_directory:
            raise ParameterError("parameter 'output_directory' is empty: expected a directory")
        return cls(
            loop_rate_hz=read.number('loop_rate_hz', low=0.0, high=1000.0, low_open=True),
            realtime_priority=read.integer('realtime_priority', low=0, high=98),
            hand_over_timeout_s=read.nonnegative('hand_over_timeout_s'),
            rest_rad=read.numbers('rest_rad', 2),
            max_stall_s=read.nonnegative('max_stall_s'),
            output_directory=output_directory,
            fit_only_bag=text('fit_only_bag'),
            wpilog_entries=tuple(entries),
            centre_rad=read.numbers('centre_rad', 2),
            quasistatic_range_rad=nonnegative_pair('quasistatic_range_rad'),
            quasistatic_acceleration_rad_s2=read.positive('quasistatic_acceleration_rad_s2'),
            fast_sweep_acceleration_rad_s2=read.nonnegative('fast_sweep_acceleration_rad_s2'),
            dynamic_step_rad=nonnegative_pair('dynamic_step_rad'),
            dynamic_step_time_s=read.positive('dynamic_step_time_s'),
            multisine_amplitude_rad=nonnegative_pair('multisine_amplitude_rad'),
            multisine_band_hz=band,
            multisine_time_s=read.nonnegative('multisine_time_s'),
            margin_rad=read.number('margin_rad', low=0.0, high=0.5),
            max_current_a=read.positive('max_current_a'),
            stage_one_current_share=read.number('stage_one_current_share', low=0.0, high=1.0,
                                                low_open=True),
            stage_two_current_share=read.number('stage_two_current_share', low=0.0, high=1.0,
                                                low_open=True),
            shoulder_pd=nonnegative_pair('shoulder_pd'),
            elbow_pd=nonnegative_pair('elbow_pd'),
            abort_tracking_error_rad=read.positive('abort_tracking_error_rad'),
            joint_state_timeout_s=read.positive('joint_state_timeout_s'),
            smoothing_window_s=read.positive('smoothing_window_s'),
            max_command_lag_s=read.number('max_command_lag_s', low=0.0, high=0.5),
            min_speed_rad_s=read.nonnegative('min_speed_rad_s'),
            random_seed=read.integer('random_seed', low=0),
        )
