"""Motions: the setpoint over time, as trajectories pinned to the clock.

The controller's setpoint is a ``Timeline`` of motions, each taking over from the one before at
its ``begin_s``: a timed trajectory to a goal, a hold, or a stop along the path it was on.
"""

from typing import Optional

import numpy as np


class HoldTrajectory:
    """Stand still at ``q``: the trajectory of holding."""

    duration_s = 0.0

    def __init__(self, q):
        self.q = np.array(q, dtype=float)

    def sample(self, t_s):
        return self.q.copy(), np.zeros(2), np.zeros(2)


class Motion:
    """A trajectory pinned to the clock: it takes over at ``begin_s`` and is at rest from
    ``end_s`` on, at ``final_q``."""

    def __init__(self, trajectory, begin_s: float):
        self.trajectory = trajectory
        self.begin_s = float(begin_s)
        self.end_s = self.begin_s + float(trajectory.duration_s)
        self.final_q = np.asarray(trajectory.sample(trajectory.duration_s)[0], float).copy()

    def sample(self, now_s: float):
        """(q, q̇, q̈) at ``now_s``; at rest on ``final_q`` from ``end_s`` on."""
        if now_s >= self.end_s:
            return self.final_q.copy(), np.zeros(2), np.zeros(2)
        q, qd, qdd = self.trajectory.sample(max(now_s - self.begin_s, 0.0))
        return np.asarray(q, float), np.asarray(qd, float), np.asarray(qdd, float)

    def finished(self, now_s: float) -> bool:
        return now_s >= self.end_s

    def delay(self, delay_s: float) -> None:
        """The same motion, ``delay_s`` later."""
        self.begin_s += delay_s
        self.end_s += delay_s

    def rejoined(self, now_s: float, q, qd, position_rad: float, speed_rad_s: float,
                 moving_rad_s: float = 0.3, step_s: float = 0.005) -> Optional['Motion']:
        """The same trajectory, shifted in time to pass through (q, q̇) at ``now_s``, when it
        passes within ``position_rad`` and ``speed_rad_s`` of it and the arm is moving
        (faster than ``moving_rad_s``); else None. A stall that froze the arm along with its
        sensors (a paused simulator) leaves it near its plan, moving along it."""
        trajectory = getattr(self, 'trajectory', None)      # braking and holds: no plan
        if trajectory is None or trajectory.duration_s <= 0.0:
            return None
        times = np.arange(0.0, trajectory.duration_s, step_s)
        samples = [trajectory.sample(t)[:2] for t in times]
        position = np.array([s[0] for s in samples]) - np.asarray(q, float)
        speed = np.array([s[1] for s in samples]) - np.asarray(qd, float)
        close = (np.max(np.abs(position), axis=1) <= position_rad) & \
            (np.max(np.abs(speed), axis=1) <= speed_rad_s)
        if not np.any(close) or np.max(np.abs(qd)) <= moving_rad_s:   # at rest: hold instead
            return None
        best = np.flatnonzero(close)[np.argmin(np.max(np.abs(position[close]), axis=1))]
        return Motion(trajectory, now_s - times[best])


class StoppingMotion(Motion):
    """Brake to rest along the path a motion was following (a path known to be free).

    Path time τ runs at rate r = 1 − (t − t₀)/T, from 1 down to 0 over T, so
    q = p(τ), q̇ = ṗ(τ)·r, q̈ = p̈(τ)·r² − ṗ(τ)/T; T is what the acceleration limits need.
    """

    def __init__(self, base: Motion, now_s: float, acceleration_limits):
        _, qd, _ = base.sample(now_s)
        self.base = base
        self.begin_s = float(now_s)
        need = float(np.max(np.abs(qd) / np.asarray(acceleration_limits, float)))
        self.brake_s = max(1.5 * need, 0.05)
        self.end_s = self.begin_s + self.brake_s
        self.final_q = self._path(self.brake_s)[0]

    def _path(self, elapsed_s):
        elapsed = min(max(elapsed_s, 0.0), self.brake_s)
        rate = 1.0 - elapsed / self.brake_s
        tau = elapsed - elapsed ** 2 / (2.0 * self.brake_s)
        q, qd, qdd = self.base.sample(self.begin_s + tau)
        return q, qd * rate, qdd * rate ** 2 - qd / self.brake_s

    def sample(self, now_s: float):
        if now_s >= self.end_s:
            return self.final_q.copy(), np.zeros(2), np.zeros(2)
        return self._path(now_s - self.begin_s)


class StraightStop(Motion):
    """Brake to rest in a straight line: q̇ = q̇₀·(1 − t/T), T = max |q̇₀ᵢ|/aᵢ."""

    def __init__(self, q, qd, now_s: float, acceleration_limits):
        self.q0, self.qd0 = np.array(q, float), np.array(qd, float)
        self.brake_s = max(float(np.max(np.abs(self.qd0) / np.asarray(acceleration_limits))),
                           1e-6)
        self.begin_s = float(now_s)
        self.end_s = self.begin_s + self.brake_s
        self.final_q = self.q0 + 0.5 * self.qd0 * self.brake_s

    def sample(self, now_s: float):
        t = now_s - self.begin_s
        if t >= self.brake_s:
            return self.final_q.copy(), np.zeros(2), np.zeros(2)
        t = max(t, 0.0)
        return (self.q0 + self.qd0 * (t - t * t / (2.0 * self.brake_s)),
                self.qd0 * (1.0 - t / self.brake_s), -self.qd0 / self.brake_s)


