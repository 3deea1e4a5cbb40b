"""The motion that identifies the arm, checked safe before it is driven, and how it is tracked.

As WPILib's SysId does per mechanism, each joint in turn makes quasistatic sweeps (its speed
ramped slowly up and down, so gravity and friction dominate: p1, p2, b, c) and dynamic steps
(fast rest-to-rest moves: the inertias α, γ); both joints also move together in a multi-sine
(the coupling and Coriolis terms, and every parameter at once), and each joint sweeps its
range again with its speed ramped fast, to about 2 rad/s (viscous friction b·θ̇ grows with
the speed and Coulomb friction does not: at the slow sweeps' speeds the two trade against
each other). All of it moves about a centre configuration and returns there between parts.
(``session`` runs the slow sweeps and the multi-sine first, and designs the fast sweeps and
the steps with what they taught.)

Before anything is driven, ``design_excitation`` samples every part every 5 ms and checks it
with the model it is given: clear of forbidden space by ``margin_rad`` on both joints, and
with the feedforward needing at most a share of ``max_current_a`` per motor (the rest is
room for feedback and for the model being wrong). A part that fails is made smaller (and a
step slower) until it passes, or dropped; each change is reported.

``ExcitationRun`` tracks it: the model's inverse dynamics as feedforward plus PD on the
joint_states, every command clamped so that no motor draws more than ``max_current_a``
(|V − G·ω/Kv|/R per motor) -- under the motor controllers' own limit, so every command is
applied as sent and the log holds the voltage the arm really got; the limit is kept at the
speed the arm has now and at the speed it will have a period on, as the command is held that
long. It stops (and glides back to the centre) if the arm strays from the plan or nears
forbidden space. A gap in the commands (the node starved of CPU: meanwhile the arm got the
last command, then 0 V) up to ``max_stall_s`` is ridden through: the plan rejoins the
excitation from where the arm is, with a quintic from its state to the excitation's at the
instant the commands stopped, and goes on from there.
"""

from dataclasses import dataclass
import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.world import ForbiddenSpace
from arm_control.sysid.segments import Hold, Join, MultiSine, Quintic, Sweep, Tail
from arm_control.sysid.settings import SysIdConfig

CHECK_STEP_S = 0.005
FEEDBACK_HEADROOM_V = 2.0       # the planned feedforward leaves this much of max_voltage
SHRINK = 0.85                   # a part that fails is scaled by this and checked again ...
SHRINK_TRIES = 12               # ... at most this many times, then dropped
PAUSE_S = 0.3                   # rest at the centre between parts
MULTISINE_TONES = 5             # per joint
MULTISINE_RAMP_S = 1.5          # the multi-sine fades in and out over this
APPROACH_SPEED_RAD_S = 0.4      # moving to the centre first, and gliding back after a stop
STALL_PERIODS = 2.5             # commands further apart than this many periods: a stall
BUS_MARGIN_V = 0.3              # commands stay this far under the last bus voltage reported
BRAKE_RAD_S2 = 8.0              # a stalled arm is first brought to rest at about this rate,
BRAKE_MIN_S = 0.25              # over at least this long, then rejoins the plan


@dataclass(frozen=True)
class Part:
    name: str
    segments: tuple


class Excitation:
    """Parts one after another: ``sample(t)`` over the whole, and which part is where."""

    def __init__(self, parts):
        self.parts = tuple(parts)
        self.segments = [s for part in self.parts for s in part.segments]
        self.labels = [part.name for part in self.parts for _ in part.segments]
        self.starts_s = np.concatenate([[0.0], np.cumsum([s.duration_s
                                                          for s in self.segments])])
        self.duration_s = float(self.starts_s[-1])

    def sample(self, t):
        """q, q̇, q̈ (each (N, 2)) at times t; before 0 the start, after the end the end."""
        t = np.atleast_1d(np.asarray(t, float))
        index = np.clip(np.searchsorted(self.starts_s, t, side='right') - 1,
                        0, len(self.segments) - 1)
        q, qd, qdd = (np.zeros((len(t), 2)) for _ in range(3))
        for k in np.unique(index):
            where = index == k
            local = np.clip(t[where] - self.starts_s[k], 0.0, self.segments[k].duration_s)
            q[where], qd[where], qdd[where] = self.segments[k].sample(local)
        return q, qd, qdd

    def after(self, t) -> list:
        """The parts left from time ``t`` on (the one under way cut at ``t``)."""
        parts, start = [], 0.0
        for part in self.parts:
            left = []
            for segment in part.segments:
                end = start + segment.duration_s
                if end > t:
                    left.append(segment if start >= t else Tail(segment, t - start))
                start = end
            if left:
                parts.append(Part(part.name, tuple(left)))
        return parts

    def label_at(self, t) -> list:
        index = np.clip(np.searchsorted(self.starts_s, np.atleast_1d(t), side='right') - 1,
                        0, len(self.segments) - 1)
        return [self.labels[k] for k in index]


