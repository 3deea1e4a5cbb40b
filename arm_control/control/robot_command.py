"""What the controller sends the robot, and for which instant.

A robot reads its sensors and applies the latest command it has at its own loop's instants,
so a command acts at the first instant after it arrives: anywhere from 0 to a whole period
after it was sent. Each reading is stamped at one of those instants, so the readings' stamps
give the loop (``RobotClock``): the controller computes each command for the robot's next
instant after it can arrive (with ``ARRIVAL_MARGIN_S`` to spare), ticks just after the
robot's instants (``TICK_AFTER_INSTANT_S``), and sends a profile
(``model/profile.py``) that the robot plays at its loop:

- setpoint 0, at that instant: the reference the controller's step tracks (its
  feedforward's model of the arm), with that step's volts less the share
  (``robot_feedback_share``) of its P and D terms that the robot closes on its own reading
  of the same instant, with that share of the gains. Read where the controller's estimate
  has the arm, the robot applies the controller's volts exactly; what it reads differently
  it corrects at once. The robot's raw potentiometers are noisier than the filtered
  estimate, hence a share: the integral stays in the volts (it is slow);
- setpoints 1 to ``AHEAD - 1``: the motion's own setpoints, one robot period apart -- a
  command that comes a period late, or is lost, leaves the robot on the motion, not on a
  stale voltage. Setpoint 1's volts are the feedforward's for the period after the step's
  (its deadbeat pair) with the step's share of P and D and its integral, the error taken as
  it is; the later ones', the inverse dynamics' at each period's middle;
- then a stop to rest along the path the arm is on (``Setpoints.stopping``), ending at rest
  with its holding volts: played to its end with nothing newer, a profile leaves the arm held.

Its sensors lost (``no_sensors``, or e-stopped holding: ``held_by_robot``), the controller
cannot compute a newer profile, and 0 V would drop the arm: it sends what is left of its
last one (``rest_of``) each period, which the robot plays as it would have (the stop, then
the hold on its own readings). A plain 0 V pair stays the command when the power is cut on
purpose (e-stop, e-stop again, disable) or nothing was sent before.
"""

from collections import deque
from functools import lru_cache
import math
import statistics

import numpy as np

from arm_control.control.state_machine import ArmState
from arm_control.model.profile import Profile, Setpoint

AHEAD = 3                     # setpoints along the motion before the stop
# A command is aimed at the robot's first instant at least this long after it is expected
# to arrive: its compute and its way there vary. One that comes after the instant it was for
# is played a period late (its first setpoint missed, and a motion it starts waits for the
# arm: WAIT_AFTER_PERIODS in control/controller.py), so it costs the period a wider margin
# would have cost whenever the instant fell within the margin.
ARRIVAL_MARGIN_S = 0.001
# Sending profiles, the controller ticks this long after each of the robot's instants: the
# instant's reading has come, and the command reaches the robot well before the next one,
# so every command acts one period after the reading it answers, whatever the phase.
TICK_AFTER_INSTANT_S = 0.003
CLOCK_WINDOW = 25             # readings' gaps the robot's period is the median of
MAX_GAP_PERIODS = 10          # a stamp further ahead than this many periods is off the grid
OFF_GRID_TO_FOLLOW = 5        # readings in a row off the grid before it follows (a moved loop)


class RobotClock:
    """The robot loop's instants, from the stamps of the readings (each taken at one)."""

    def __init__(self, nominal_period_s: float):
        self.nominal_period_s = float(nominal_period_s)
        self.period_s = self.nominal_period_s
        self.last_s = None                     # the latest reading's stamp
        self.gaps_s = deque(maxlen=CLOCK_WINDOW)
        self.off_grid = 0                      # readings in a row off the loop's grid

    def observe(self, stamp_s: float) -> None:
        """A reading stamped ``stamp_s`` (s); a missed reading leaves a gap of whole periods."""
        if not math.isfinite(stamp_s):
            return
        if self.last_s is not None:
            gap = stamp_s - self.last_s
            if -0.5 * self.period_s < gap <= 0.0:
                return                         # the same reading again, or one reordered
            periods = round(gap / self.period_s)
            if not 1 <= periods <= MAX_GAP_PERIODS or \
                    abs(gap - periods * self.period_s) >= 0.25 * self.period_s:
                self.off_grid += 1
                # Off the loop's grid: another publisher's, a stamp across a jump of the
                # clock, or the robot's loop moved. It follows only readings that stay off.
                if self.off_grid < OFF_GRID_TO_FOLLOW:
                    return
                self.gaps_s.clear()
            else:
                self.gaps_s.append(gap / periods)
                median = statistics.median(self.gaps_s)
                self.period_s = min(max(median, 0.5 * self.nominal_period_s),
                                    2.0 * self.nominal_period_s)
        self.off_grid = 0
        self.last_s = float(stamp_s)

    def acting_at(self, arrives_s: float) -> float:
        """The instant a command expected to arrive at ``arrives_s`` is computed for."""
        return self.next_instant(arrives_s + ARRIVAL_MARGIN_S)

    def next_instant(self, t_s: float) -> float:
        """The robot's first instant at or after ``t_s`` that is after its last reading
        (a command cannot act at an instant whose reading it was computed from); ``t_s``
        before any reading."""
        if self.last_s is None:
            return t_s
        periods = max(math.ceil((t_s - self.last_s) / self.period_s - 1e-6), 1)
        return self.last_s + periods * self.period_s


