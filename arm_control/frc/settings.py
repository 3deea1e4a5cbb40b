"""The bridge's and the robot stand-in's settings, validated, from ``config/arm.yaml``
(sections ``/frc_bridge`` and ``/frc_robot_sim``)."""

from dataclasses import dataclass, replace
from typing import Any, Mapping

from arm_control.model.profile import MAX_KD_V_S_PER_RAD, MAX_KP_V_PER_RAD
from arm_control.parameters import ParameterError, read_parameter_files, Reader

MODES = ('voltage', 'setpoint')


def _string(params: Mapping[str, Any], name: str) -> str:
    value = params.get(name)
    if not isinstance(value, str):
        raise ParameterError(f"parameter '{name}' = {value!r}: expected a string")
    return value.strip()


def _port(read: Reader, name: str) -> int:
    port = read.integer(name, low=1)
    if port > 65535:
        raise ParameterError(f"parameter '{name}' = {port}: a TCP port is at most 65535")
    return port


def _phase(phase_s: float, rate_hz: float, name: str) -> float:
    if not 0.0 <= phase_s < 1.0 / rate_hz:
        raise ParameterError(f"parameter '{name}' = {phase_s}: expected a phase within the "
                             f'loop period, 0 <= phase < {1.0 / rate_hz:g} s')
    return float(phase_s)


@dataclass(frozen=True)
class FrcBridgeConfig:
    """Where the robot is, what to send it, when it counts as lost, and where to log."""

    team_number: int
    server_address: str
    nt_port: int
    mode: str
    setpoint_gains: tuple[tuple[float, float], tuple[float, float]]   # ((kp, kd), (kp, kd))
    reading_timeout_s: float
    wpilog_path: str
    realtime_priority: int          # SCHED_FIFO priority of every thread; 0: normal

    @property
    def server(self) -> str:
        """The NT server, as people say it."""
        if self.team_number:
            return f'team {self.team_number} (port {self.nt_port})'
        return f'{self.server_address}:{self.nt_port}'

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'FrcBridgeConfig':
        read = Reader(params)
        team = read.integer('team_number', low=0)
        if team > 25599:
            raise ParameterError(f"parameter 'team_number' = {team}: FRC team numbers are "
                                 'at most 25599 (10.TE.AM.2)')
        address = _string(params, 'server_address')
        if not team and not address:
            raise ParameterError("parameter 'server_address' is empty and 'team_number' is 0: "
                                 'say where the robot is')
        mode = _string(params, 'mode')
        if mode not in MODES:
            raise ParameterError(f"parameter 'mode' = {mode!r}: expected one of {list(MODES)}")
        gains = []
        for name in ('shoulder_pd', 'elbow_pd'):
            kp, kd = read.numbers(name, 2)
            if not (0.0 <= kp <= MAX_KP_V_PER_RAD and 0.0 <= kd <= MAX_KD_V_S_PER_RAD):
                raise ParameterError(f"parameter '{name}' = {[kp, kd]}: expected kp within "
                                     f'[0, {MAX_KP_V_PER_RAD:g}] V/rad and kd within '
                                     f'[0, {MAX_KD_V_S_PER_RAD:g}] V s/rad')
            gains.append((kp, kd))
        return cls(team_number=team, server_address=address, nt_port=_port(read, 'nt_port'),
                   mode=mode, setpoint_gains=tuple(gains),
                   reading_timeout_s=read.positive('reading_timeout_s'),
                   realtime_priority=read.integer('realtime_priority', low=0, high=98),
                   wpilog_path=_string(params, 'wpilog_path'))


@dataclass(frozen=True)
class FrcRobotSimConfig:
    """The robot stand-in's loop, command timeout and port."""

    nt_port: int
    loop_rate_hz: float
    loop_phase_s: float
    command_timeout_s: float
    start_enabled: bool
    realtime_priority: int          # SCHED_FIFO priority of every thread; 0: normal

    def with_phase(self, phase_s: float) -> 'FrcRobotSimConfig':
        return replace(self, loop_phase_s=_phase(phase_s, self.loop_rate_hz, 'loop_phase_s'))

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'FrcRobotSimConfig':
        read = Reader(params)
        rate_hz = read.number('loop_rate_hz', low=0.0, high=1000.0, low_open=True)
        return cls(
            nt_port=_port(read, 'nt_port'),
            loop_rate_hz=rate_hz,
            loop_phase_s=_phase(read.number('loop_phase_s'), rate_hz, 'loop_phase_s'),
            command_timeout_s=read.positive('command_timeout_s'),
            start_enabled=read.boolean('start_enabled'),
            realtime_priority=read.integer('realtime_priority', low=0, high=98),
        )


def load_robot_sim(*paths) -> FrcRobotSimConfig:
    """The stand-in's settings: the defaults with ``paths`` layered over them."""
    return FrcRobotSimConfig.from_parameters(read_parameter_files(paths, 'frc_robot_sim'))
