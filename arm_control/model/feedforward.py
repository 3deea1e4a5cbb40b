"""Feedforward for a voltage held over each control period, from the one model of the arm.

A 50 Hz loop holds each command for 20 ms, while a time-optimal trajectory switches from
driving to braking, and stops, at any instant: driven by the period's average voltage the
arm ends the period off the trajectory (up to a degree on a short hop) and the PID has to
catch it. Instead a model of the arm, the reference, is driven by the feedforward itself,
and each period's voltage is the first of two -- one per period ahead, per joint -- that
would put the reference exactly on the trajectory, position and velocity, two periods from
now (four conditions, four volts: deadbeat; one Newton step from the Simpson average of the
trajectory's voltage over each period, the Jacobian by finite differences). The PID tracks
the reference, a motion the arm can follow exactly. The reference moves as the robot's
motor controllers apply each held voltage (``PowerSupply.solve_many``: within the current
limits and the bus it sags), so a command they lower moves the reference as it moves the
arm; the Newton step itself is taken in the model alone.

Holding still, nothing changes from one period to the next: the setpoint rests at one angle
over the periods ahead, the reference sits on it, and the voltage that held it there holds it
again. Once a period has shown that (the reference, driven by the last voltage, ended within
``HOLD_TOLERANCE`` of the setpoint at rest and the new voltage equals the last), the voltage
is kept and the reference put on the setpoint, until the setpoint moves or the battery (or
the limit) changes by ``BATTERY_TOLERANCE_V``: the same answer, without solving it again
every period. (At rest the answer does not depend on the battery at all unless a voltage is
clipped to it, and the kept ones are below the limit by more than that.)
"""

import math

import numpy as np

from arm_control.model.dynamics import ArmDynamics, rk4_batch
from arm_control.model.electrical import PowerSupply

# A reference this close to a setpoint at rest (rad, rad/s), driven by a voltage this close
# to the last (V), is held by it: the next periods would solve the same problem again.
HOLD_TOLERANCE = 1e-9
# ... until the battery's voltage, or the limit, has moved this far from the one it was
# solved at (V): a reading of it rounds to float32 and swings with every command.
BATTERY_TOLERANCE_V = 0.01