def per_motor_current_a(dynamics: ArmDynamics, arm: ArmConfig, joint: int, voltage,
                        speed_rad_s):
    """(V − G·ω/Kv)/R for one motor of ``joint``."""
    return dynamics.motors[joint].current_a(voltage, speed_rad_s)


def voltage_range_for_current(dynamics, arm, joint, speed_rad_s, max_current_a):
    """The voltages at which one motor of ``joint`` draws at most ``max_current_a``."""
    at_zero = per_motor_current_a(dynamics, arm, joint, 0.0, speed_rad_s)
    per_volt = per_motor_current_a(dynamics, arm, joint, 1.0, speed_rad_s) - at_zero
    return ((-max_current_a - at_zero) / per_volt, (max_current_a - at_zero) / per_volt)


def feedforward(dynamics: ArmDynamics, q, qd, qdd) -> np.ndarray:
    """The voltages the model says a motion needs, (N, 2)."""
    return np.array([dynamics.voltage_for(a, b, c) for a, b, c in zip(q, qd, qdd)])


def check_segments(segments, arm: ArmConfig, settings: SysIdConfig,
                   forbidden: ForbiddenSpace, dynamics: ArmDynamics,
                   current_share: float) -> str | None:
    """Why the motion is unsafe to drive (a sentence), or None when it is safe."""
    for segment in segments:
        t = np.arange(0.0, segment.duration_s + CHECK_STEP_S, CHECK_STEP_S)
        q, qd, qdd = segment.sample(np.minimum(t, segment.duration_s))
        free = np.asarray(forbidden.is_free(q))
        if not np.all(free):
            first = q[np.argmin(free)]
            return (f'it comes within {math.degrees(settings.margin_rad):.1f} deg of forbidden '
                    f'space at [{math.degrees(first[0]):.1f}, {math.degrees(first[1]):.1f}] deg')
        voltage = feedforward(dynamics, q, qd, qdd)
        limit_v = arm.battery.nominal_voltage - FEEDBACK_HEADROOM_V
        if np.max(np.abs(voltage)) > limit_v:
            return (f'its feedforward needs {np.max(np.abs(voltage)):.1f} V, more than '
                    f'{limit_v:.1f} V')
        allowed_a = current_share * settings.max_current_a
        for joint in range(2):
            current = np.abs(per_motor_current_a(dynamics, arm, joint, voltage[:, joint],
                                                 qd[:, joint]))
            if np.max(current) > allowed_a:
                return (f'the {arm.joints[joint].name} needs {np.max(current):.0f} A per '
                        f'motor, more than {allowed_a:.0f} A')
    return None


def _sweeps(centre, joint, reach, a):
    out = Sweep(centre, joint, reach, a)
    across = Sweep(out.end_rad, joint, -2.0 * reach, a)
    back = Sweep(across.end_rad, joint, reach, a)
    return (out, across, back, Hold(centre, PAUSE_S))


def _steps(centre, joint, reach, duration_s):
    target = np.array(centre, float)
    target[joint] += reach
    other = np.array(centre, float)
    other[joint] -= reach
    return (Quintic(centre, target, duration_s), Hold(target, PAUSE_S),
            Quintic(target, other, duration_s * math.sqrt(2.0)), Hold(other, PAUSE_S),
            Quintic(other, centre, duration_s), Hold(centre, PAUSE_S))


