"""A short profile for the robot to play at its own loop: the format and the player.

A profile is the next setpoints of the arm, one per robot loop, each with its feedforward
volts, and the PD gains the robot closes on its own fresh readings -- as FRC teams use a
motor controller's on-board PID with an arbitrary feedforward (Phoenix 6
``PositionVoltage(...).withFeedForward(...)``). It travels on ``voltage_command``
(std_msgs/Float64MultiArray), and as one double array over NetworkTables::

    layout.dim[0] = {label: 'setpoint', size: N, stride: 6·N}
    layout.dim[1] = {label: FIELDS_LABEL, size: 6, stride: 6}
    layout.data_offset = 6
    data[0] = start_s   when setpoint 0 applies (s, the sender's clock: the readings' stamps)
    data[1] = step_s    seconds between setpoints (the robot's loop period)
    data[2:6] = [shoulder kp V/rad, shoulder kd V·s/rad, elbow kp V/rad, elbow kd V·s/rad]
    data[6 + 6k : 12 + 6k] = setpoint k: [shoulder_rad, elbow_rad, shoulder_rad_s,
                             elbow_rad_s, shoulder_v, elbow_v]

A message of two values is a plain voltage pair [shoulder_V, elbow_V], as ever.

Playing (``ProfilePlayer``), at the robot's loop instant t with its reading (q, q̇):
setpoint k = round((t − start_s)/step_s) within [0, N−1], at t_k = start_s + k·step_s;
q_sp = q_k + q̇_k·(t − t_k), q̇_sp = q̇_k (exact at the instants the sender aimed at, first
order between them); V = V_ff,k + kp·(q_sp − q) + kd·(q̇_sp − q̇), clamped. A profile takes over
from half a step before its start (the instant that rounds to its setpoint 0), never before
it arrived. Past its last setpoint it holds that setpoint's position at rest with its volts:
a profile that ends at rest with its holding volts (the controller's all do) leaves the arm
held when nothing newer comes.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence

FIELDS = ('shoulder_rad', 'elbow_rad', 'shoulder_rad_s', 'elbow_rad_s', 'shoulder_v',
          'elbow_v')
FIELDS_LABEL = ','.join(FIELDS)
SETPOINT_LABEL = 'setpoint'
DATA_OFFSET = 6                 # start_s, step_s, then the four gains
MAX_SETPOINTS = 200
MAX_STEP_S = 0.1                # a robot loop slower than 10 Hz is not one
MAX_ANGLE_RAD = 4.0 * math.pi   # two turns: no sensor of the arm reads beyond
MAX_SPEED_RAD_S = 100.0
MAX_KP_V_PER_RAD = 1000.0
MAX_KD_V_S_PER_RAD = 100.0
MAX_FEEDFORWARD_V = 100.0       # refused beyond; played clamped to the battery's volts


class ProfileError(ValueError):
    """A voltage_command that is neither a voltage pair nor a well-formed profile."""


@dataclass(frozen=True)
class Setpoint:
    position_rad: tuple[float, float]
    velocity_rad_s: tuple[float, float]
    feedforward_v: tuple[float, float]


@dataclass(frozen=True)
class Profile:
    """Setpoints ``step_s`` apart from ``start_s``; ``gains`` = ((kp, kd) shoulder, (kp, kd)
    elbow) in V/rad and V·s/rad."""

    start_s: float
    step_s: float
    gains: tuple[tuple[float, float], tuple[float, float]]
    setpoints: tuple[Setpoint, ...]

    @property
    def end_s(self) -> float:
        """When its last setpoint applies."""
        return self.start_s + (len(self.setpoints) - 1) * self.step_s

    def at(self, t_s: float) -> Setpoint:
        """The setpoint to track at ``t_s`` (the module's rule)."""
        count, step = len(self.setpoints), self.step_s
        k = min(max(math.floor((t_s - self.start_s) / step + 0.5), 0), count - 1)
        setpoint = self.setpoints[k]
        tau = t_s - (self.start_s + k * step)
        if k == count - 1 and tau > 0.5 * step:         # past the end: held at rest
            return Setpoint(setpoint.position_rad, (0.0, 0.0), setpoint.feedforward_v)
        tau = min(max(tau, -0.5 * step), 0.5 * step)
        position = tuple(q + qd * tau for q, qd in zip(setpoint.position_rad,
                                                       setpoint.velocity_rad_s))
        return Setpoint(position, setpoint.velocity_rad_s, setpoint.feedforward_v)


# ---------------------------------------------------------------------- the format


def encode(profile: Profile) -> tuple[list[tuple[str, int, int]], int, list[float]]:
    """(dims as (label, size, stride), data_offset, data) of the message; checked first."""
    count = len(profile.setpoints)
    data = [float(profile.start_s), float(profile.step_s)]
    data += [float(g) for pair in profile.gains for g in pair]
    for s in profile.setpoints:
        data += [float(v) for v in (*s.position_rad, *s.velocity_rad_s, *s.feedforward_v)]
    dims = [(SETPOINT_LABEL, count, 6 * count), (FIELDS_LABEL, 6, 6)]
    decode(data, dims, DATA_OFFSET)                 # a sender never sends what it would refuse
    return dims, DATA_OFFSET, data


def decode(data: Sequence[float], dims: Sequence[tuple[str, int, int]],
           data_offset: int) -> Profile:
    """The profile in a message's data and layout; ProfileError saying what is wrong."""
    data = list(data)
    dims = [tuple(d) for d in dims]
    if len(dims) != 2 or dims[0][0] != SETPOINT_LABEL or dims[1] != (FIELDS_LABEL, 6, 6):
        raise ProfileError(f"profile layout: expected dims [('{SETPOINT_LABEL}', N, 6N), "
                           f"('{FIELDS_LABEL}', 6, 6)], got {[d[:3] for d in dims[:3]]}")
    count = dims[0][1]
    if not 1 <= count <= MAX_SETPOINTS or dims[0][2] != 6 * count:
        raise ProfileError(f'profile layout: {count} setpoints of stride {dims[0][2]}; '
                           f'expected 1 to {MAX_SETPOINTS}, stride 6 per setpoint')
    if data_offset != DATA_OFFSET or len(data) != DATA_OFFSET + 6 * count:
        raise ProfileError(f'profile: data_offset {data_offset} and {len(data)} values; '
                           f'expected {DATA_OFFSET} and {DATA_OFFSET + 6 * count}')
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in data):
        raise ProfileError('profile: every value must be a finite number')
    start_s, step_s = float(data[0]), float(data[1])
    if not 0.0 < step_s <= MAX_STEP_S:
        raise ProfileError(f'profile: step {step_s} s, expected within (0, {MAX_STEP_S}]')
    kp_a, kd_a, kp_b, kd_b = (float(v) for v in data[2:6])
    for name, value, high in (('kp', kp_a, MAX_KP_V_PER_RAD), ('kd', kd_a, MAX_KD_V_S_PER_RAD),
                              ('kp', kp_b, MAX_KP_V_PER_RAD), ('kd', kd_b, MAX_KD_V_S_PER_RAD)):
        if not 0.0 <= value <= high:
            raise ProfileError(f'profile: gain {name} = {value}, expected within [0, {high}]')
    setpoints = []
    for k in range(count):
        q_a, q_b, qd_a, qd_b, v_a, v_b = (float(v) for v in data[6 + 6 * k:12 + 6 * k])
        if max(abs(q_a), abs(q_b)) > MAX_ANGLE_RAD or max(abs(qd_a), abs(qd_b)) > \
                MAX_SPEED_RAD_S or max(abs(v_a), abs(v_b)) > MAX_FEEDFORWARD_V:
            raise ProfileError(f'profile: setpoint {k} out of range: angles within '
                               f'{MAX_ANGLE_RAD:.1f} rad, speeds {MAX_SPEED_RAD_S:g} rad/s, '
                               f'volts {MAX_FEEDFORWARD_V:g} V')
        setpoints.append(Setpoint((q_a, q_b), (qd_a, qd_b), (v_a, v_b)))
    return Profile(start_s, step_s, ((kp_a, kd_a), (kp_b, kd_b)), tuple(setpoints))


