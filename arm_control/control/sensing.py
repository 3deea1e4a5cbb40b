"""The controller's view of the arm: the Kalman estimate, how fresh it is, and whether the arm
was put somewhere else under it.

Each reading is folded in at the time it was taken: the filter predicts with the voltage the
motor controllers applied (the command within the current limits and the bus voltage the
robot reports, as a roboRIO reads its own), updates, then predicts up to now. The prediction
to now is made afresh each period from the last reading folded in, with each command over
the time it acted: a reading taken before the instant the last prediction was for (through
ROS, one that came just after a tick, and the controller works at the instant its command
will act) is still folded in at its own time, not at that later one.

The battery's open-circuit voltage, V_bus + R_battery·I_supply from the same reading, is
what the control ahead uses: it changes slowly, while the bus itself swings with every
command, so a bus reading even a period old would clamp the next command to a sag that has
passed (through ROS: the tool 38-71 mm below its path at the end of a fast move).
"""

from dataclasses import dataclass
import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.control.estimator import ArmEstimator
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.electrical import PowerSupply

# A sensor jump means the arm was put elsewhere only if the potentiometers moved farther
# between two readings than this many times the motors' free speed allows (plus the margin,
# for noise); else the arm is falling or pushed, for the tracking-error rule to judge.
LEAP_SPEED_FACTOR = 3.0
LEAP_MARGIN_RAD = 0.05
# A leap of the potentiometers is refused where the encoders put the arm within this of the
# estimate (their backlash and noise are a fraction of it), while readings that did not leap
# came within TRUSTED_SOURCE_S (s); after that the leap is taken: the source it trusted is gone.
ENCODERS_AGREE_RAD = 0.05
TRUSTED_SOURCE_S = 0.1
# The prediction from the last reading is kept as the filter's state once it reaches this far
# (the sensors silent: no prediction grows without end; a later reading older than that is
# folded in there).
KEEP_PREDICTION_AFTER_S = 0.1
# A command that acts within this of a reading's instant acts at it (s): the two are one
# robot instant, found from the learned loop and from the stamp, apart by rounding on a clock
# of ~1e9 s; a sliver of a step between them would cost a prediction for nothing.
SAME_INSTANT_S = 1e-6


@dataclass(frozen=True)
class SensorReading:
    """One sample of the arm's sensors (the node builds it from joint_states, motor_encoders
    and battery_state).

    ``encoder_rad`` may hold NaN when the encoders are missing: the filter skips them.
    ``sampled_s``: when the sensors took it on their own clock (the message's stamp; only
    differences are used), NaN if unknown. ``bus_voltage`` and ``supply_current_a`` (from
    the battery): NaN when not reported (the battery's nominal volts, no draw).
    ``ArmPlant.read()`` returns an object with these fields but ``sampled_s``.
    """

    potentiometer_rad: tuple[float, float]
    velocity_rad_s: tuple[float, float]
    encoder_rad: tuple[float, float] = (math.nan, math.nan)
    sampled_s: float = math.nan
    bus_voltage: float = math.nan
    supply_current_a: float = math.nan