def _multisine(centre, settings, scale):
    """Log-spaced tones over the band, alternating between the joints so none is shared;
    amplitudes ∝ 1/f (each tone the same speed) summing to the joint's largest excursion."""
    rng = np.random.default_rng(settings.random_seed)
    low, high = settings.multisine_band_hz
    tones = np.geomspace(low, high, 2 * MULTISINE_TONES)
    # Whole cycles over the motion, so the tones stay apart in frequency.
    duration = settings.multisine_time_s
    tones = np.maximum(np.round(tones * duration), 1.0) / duration
    frequencies = np.stack([tones[0::2], tones[1::2]])
    weights = 1.0 / frequencies
    amplitudes = (weights / weights.sum(axis=1, keepdims=True)
                  * np.asarray(settings.multisine_amplitude_rad)[:, None] * scale)
    phases = rng.uniform(0.0, 2.0 * math.pi, frequencies.shape)
    return (MultiSine(centre, amplitudes, frequencies, phases, duration, MULTISINE_RAMP_S),
            Hold(centre, PAUSE_S))


QUASISTATIC, MULTISINE, FAST, DYNAMIC = 'quasistatic', 'multi-sine', 'fast sweeps', 'dynamic'


def design_excitation(arm: ArmConfig, settings: SysIdConfig, start_rad=None,
                      kinds=(QUASISTATIC, MULTISINE, FAST, DYNAMIC), current_share=None):
    """The excitation about ``settings.centre_rad``, every part checked and shrunk until safe.

    ``kinds`` picks the parts, in this order: each joint's quasistatic sweeps, the coupled
    multi-sine, each joint's fast sweeps, each joint's dynamic steps. Returns
    ``(Excitation, notes)``; with ``start_rad`` (where the arm is) it begins with a gentle
    move from there to the centre, checked free of forbidden space (no margin: the arm may
    rest near it). Raises ValueError if the centre or that move is unsafe, or if no part can
    be made safe. The feedforward may need ``current_share`` of ``max_current_a`` (default:
    stage 1's).
    """
    if current_share is None:
        current_share = settings.stage_one_current_share
    dynamics = ArmDynamics(arm)
    forbidden = ForbiddenSpace(arm, settings.margin_rad)
    centre = np.array(settings.centre_rad, float)
    if not forbidden.is_free(centre):
        raise ValueError(f'the excitation centre {list(settings.centre_rad)} rad is not clear '
                         f'of forbidden space by margin_rad: '
                         f'{forbidden.why_forbidden(centre) or "too close"}')
    notes, parts = [], []
    if start_rad is not None:
        start = np.asarray(start_rad, float)
        distance = float(np.max(np.abs(centre - start)))
        if distance > 1e-3:
            if not ForbiddenSpace(arm).segment_is_free(start, centre, 0.001745):
                raise ValueError(
                    f'the straight move from the arm at {np.round(start, 3).tolist()} rad to '
                    f'the centre {list(settings.centre_rad)} rad crosses forbidden space: '
                    'move the arm nearer the centre first')
            duration = max(1.0, 1.875 * distance / APPROACH_SPEED_RAD_S)
            parts.append(Part('to the centre', (Quintic(start, centre, duration),
                                                Hold(centre, PAUSE_S))))

    builders = []
    for joint, name in enumerate(('shoulder', 'elbow')):
        reach = settings.quasistatic_range_rad[joint]
        if QUASISTATIC in kinds and reach > 0.0:
            builders.append((f'{name} {QUASISTATIC}',
                             lambda s, j=joint, r=reach: _sweeps(
                                 centre, j, r * s, settings.quasistatic_acceleration_rad_s2)))
    if (MULTISINE in kinds and settings.multisine_time_s > 0.0
            and max(settings.multisine_amplitude_rad) > 0.0):
        builders.append((f'coupled {MULTISINE}', lambda s: _multisine(centre, settings, s)))
    for joint, name in enumerate(('shoulder', 'elbow')):
        reach = settings.quasistatic_range_rad[joint]
        fast = settings.fast_sweep_acceleration_rad_s2
        if FAST in kinds and reach > 0.0 and fast > 0.0:
            builders.append((f'{name} {FAST}', lambda s, j=joint, r=reach, a=fast: _sweeps(
                centre, j, r * math.sqrt(s), a * s)))
    for joint, name in enumerate(('shoulder', 'elbow')):
        reach = settings.dynamic_step_rad[joint]
        if DYNAMIC in kinds and reach > 0.0:
            builders.append((f'{name} {DYNAMIC}', lambda s, j=joint, r=reach: _steps(
                centre, j, r * math.sqrt(s), settings.dynamic_step_time_s / math.sqrt(s))))

    for name, build in builders:
        scale = 1.0
        for _ in range(SHRINK_TRIES + 1):
            segments = build(scale)
            problem = check_segments(segments, arm, settings, forbidden, dynamics,
                                     current_share)
            if problem is None:
                break
            scale *= SHRINK
        if problem is not None:
            notes.append(f'{name}: dropped, {problem} even at {scale / SHRINK:.0%} of its size')
            continue
        if scale < 1.0:
            notes.append(f'{name}: at {scale:.0%} of its size, to keep it safe')
        parts.append(Part(name, segments))
    if builders and not any(part.name != 'to the centre' for part in parts):
        raise ValueError('no part of the excitation can be made safe: ' + '; '.join(notes))
    return Excitation(parts), notes