def decode_command(data, dims=(), data_offset: int = 0):
    """A voltage_command: a (shoulder_V, elbow_V) pair for two finite values, else a
    Profile; ProfileError otherwise."""
    data = list(data)
    if len(data) == 2:
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in data):
            raise ProfileError(f'voltage pair: expected two finite numbers, got {data}')
        return float(data[0]), float(data[1])
    return decode(data, dims, data_offset)


# ---------------------------------------------------------------------- the robot side


class ProfilePlayer:
    """The robot's side: profiles as they arrive, volts at each loop instant."""

    def __init__(self, max_voltage: float):
        self.max_voltage = float(max_voltage)
        self.profiles: list[Profile] = []        # in order of arrival, the one in force first

    def offer(self, profile: Profile) -> None:
        """A profile just arrived: it takes over at its start (``in_force``)."""
        self.profiles.append(profile)

    def clear(self) -> None:
        self.profiles = []

    def in_force(self, t_s: float) -> Optional[Profile]:
        """The newest profile begun by ``t_s`` (from half a step before its start); None when
        none has."""
        begun = [i for i, p in enumerate(self.profiles) if t_s >= p.start_s - 0.5 * p.step_s]
        if not begun:
            return None
        self.profiles = self.profiles[begun[-1]:]
        return self.profiles[0]

    def volts(self, t_s: float, position_rad, velocity_rad_s) -> Optional[tuple[float, float]]:
        """V = V_ff + kp·(q_sp − q) + kd·(q̇_sp − q̇) per joint at ``t_s`` with the reading
        (q, q̇), within ±max_voltage; None when no profile is in force."""
        profile = self.in_force(t_s)
        if profile is None:
            return None
        setpoint = profile.at(t_s)
        limit = self.max_voltage
        return tuple(min(max(ff + kp * (q_sp - q) + kd * (qd_sp - qd), -limit), limit)
                     for ff, (kp, kd), q_sp, q, qd_sp, qd in zip(
                         setpoint.feedforward_v, profile.gains, setpoint.position_rad,
                         position_rad, setpoint.velocity_rad_s, velocity_rad_s))