class Sensing:
    """The state estimate [θa, θb, ωa, ωb] and the readings behind it."""

    def __init__(self, arm: ArmConfig, process_noise_rad_s2: float):
        dynamics = ArmDynamics(arm)
        self.supply = PowerSupply(arm, dynamics.motors)
        self.estimator = ArmEstimator(arm, process_noise_rad_s2)
        self.nominal_voltage = arm.battery.nominal_voltage
        self.bus_voltage = self.nominal_voltage
        self.battery_voltage = self.nominal_voltage     # open circuit
        self.battery_resistance_ohm = arm.battery.resistance_ohm
        self.max_leap_speed_rad_s = LEAP_SPEED_FACTOR * float(
            np.max(dynamics.free_speed_rad_s(self.nominal_voltage)))
        self.time_s = None                 # of the estimate; None before the first reading
        self.kept = None                   # the filter at kept_s: the last reading folded in
        self.kept_s = -math.inf
        self.held_v = np.zeros(2)          # the command acting at kept_s ...
        self.commands = []                 # ... and (from s, volts) of those since
        self.last_reading_s = -math.inf
        self.last_potentiometer = None
        self.last_sampled_s = math.nan
        self.jumped = False                # the filter re-initialised: the arm is elsewhere
        self.refuse_leaps = False          # another node publishes joint_states
        self.refused, self.refusal = 0, None   # leaps refused, and (cause, why) of the last

    @property
    def started(self) -> bool:
        return self.time_s is not None

    @property
    def state(self) -> np.ndarray:
        return self.estimator.state

    def age_s(self, now_s: float) -> float:
        return now_s - self.last_reading_s

    def _predict(self, from_s: float, to_s: float) -> None:
        """The filter from ``from_s`` to ``to_s``, each command over the time it acted."""
        t, volts = from_s, self.held_v
        for start_s, command in self.commands:
            if start_s >= to_s - SAME_INSTANT_S:
                break
            if start_s > t + SAME_INSTANT_S:
                self.estimator.predict(volts, start_s - t, self.supply, self.bus_voltage)
                t = start_s
            volts = command
        if to_s > t:
            self.estimator.predict(volts, to_s - t, self.supply, self.bus_voltage)

    def _keep(self, at_s: float) -> None:
        """The filter as it is now is the one at ``at_s``: later predictions start here."""
        self.kept, self.kept_s = self.estimator.snapshot(), at_s
        while self.commands and self.commands[0][0] <= at_s:
            self.held_v = self.commands.pop(0)[1]

    def update(self, now_s: float, reading, reading_time_s, command_v) -> None:
        """Fold in ``reading`` (taken at ``reading_time_s``, default now) and predict the
        state at ``now_s``; ``command_v``: the command of the last update, acting since."""
        if self.started:
            self.commands.append((self.time_s, np.asarray(command_v, float)))
        if reading is not None:
            pot = np.asarray(reading.potentiometer_rad, float).reshape(2)
            if not np.all(np.isfinite(pot)):
                reading = None
        if reading is None:
            if self.started:
                self._predict_to(now_s)
            return
        taken_s = now_s if reading_time_s is None else min(reading_time_s, now_s)
        velocity = np.asarray(reading.velocity_rad_s, float).reshape(2)
        encoder = np.asarray(reading.encoder_rad, float).reshape(2)
        sampled_s = float(getattr(reading, 'sampled_s', math.nan))
        bus = float(getattr(reading, 'bus_voltage', math.nan))
        leapt = self._leapt(pot, taken_s, sampled_s)
        if (leapt or self.refuse_leaps) and self.started and \
                self._refused(pot, encoder, taken_s, leapt):
            self._predict_to(now_s)
            return
        self.last_reading_s, self.last_sampled_s, self.last_potentiometer = \
            taken_s, sampled_s, pot
        if not self.started:
            self.estimator.reset(pot, np.where(np.isfinite(encoder), encoder, 0.0))
            self.held_v, self.commands = np.asarray(command_v, float), []
        else:
            self.estimator.restore(self.kept)
            taken_s = max(taken_s, self.kept_s)
            self._predict(self.kept_s, taken_s)
            resets = self.estimator.jump_count
            self.estimator.update(pot, velocity, encoder)
            self.jumped |= self.estimator.jump_count > resets and leapt
        self._keep(taken_s)
        if math.isfinite(bus) and bus > 0.0:
            self.bus_voltage = bus
            current = float(getattr(reading, 'supply_current_a', math.nan))
            self.battery_voltage = bus + self.battery_resistance_ohm * current \
                if math.isfinite(current) else self.nominal_voltage
        self._predict(self.kept_s, now_s)
        self.time_s = max(now_s, taken_s)

    def _refused(self, pot, encoder, taken_s: float, leapt: bool = True) -> bool:
        """A leap of the potentiometers refused, and why kept in ``refusal``: the encoders
        say the arm is where the estimate has it (within ``ENCODERS_AGREE_RAD``; encoders
        that read about zero may have restarted where the arm was put, and tell nothing), or
        another node publishes joint_states (``refuse_leaps``) -- while readings that did not
        leap came within ``TRUSTED_SOURCE_S``. Taken as "the arm moved", each leap of a
        second publisher had re-held the arm where it said, lower each time, into the floor.

        While another node publishes, a reading is a leap when it lies farther than
        ``LEAP_MARGIN_RAD`` from the filter's prediction at its instant, however long since
        the last reading: the free-speed bound of ``_leapt`` grows with the interval (20 deg
        in under 30 ms), so a second publisher's reading after a missed one passed it.
        Once the source it trusted has gone quiet for ``TRUSTED_SOURCE_S``, a reading is
        taken if it is within ``LEAP_MARGIN_RAD`` of the last one taken, or nobody else
        publishes."""
        if taken_s - self.last_reading_s > TRUSTED_SOURCE_S:
            # The source it trusted went quiet: take this, unless another node publishes and
            # it lies beyond the margin from the last reading taken (the robot held the arm
            # meanwhile: its last profile ends held). Taken whatever its source, the other's
            # first reading after a stall was re-held, and the robot's refused from it.
            away = pot - self.last_potentiometer
            if not self.refuse_leaps or np.max(np.abs(away)) <= LEAP_MARGIN_RAD:
                return False
            self.refusal = ('publishers', f'the potentiometers leapt ({math.degrees(away[0]):+.1f}'
                            f', {math.degrees(away[1]):+.1f}) deg from the last reading taken, '
                            f'{taken_s - self.last_reading_s:.2f} s before, while another node '
                            'publishes joint_states')
            self.refused += 1
            return True
        self.estimator.restore(self.kept)
        self._predict(self.kept_s, max(taken_s, self.kept_s))
        estimate = self.estimator.state[:2]
        if not leapt and np.max(np.abs(pot - estimate)) <= LEAP_MARGIN_RAD:
            return False
        leap = np.degrees(pot - estimate)
        if np.all(np.isfinite(encoder)) and np.max(np.abs(encoder)) > ENCODERS_AGREE_RAD:
            by_encoders = encoder + self.estimator.encoder_zero_rad
            if np.max(np.abs(by_encoders - estimate)) <= ENCODERS_AGREE_RAD:
                self.refusal = ('encoders', f'the potentiometers leapt ({leap[0]:+.1f}, '
                                f'{leap[1]:+.1f}) deg from the estimate where the encoders '
                                'did not move')
                self.refused += 1
                return True
        if self.refuse_leaps:
            self.refusal = ('publishers', f'the potentiometers leapt ({leap[0]:+.1f}, '
                            f'{leap[1]:+.1f}) deg from the estimate while another node '
                            'publishes joint_states')
            self.refused += 1
            return True
        return False

    def _predict_to(self, now_s: float) -> None:
        """Without a reading: the state at ``now_s`` from the last one folded in."""
        self.estimator.restore(self.kept)
        self._predict(self.kept_s, now_s)
        self.time_s = max(now_s, self.kept_s)
        if now_s - self.kept_s > KEEP_PREDICTION_AFTER_S:
            self._keep(now_s)

    def _leapt(self, pot, taken_s: float, sampled_s: float) -> bool:
        """The potentiometers moved farther since the last reading than the arm can move: it
        was put somewhere (the sim reset or restarted), not driven or dropped there.

        The interval is the longer of arrival and sampling: readings delayed and delivered
        together (a loaded machine) arrive close but were taken far apart."""
        if self.last_potentiometer is None:
            return True
        interval_s = max(taken_s - self.last_reading_s, 0.0)
        if math.isfinite(sampled_s - self.last_sampled_s):
            interval_s = max(interval_s, sampled_s - self.last_sampled_s)
        step = float(np.max(np.abs(pot - self.last_potentiometer)))
        return step > self.max_leap_speed_rad_s * interval_s + LEAP_MARGIN_RAD