class ExcitationRun:
    """Drives an ``Excitation``: ``command(now_s, position, velocity)`` gives the voltages.

    V = V_ff(q_ref, q̇_ref, q̈_ref) + kp·(q_ref − q) + kd·(q̇_ref − q̇), with V_ff from the robot
    file's inverse dynamics, then clamped to ±max_voltage (±(bus − ``BUS_MARGIN_V``) when the
    bus voltage is known: the battery sags under load) and to the voltages at which each
    motor draws at most ``max_current_a``. Time starts at the first command. ``finished``
    once the excitation (or, after a stop, the glide back) is over; ``stopped`` says why it
    stopped early, if it did.
    """

    def __init__(self, arm: ArmConfig, settings: SysIdConfig, excitation: Excitation):
        self.arm, self.settings, self.excitation = arm, settings, excitation
        self.dynamics = ArmDynamics(arm)
        self.watch = ForbiddenSpace(arm, settings.margin_rad / 2.0)
        self.free_space = ForbiddenSpace(arm)
        self.gains = np.array(settings.pd_gains)
        self.motion = excitation
        self.began_s = None
        self.motion_began_s = 0.0
        self.stopped = None                   # the reason, once stopped early
        self.current_clamped = 0              # commands the current limit changed
        self.reference = None                 # (q, q̇) the last command was computed for
        self.last_s = self.last_velocity = None
        self.stalls = []                      # (when, how long) of each gap ridden through

    def elapsed_s(self, now_s) -> float:
        return 0.0 if self.began_s is None else now_s - self.began_s

    def finished(self, now_s) -> bool:
        return (self.began_s is not None
                and now_s - self.motion_began_s >= self.motion.duration_s)

    def label_at(self, now_s) -> str:
        if self.stopped is not None:
            return 'stopped'
        return self.motion.label_at(now_s - self.motion_began_s)[0]

    def command(self, now_s, position, velocity, bus_v=None) -> np.ndarray:
        if self.began_s is None:
            self.began_s = self.motion_began_s = now_s
        position, velocity = np.asarray(position, float), np.asarray(velocity, float)
        gap = now_s - self.last_s if self.last_s is not None else 0.0
        if gap > STALL_PERIODS / self.settings.loop_rate_hz:
            if self.stopped is None and gap > self.settings.max_stall_s:
                self.stop(now_s, position, f'the commands stalled for {gap:.2f} s '
                          f'(max_stall_s {self.settings.max_stall_s:g} s)')
            else:
                self.rejoin(now_s, position, velocity, gap)
            self.last_velocity = None
        q_ref, qd_ref, qdd_ref = (v[0] for v in self.motion.sample(now_s - self.motion_began_s))
        if self.stopped is None:
            problem = self._problem(position, q_ref)
            if problem is not None:
                self.stop(now_s, position, problem)
                q_ref, qd_ref, qdd_ref = (v[0] for v in self.motion.sample(0.0))
        self.reference = (q_ref, qd_ref)
        voltage = (np.array(self.dynamics.voltage_for(q_ref, qd_ref, qdd_ref))
                   + self.gains[:, 0] * (q_ref - position)
                   + self.gains[:, 1] * (qd_ref - velocity))
        # Under the bus voltage the robot last reported, so that the motor controllers apply
        # each command as sent (above it they apply the bus, which the log would not hold).
        volts = self.arm.battery.nominal_voltage
        if bus_v is not None and math.isfinite(bus_v):
            volts = max(min(volts, bus_v - BUS_MARGIN_V), 0.0)
        voltage = np.clip(voltage, -volts, volts)
        clamped = voltage.copy()
        # The speed a period on, extrapolated: the command is held until then.
        ahead = velocity if self.last_velocity is None else 2.0 * velocity - self.last_velocity
        self.last_s, self.last_velocity = now_s, velocity
        for joint in range(2):
            now_low, now_high = voltage_range_for_current(
                self.dynamics, self.arm, joint, velocity[joint], self.settings.max_current_a)
            next_low, next_high = voltage_range_for_current(
                self.dynamics, self.arm, joint, ahead[joint], self.settings.max_current_a)
            # Within the limit now in any case; a period on too, as far as that allows.
            low = min(max(now_low, next_low), now_high)
            high = max(min(now_high, next_high), low)
            clamped[joint] = min(max(voltage[joint], low), high)
        if np.any(clamped != voltage):
            self.current_clamped += 1
        return clamped

    def rejoin(self, now_s, position, velocity, gap_s) -> None:
        """After a gap in the commands: a quintic from the arm's state to the plan's at the
        last command, then the rest of the plan."""
        t = self.last_s - self.motion_began_s
        left = self.motion.after(t)
        if left:
            target = [v[0] for v in self.motion.sample(t)]
        else:
            end = self.motion.segments[-1].end_rad
            target, left = (end, np.zeros(2), np.zeros(2)), [Part('holding', (Hold(end,
                                                                                   PAUSE_S),))]
        # Brake: a quintic to rest, stopping where a constant deceleration would.
        brake_s = max(BRAKE_MIN_S, float(np.max(np.abs(velocity))) / BRAKE_RAD_S2)
        stop = position + 0.5 * velocity * brake_s
        brake = Join((position, velocity, np.zeros(2)), (stop, np.zeros(2), np.zeros(2)),
                     brake_s)
        duration = max(1.0, 1.875 * float(np.max(np.abs(target[0] - stop)))
                       / APPROACH_SPEED_RAD_S)
        join = Join((stop, np.zeros(2), np.zeros(2)), target, duration)
        self.motion = Excitation([Part('rejoining after a stall', (brake, join))] + left)
        self.motion_began_s = now_s
        self.stalls.append((now_s, gap_s))

    def _problem(self, position, q_ref):
        error = np.abs(q_ref - position)
        if np.max(error) > self.settings.abort_tracking_error_rad:
            joint = int(np.argmax(error))
            return (f'the {self.arm.joints[joint].name} strayed {math.degrees(error[joint]):.1f}'
                    f' deg from the excitation (abort_tracking_error_rad '
                    f'{math.degrees(self.settings.abort_tracking_error_rad):.1f} deg)')
        if not self.watch.is_free(position):
            return (f'the arm at [{math.degrees(position[0]):.1f}, '
                    f'{math.degrees(position[1]):.1f}] deg came within '
                    f'{math.degrees(self.watch.margin_rad):.1f} deg of forbidden space')
        return None

    def stop(self, now_s, position, reason: str) -> None:
        """Stop the excitation: glide back to the centre if the straight way is free, else
        hold where the arm is, for at least a second."""
        self.stopped = reason
        centre = np.array(self.settings.centre_rad, float)
        position = np.asarray(position, float)
        distance = float(np.max(np.abs(centre - position)))
        if self.free_space.segment_is_free(position, centre, 0.001745):
            glide = Quintic(position, centre,
                            max(1.0, 1.875 * distance / APPROACH_SPEED_RAD_S))
            self.motion = Excitation([Part('stopped', (glide, Hold(centre, PAUSE_S)))])
        else:
            self.motion = Excitation([Part('stopped', (Hold(position, 1.0),))])
        self.motion_began_s = now_s