class Timeline:
    """The setpoint over time: motions, each taking over from the one before at its
    ``begin_s``. Scheduling a motion drops those that would begin at or after it."""

    def __init__(self):
        self.motions: list[Motion] = []

    def schedule(self, motion: Motion) -> None:
        self.motions = [m for m in self.motions if m.begin_s < motion.begin_s] + [motion]

    def at(self, t_s: float) -> Optional[Motion]:
        """The motion in charge at ``t_s`` (the first one before any has begun)."""
        current = self.motions[0] if self.motions else None
        for motion in self.motions:
            if motion.begin_s <= t_s:
                current = motion
        return current

    def prune(self, now_s: float) -> None:
        active = self.at(now_s)
        if active is not None:
            self.motions = self.motions[self.motions.index(active):]

    @property
    def last(self) -> Optional[Motion]:
        return self.motions[-1] if self.motions else None

    def sample(self, t_s: float):
        motion = self.at(t_s)
        return None if motion is None else motion.sample(t_s)

    def moving_at(self, t_s: float) -> bool:
        last = self.last
        return last is not None and not last.finished(t_s)


class StraightMove(Motion):
    """From rest at ``q0`` to rest at ``q1`` along the straight joint-space line, as fast as
    ``max_acceleration_rad_s2`` and ``max_velocity_rad_s`` allow each joint: both joints
    follow one profile s(t) from 0 to 1 (accelerate, cruise, brake). For short moves whose
    limits are what the motors surely give in any pose: no timing solve is needed."""

    def __init__(self, q0, q1, now_s: float, max_acceleration_rad_s2, max_velocity_rad_s):
        self.q0, self.q1 = np.array(q0, float), np.array(q1, float)
        delta = np.abs(self.q1 - self.q0)
        moving = delta > 0.0
        self.acceleration = float(np.min(np.asarray(max_acceleration_rad_s2)[moving]
                                         / delta[moving])) if np.any(moving) else 1.0
        speed = float(np.min(np.asarray(max_velocity_rad_s)[moving] / delta[moving])) \
            if np.any(moving) else 1.0
        ramp_s = min(speed / self.acceleration, np.sqrt(1.0 / self.acceleration))
        self.peak = self.acceleration * ramp_s                 # ds/dt at the top
        self.ramp_s = ramp_s
        self.cruise_s = (1.0 - self.acceleration * ramp_s ** 2) / self.peak
        self.begin_s = float(now_s)
        self.end_s = self.begin_s + 2.0 * ramp_s + self.cruise_s if np.any(moving) \
            else self.begin_s
        self.final_q = self.q1.copy()

    def _profile(self, t: float):
        """(s, ṡ, s̈) at time t from the start."""
        a, ramp, cruise = self.acceleration, self.ramp_s, self.cruise_s
        if t < ramp:
            return 0.5 * a * t * t, a * t, a
        if t < ramp + cruise:
            return 0.5 * a * ramp * ramp + self.peak * (t - ramp), self.peak, 0.0
        left = max(2.0 * ramp + cruise - t, 0.0)
        return 1.0 - 0.5 * a * left * left, a * left, -a

    def sample(self, now_s: float):
        if now_s >= self.end_s:
            return self.final_q.copy(), np.zeros(2), np.zeros(2)
        s, sd, sdd = self._profile(max(now_s - self.begin_s, 0.0))
        step = self.q1 - self.q0
        return self.q0 + s * step, sd * step, sdd * step


class Setpoints:
    """Where the arm should be at any time: the timeline's motions, or in driver mode the
    driver's setpoint (``DriverMode``). Braking and holding act on whichever is in charge."""

    def __init__(self, driver, max_acceleration_rad_s2):
        self.timeline = Timeline()
        self.driver = driver
        self.driving = False
        self.max_acceleration = np.asarray(max_acceleration_rad_s2, float)

    def sample(self, t_s: float):
        """(q, q̇, q̈) at ``t_s``; None before any motion."""
        return self.driver.sample(t_s) if self.driving else self.timeline.sample(t_s)

    def schedule(self, motion: Motion) -> None:
        self.timeline.schedule(motion)

    def hold(self, q, now_s: float) -> None:
        self.timeline.schedule(Motion(HoldTrajectory(q), now_s))

    def in_charge(self, motion: Optional[Motion], now_s: float) -> bool:
        """Whether ``motion``, or the braking of it, gives the setpoint at ``now_s``."""
        active = None if self.driving else self.timeline.at(now_s)
        return motion is not None and active is not None and (
            active is motion or getattr(active, 'base', None) is motion)

    def drive(self, now_s: float, q, qd) -> None:
        """The driver takes over from the setpoint (q, q̇) being followed now."""
        self.driver.take_over(now_s, q, qd)
        self.driving = True

    def stopping(self, now_s: float) -> Optional[Motion]:
        """The motion that brings the setpoint at ``now_s`` to rest (along its path) and holds
        there; None before any motion."""
        if self.driving:
            q, qd, _ = self.driver.sample(now_s)
            return StraightStop(q, qd, now_s, self.max_acceleration) if np.any(qd) \
                else Motion(HoldTrajectory(q), now_s)
        motion = self.timeline.at(now_s)
        if motion is None:
            return None
        if motion.finished(now_s):
            return Motion(HoldTrajectory(motion.final_q), now_s)
        return StoppingMotion(motion, now_s, self.max_acceleration)

    def brake(self, now_s: float) -> None:
        """Come to rest from the current setpoint (along its path) and hold there."""
        stop = self.stopping(now_s)
        self.driving = False
        if stop is not None:
            self.timeline.schedule(stop)

    def moving_at(self, t_s: float) -> bool:
        return self.timeline.moving_at(t_s)

    def prune(self, now_s: float) -> None:
        self.timeline.prune(now_s)