class PeriodFeedforward:
    """The voltage to hold over each control period, and the reference state to track.

    The reference restarts on the setpoint when it is more than ``restart_rad`` away (the
    setpoint jumped) or the loop paused for more than two periods. The voltage is clamped to
    ±``max_voltage``, or to the battery's open-circuit voltage when ``step`` is given one:
    the reference's bus then sags from it under the reference's own draw.
    """

    def __init__(self, dynamics: ArmDynamics, period_s: float, max_voltage: float,
                 substep_s: float = 0.01, restart_rad: float = 0.05):
        self.dynamics = dynamics
        self.supply = PowerSupply(dynamics.arm, dynamics.motors)
        self.period_s = float(period_s)
        self.max_voltage = float(max_voltage)
        self.substep_s = dynamics.stable_step_s(substep_s)
        self.newton_step_s = dynamics.stable_step_s(period_s)
        self.restart_rad = float(restart_rad)
        self.state = None               # the reference [θa, θb, ωa, ωb] at time_s
        self.time_s = -math.inf
        self.voltage = self.next_voltage = np.zeros(2)
        self.holding = None             # what a kept voltage holds: (setpoint q, limit, bus)

    def reset(self) -> None:
        self.state = self.holding = None

    def _simulate(self, x, volts, duration_s, applied=True, substep_s=None):
        """States (P, 4) after holding each of ``volts`` (P, k, 2) for ``duration_s`` in
        turn, as the motor controllers apply them (``applied``; else as they are), by RK4
        on steps of at most ``substep_s`` (``ArmDynamics.derivatives``)."""
        steps = max(1, math.ceil(duration_s / (substep_s or self.substep_s) - 1e-9))
        h = duration_s / steps
        x = np.array(x, float)

        def f(state, command):
            _, volts_applied, _ = self.supply.solve_many(command, state[..., 2:])
            return self.dynamics.derivatives(state, volts_applied)

        for k in range(volts.shape[1]):
            for _ in range(steps):
                x = rk4_batch(f if applied else self.dynamics.derivatives, x, volts[:, k], h)
        return x

    def step(self, now_s: float, setpoint, battery_voltage: float | None = None) -> np.ndarray:
        """The voltage to hold from ``now_s``; ``setpoint(t)`` -> (q, q̇, q̈) of the
        trajectory; ``battery_voltage``: the battery's open-circuit voltage (V) as measured.
        Updates ``state``, the reference at ``now_s``."""
        period = self.period_s
        limit = self.max_voltage
        if battery_voltage is not None and math.isfinite(battery_voltage) \
                and battery_voltage > 0.0:
            self.supply.nominal_voltage = float(battery_voltage)
            limit = min(limit, float(battery_voltage))
        q_sp, qd_sp, _ = setpoint(now_s)
        here = np.concatenate([q_sp, qd_sp])
        samples = [setpoint(now_s + fraction * period) for fraction in (0, 0.5, 1, 1.5, 2)]
        rest = _at_rest(samples, limit, self.supply.nominal_voltage)
        if self.state is not None and _same_rest(rest, self.holding):
            self.state, self.time_s = here, now_s
            return self.voltage.copy()
        driven = self.state is not None and 0.0 < now_s - self.time_s <= 2.5 * period
        if driven:
            self.state = self._simulate(self.state[None], self.voltage[None, None],
                                        now_s - self.time_s)[0]
        if (self.state is None or not 0.0 <= now_s - self.time_s <= 2.5 * period
                or np.max(np.abs(self.state[:2] - q_sp)) > self.restart_rad):
            self.state, driven = here, False
        self.time_s = now_s
        # The last voltage kept the reference on the setpoint at rest (simulated, not assumed).
        held = driven and rest is not None and np.max(np.abs(self.state - here)) <= HOLD_TOLERANCE
        volts = self.dynamics.voltages(*(np.array(v) for v in zip(*samples)))
        guess = np.concatenate([(volts[0] + 4 * volts[1] + volts[2]) / 6,
                                (volts[2] + 4 * volts[3] + volts[4]) / 6])
        target = np.concatenate(samples[-1][:2])
        delta = 0.5
        trials = np.tile(guess, (5, 1))
        trials[1:] += delta * np.eye(4)
        # The Newton step in the model alone: where the motor controllers would lower a
        # command, its column of the Jacobian vanishes and the other joint's volts would be
        # bent to make up for it through the coupling. One RK4 step a period is enough for
        # the step (the reference itself moves on finer ones) where it is stable: half the
        # loop's CPU. Coulomb friction makes the arm stiff near rest (``stable_step_s``).
        ends = self._simulate(np.tile(self.state, (5, 1)), trials.reshape(5, 2, 2), period,
                              applied=False, substep_s=self.newton_step_s)
        jacobian = (ends[1:] - ends[0]).T / delta
        try:
            guess = guess - np.linalg.solve(jacobian, ends[0] - target)
        except np.linalg.LinAlgError:
            pass
        last = self.voltage
        self.voltage = np.clip(guess[:2], -limit, limit)
        self.next_voltage = np.clip(guess[2:], -limit, limit)     # the period after
        steady = np.max(np.abs(np.concatenate([last, self.next_voltage])
                               - np.tile(self.voltage, 2))) <= HOLD_TOLERANCE
        within = np.max(np.abs(guess)) < limit - BATTERY_TOLERANCE_V
        self.holding = rest if held and steady and within else None
        return self.voltage.copy()


def _at_rest(samples, limit: float, bus: float):
    """(q, limit, bus) when the setpoint samples all rest at one angle q; else None."""
    q = (float(samples[0][0][0]), float(samples[0][0][1]))
    for q_k, qd_k, qdd_k in samples:
        if (q_k[0], q_k[1]) != q or qd_k[0] or qd_k[1] or qdd_k[0] or qdd_k[1]:
            return None
    return q[0], q[1], limit, bus


def _same_rest(rest, holding) -> bool:
    """The same angle, the limit and the battery within ``BATTERY_TOLERANCE_V``."""
    return rest is not None and holding is not None and rest[:2] == holding[:2] and all(
        abs(a - b) <= BATTERY_TOLERANCE_V for a, b in zip(rest[2:], holding[2:]))
