"""The control law: V = feedforward + PID, clamped to the battery's volts, and the wait for
an arm late on its planned motion.

The feedforward is the held voltage that keeps a model of the arm on the trajectory at every
period's end (``PeriodFeedforward``); the PID tracks that model's state on the estimate.
"""

from typing import Callable, Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.motions import Motion
from arm_control.control.pid import ArmPid
from arm_control.model.feedforward import PeriodFeedforward

# A planned motion waits for an arm late on it by over WAIT_AFTER_PERIODS periods (its first
# command taken a robot loop late, a weak start), by that lag less those, at most WAIT_LIMIT_S
# in all: an arm that cannot move still meets the tracking-error rule. Driven to catch up, it
# brakes at the motors' limits with only the reserve; a start missed by one robot loop then
# costs several. Slower than WAIT_MIN_SPEED_RAD_S the lag along the path is not read.
WAIT_AFTER_PERIODS, WAIT_LIMIT_S = 0.35, 0.2
WAIT_MIN_SPEED_RAD_S = 0.5


class Tracking:
    """The volts that keep the arm on its setpoint, and what they were made of: ``setpoint``
    (q, q̇, q̈), ``tracking_error_rad``, ``feedforward_v``, ``feedback_v``."""

    def __init__(self, arm: ArmConfig, config: ControllerConfig, dynamics):
        self.period_s, self.nominal_voltage = config.period_s, arm.battery.nominal_voltage
        self.pid = ArmPid.from_config(config)
        self.feedforward = PeriodFeedforward(dynamics, self.period_s, self.nominal_voltage)
        self.feedforward_v = self.feedback_v = np.zeros(2)
        self.saturated = (0, 0)
        self.setpoint = (np.zeros(2), np.zeros(2), np.zeros(2))
        self.tracking_error_rad = np.zeros(2)
        self.waited_on, self.waited_s = None, 0.0         # the motion that waited, how long

    def volts(self, now_s: float, dt_s: float, reference: Callable, estimate: np.ndarray,
              battery_voltage: float) -> np.ndarray:
        """Feedforward at the setpoint ``reference(t_s)`` plus PID on ``estimate``
        [θa, θb, ωa, ωb], clamped to the battery's open-circuit voltage (within its nominal
        volts, the command's range)."""
        self.setpoint = reference(now_s)
        # The voltage is held over the coming period: the feedforward keeps a model of the
        # arm on the trajectory at every period's end; the PID tracks that model.
        bus = min(battery_voltage, self.nominal_voltage)
        feedforward = self.feedforward.step(now_s, reference, battery_voltage=bus)
        model = self.feedforward.state
        error = model[:2] - estimate[:2]
        feedback = np.array(self.pid.update(error, model[2:] - estimate[2:], dt_s,
                                            self.saturated))
        total = feedforward + feedback
        self.saturated = tuple(int(np.sign(v)) if abs(v) > bus else 0 for v in total)
        self.tracking_error_rad = error
        self.feedforward_v, self.feedback_v = feedforward, feedback
        return np.clip(total, -bus, bus)

    def settled(self, estimate, tolerance_rad: float, speed_rad_s: float) -> bool:
        """Within ``tolerance_rad`` of the setpoint, slower than ``speed_rad_s``, and the
        feedforward keeping its voltage (``PeriodFeedforward.holding``: its reference is
        driven by one voltage over however long the loop waits; once settled, the next
        period's is the same)."""
        return self.feedforward.holding is not None \
            and all(abs(e) <= tolerance_rad for e in self.tracking_error_rad) \
            and all(abs(w) <= speed_rad_s for w in estimate[2:])

    def stop(self) -> None:
        """At 0 V: no error to track."""
        self.tracking_error_rad = np.zeros(2)

    def wait_for_a_late_arm(self, now_s: float, motion: Motion, q) -> Optional[float]:
        """Shift ``motion`` later when the arm (at ``q``) is behind on it: the lag is the most
        any joint faster than WAIT_MIN_SPEED_RAD_S is behind, (q_set − q̂)/q̇_set (s); the
        other joint's feedback then keeps it on the path. Returns the time waited on it in
        all (s), or None when it did not wait now."""
        if motion is not self.waited_on:
            self.waited_on, self.waited_s = motion, 0.0
        q_set, qd_set, _ = motion.sample(now_s)
        moving = np.abs(qd_set) >= WAIT_MIN_SPEED_RAD_S
        if not moving.any():
            return None
        lag_s = float(np.max((q_set - q)[moving] / qd_set[moving]))
        delay_s = min(lag_s - WAIT_AFTER_PERIODS * self.period_s, WAIT_LIMIT_S - self.waited_s,
                      now_s - motion.begin_s)       # it stays the motion in charge
        if delay_s <= 0.0:
            return None
        motion.delay(delay_s)
        self.waited_s += delay_s
        self.feedforward.reset()                # its reference restarts on the motion
        return self.waited_s