class Commander:
    """What the controller sends and for when (``command_mode``): a profile for the robot's
    instant after the command arrives, or plain volts for its arrival; at 0 V, 0 V."""

    def __init__(self, config):
        self.period_s = config.period_s
        self.clock = RobotClock(config.period_s)
        self.profiles = config.command_mode == 'profile'
        self.last_profile = None        # the last profile sent while the robot plays one

    def tick_due(self, due_s: float) -> float:
        """The controller's next tick, due at ``due_s``, moved to the nearest time
        ``TICK_AFTER_INSTANT_S`` after a robot instant -- when sending profiles to a robot
        whose loop runs at the controller's rate (within 1 %); else ``due_s``."""
        clock = self.clock
        if not self.profiles or clock.last_s is None or \
                abs(clock.period_s - self.period_s) > 0.01 * self.period_s:
            return due_s
        periods = round((due_s - TICK_AFTER_INSTANT_S - clock.last_s) / clock.period_s)
        return clock.last_s + periods * clock.period_s + TICK_AFTER_INSTANT_S

    def acts_s(self, arrives_s: float) -> float:
        """When a command that arrives at ``arrives_s`` acts, as the core computes it."""
        return self.clock.acting_at(arrives_s) if self.profiles else arrives_s

    def command(self, core, voltage, acts_s: float):
        """The core's last step as a Profile from ``acts_s``; its sensors lost, what is left
        of the last profile (the robot holds); else its voltage pair."""
        if self.profiles and not core.unpowered:
            self.last_profile = profile_ahead(core, acts_s, self.clock.period_s)
            return self.last_profile
        lost = core.state == ArmState.NO_SENSORS or core.held_by_robot
        if self.profiles and lost and self.last_profile is not None:
            self.last_profile = rest_of(self.last_profile, acts_s)
            return self.last_profile
        self.last_profile = None                    # a pair in charge: nothing left to hold
        return tuple(float(v) for v in voltage)


def rest_of(profile: Profile, from_s: float) -> Profile:
    """What is left of ``profile`` from the robot's instant ``from_s``: its setpoints from
    the one in force there (``Profile.at``), or, once it is over, its last, held at rest.
    The robot plays it exactly as it would have played ``profile``, and it is not late for
    its first instant."""
    k = math.floor((from_s - profile.start_s) / profile.step_s + 0.5)
    if k <= 0:
        return profile
    if k < len(profile.setpoints):
        return Profile(profile.start_s + k * profile.step_s, profile.step_s, profile.gains,
                       profile.setpoints[k:])
    last = profile.setpoints[-1]
    return Profile(float(from_s), profile.step_s, profile.gains,
                   (Setpoint(last.position_rad, (0.0, 0.0), last.feedforward_v),))


def profile_ahead(core, start_s: float, step_s: float) -> Profile:
    """The profile from the core's last step, taken for the robot's instant ``start_s``,
    its setpoints ``step_s`` apart (the module's rule)."""
    share = core.config.robot_feedback_share
    gains = tuple((share * kp, share * kd) for kp, _, kd in (core.config.shoulder_pid,
                                                             core.config.elbow_pid))
    integral = np.array(core.tracking.pid.integral_v)
    proportional_derivative = np.asarray(core.tracking.feedback_v) - integral
    reference = core.tracking.feedforward.state
    first = Setpoint(tuple(map(float, reference[:2])), tuple(map(float, reference[2:])),
                     tuple(map(float, core.tracking.feedforward_v + integral
                               + (1.0 - share) * proportional_derivative)))
    held_q = _held_q(core.setpoints, start_s)
    if held_q is not None:                   # at rest from the start: every setpoint the hold
        samples = [(held_q, np.zeros(2), np.zeros(2))] * AHEAD
        volts = _hold_volts(core.tracking.feedforward.dynamics, tuple(held_q), AHEAD).copy()
    else:
        stop_s = start_s + AHEAD * step_s
        stop = core.setpoints.stopping(stop_s)
        if stop is None:                     # no motion yet: the reference, held
            return Profile(float(start_s), float(step_s), gains, (first,))
        count = max(math.ceil((stop.end_s - stop_s) / step_s - 1e-9), 0) + 1
        times = list(start_s + step_s * np.arange(1, AHEAD)) + \
            list(stop_s + step_s * np.arange(count))

        def sample(t):
            return core.setpoints.sample(t) if t < stop_s - 1e-9 else stop.sample(t)
        samples = [sample(t) for t in times]
        middles = [sample(t + 0.5 * step_s) for t in times]
        middles[-1] = samples[-1] = (stop.final_q, np.zeros(2), np.zeros(2))   # held, at rest
        volts = core.tracking.feedforward.dynamics.voltages(*(np.array(v) for v in zip(*middles)))
    if AHEAD > 1:                            # setpoint 1: the step's next period
        volts[0] = core.tracking.feedforward.next_voltage + (1.0 - share) * proportional_derivative
    rest = [Setpoint(tuple(map(float, q)), tuple(map(float, qd)), tuple(map(float, v + integral)))
            for (q, qd, _), v in zip(samples, volts)]
    return Profile(float(start_s), float(step_s), gains, (first, *rest))


def _held_q(setpoints, t_s: float):
    """The angle the setpoints rest at from ``t_s`` on, when nothing moves them then (no
    driver; the last motion began by ``t_s`` and is over): the profile's setpoints and their
    middles are then all that hold, at rest, the last one the stop. Else None."""
    last = setpoints.timeline.last
    if setpoints.driving or last is None or last.begin_s > t_s or not last.finished(t_s):
        return None
    return last.final_q


@lru_cache(maxsize=8)
def _hold_volts(dynamics, q: tuple, count: int) -> np.ndarray:
    """The inverse dynamics' volts holding ``q`` at rest, for ``count`` setpoints: as the
    moving profile's (the same arrays), once per held angle."""
    rows = np.tile(np.asarray(q, float), (count, 1))
    return dynamics.voltages(rows, np.zeros((count, 2)), np.zeros((count, 2)))
