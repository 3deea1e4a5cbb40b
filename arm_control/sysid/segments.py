"""The reference motions an excitation is made of, each rest to rest or held: a hold, a quintic
move, a quasistatic sweep of one joint, and a coupled multi-sine. ``sample(t)`` gives q, q̇,
q̈ at the times t, each (N, 2)."""

from abc import ABC, abstractmethod
import math

import numpy as np


def _smoothstep(u):
    """s(u) = 10u³ − 15u⁴ + 6u⁵ and its first two derivatives: rest to rest, C²."""
    u = np.clip(u, 0.0, 1.0)
    return (u ** 3 * (10.0 - 15.0 * u + 6.0 * u ** 2),
            30.0 * u ** 2 * (1.0 - u) ** 2,
            60.0 * u * (1.0 - u) * (1.0 - 2.0 * u))


class Segment(ABC):
    """A reference motion over [0, duration_s]: ``sample(t)`` gives q, q̇, q̈, each (N, 2)."""

    duration_s: float
    start_rad: np.ndarray
    end_rad: np.ndarray

    @abstractmethod
    def sample(self, t):
        """q, q̇, q̈ at the times ``t`` (s from the segment's start)."""


class Hold(Segment):
    def __init__(self, q, duration_s):
        self.start_rad = self.end_rad = np.asarray(q, float)
        self.duration_s = float(duration_s)

    def sample(self, t):
        t = np.atleast_1d(t)
        zero = np.zeros((len(t), 2))
        return self.start_rad + zero, zero, zero.copy()


class Quintic(Segment):
    """q = q0 + (q1 − q0)·s(t/T), s the smoothstep: rest to rest."""

    def __init__(self, q_from, q_to, duration_s):
        self.start_rad, self.end_rad = np.asarray(q_from, float), np.asarray(q_to, float)
        self.duration_s = float(duration_s)

    def sample(self, t):
        u = np.atleast_1d(t)[:, None] / self.duration_s
        s, ds, dds = _smoothstep(u)
        change = self.end_rad - self.start_rad
        return (self.start_rad + change * s, change * ds / self.duration_s,
                change * dds / self.duration_s ** 2)


class Sweep(Segment):
    """One joint from q0 over ``distance_rad``, its speed ramped up at ``acceleration`` to
    half-way and down again (a triangle in velocity), the other joint held: quasistatic."""

    def __init__(self, q_from, joint, distance_rad, acceleration_rad_s2):
        self.start_rad = np.asarray(q_from, float)
        self.joint, self.distance_rad = joint, float(distance_rad)
        self.acceleration = math.copysign(acceleration_rad_s2, distance_rad)
        self.duration_s = 2.0 * math.sqrt(abs(distance_rad) / acceleration_rad_s2)
        self.end_rad = self.start_rad.copy()
        self.end_rad[joint] += distance_rad

    def sample(self, t):
        t = np.clip(np.atleast_1d(t), 0.0, self.duration_s)
        half, a = self.duration_s / 2.0, self.acceleration
        rising = t < half
        left = self.duration_s - t
        x = np.where(rising, 0.5 * a * t ** 2, self.distance_rad - 0.5 * a * left ** 2)
        v = np.where(rising, a * t, a * left)
        acc = np.where(rising, a, -a)
        q, qd, qdd = (np.zeros((len(t), 2)) for _ in range(3))
        q[:] = self.start_rad
        q[:, self.joint] += x
        qd[:, self.joint], qdd[:, self.joint] = v, acc
        return q, qd, qdd


class MultiSine(Segment):
    """q_j = c_j + w(t)·Σ_k a_jk·sin(2π f_jk t + φ_jk), faded in and out by w (C²)."""

    def __init__(self, centre, amplitudes, frequencies_hz, phases, duration_s, ramp_s):
        self.start_rad = self.end_rad = np.asarray(centre, float)
        self.amplitudes = np.asarray(amplitudes, float)          # (2, K)
        self.omega = 2.0 * math.pi * np.asarray(frequencies_hz, float)
        self.phases = np.asarray(phases, float)
        self.duration_s, self.ramp_s = float(duration_s), min(float(ramp_s), duration_s / 2)

    def _window(self, t):
        rise = _smoothstep(t / self.ramp_s)
        fall = _smoothstep((self.duration_s - t) / self.ramp_s)
        w = rise[0] * fall[0]
        dw = (rise[1] * fall[0] - rise[0] * fall[1]) / self.ramp_s
        ddw = (rise[2] * fall[0] - 2.0 * rise[1] * fall[1] + rise[0] * fall[2]) \
            / self.ramp_s ** 2
        return w, dw, ddw

    def sample(self, t):
        t = np.atleast_1d(t)
        angle = self.omega[None] * t[:, None, None] + self.phases[None]   # (N, 2, K)
        a, w_k = self.amplitudes[None], self.omega[None]
        s = np.sum(a * np.sin(angle), axis=-1)
        ds = np.sum(a * w_k * np.cos(angle), axis=-1)
        dds = -np.sum(a * w_k ** 2 * np.sin(angle), axis=-1)
        w, dw, ddw = (v[:, None] for v in self._window(t))
        return (self.start_rad + w * s, dw * s + w * ds, ddw * s + 2.0 * dw * ds + w * dds)


class Join(Segment):
    """A quintic per joint from (q0, q̇0, q̈0) to (q1, q̇1, q̈1) over ``duration_s``: rejoins a
    motion from wherever the arm is."""

    def __init__(self, start, end, duration_s):
        self.duration_s = float(duration_s)
        (q0, v0, a0), (q1, v1, a1) = ([np.asarray(v, float) for v in s] for s in (start, end))
        self.start_rad, self.end_rad = q0, q1
        t = self.duration_s
        # q(s) = Σ c_k s^k; c0..c2 from the start, c3..c5 from the end's three conditions.
        ends = np.array([[t ** 3, t ** 4, t ** 5],
                         [3 * t ** 2, 4 * t ** 3, 5 * t ** 4],
                         [6 * t, 12 * t ** 2, 20 * t ** 3]])
        rest = np.array([q1 - (q0 + v0 * t + 0.5 * a0 * t ** 2), v1 - (v0 + a0 * t), a1 - a0])
        self.coefficients = np.vstack([q0, v0, 0.5 * a0, np.linalg.solve(ends, rest)])

    def sample(self, t):
        s = np.clip(np.atleast_1d(t), 0.0, self.duration_s)[:, None]
        c = self.coefficients
        q = sum(c[k] * s ** k for k in range(6))
        qd = sum(k * c[k] * s ** (k - 1) for k in range(1, 6))
        qdd = sum(k * (k - 1) * c[k] * s ** (k - 2) for k in range(2, 6))
        return q, qd, qdd


class Tail(Segment):
    """What is left of ``segment`` from ``from_s`` on."""

    def __init__(self, segment, from_s):
        self.segment, self.from_s = segment, float(from_s)
        self.duration_s = segment.duration_s - self.from_s
        self.start_rad = segment.sample(self.from_s)[0][0]
        self.end_rad = segment.end_rad

    def sample(self, t):
        return self.segment.sample(np.atleast_1d(t) + self.from_s)
