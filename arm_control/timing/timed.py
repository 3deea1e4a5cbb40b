"""A timed trajectory: the path position s(t) piecewise quadratic on each piece's grid, and
q(t), q̇(t), q̈(t) along the pieces."""

from dataclasses import dataclass
import math

import numpy as np

from arm_control.timing.limits import TrajectoryError
from arm_control.timing.path import BlendedPath


@dataclass
class Piece:
    """One timed piece: s(t) piecewise quadratic on the grid (s̈ constant per stage)."""

    path: BlendedPath
    grid: np.ndarray
    speed: np.ndarray        # ṡ at the grid points
    accel: np.ndarray        # s̈ on each stage
    times: np.ndarray        # t at the grid points, from the piece's start
    end_rad: np.ndarray

    @classmethod
    def from_profile(cls, path, grid, x, time_scale=1.0):
        speed = np.sqrt(np.maximum(x, 0.0)) / time_scale
        deltas = np.diff(grid)
        mean = 0.5 * (speed[1:] + speed[:-1])
        if np.any(mean <= 0.0):
            raise TrajectoryError('the path speed profile stalls before the end')
        stage_s = deltas / mean
        accel = (speed[1:] - speed[:-1]) / stage_s
        times = np.concatenate([[0.0], np.cumsum(stage_s)])
        return cls(path, grid, speed, accel, times, path.points[-1].copy())

    @property
    def duration_s(self) -> float:
        return float(self.times[-1])

    def state(self, t):
        """(s, ṡ, s̈) at time t within the piece (t in [0, duration])."""
        t = np.atleast_1d(t)
        i = np.clip(np.searchsorted(self.times, t, side='right') - 1, 0, len(self.accel) - 1)
        tau = t - self.times[i]
        s = self.grid[i] + self.speed[i] * tau + 0.5 * self.accel[i] * tau ** 2
        return (np.minimum(s, self.grid[i + 1]), self.speed[i] + self.accel[i] * tau,
                self.accel[i])

    def sample(self, t):
        s, sd, sdd = self.state(t)
        dq, ddq = self.path(s, 1), self.path(s, 2)
        return (self.path(s), dq * sd[:, None],
                dq * sdd[:, None] + ddq * (sd ** 2)[:, None])


class Trajectory:
    """q(t), q̇(t), q̈(t) along the timed pieces; t clamped to [0, duration], at rest after."""

    def __init__(self, pieces, start_rad, end_rad):
        self._pieces = list(pieces)
        self._offsets = np.concatenate(
            [[0.0], np.cumsum([p.duration_s for p in self._pieces])])
        self.duration_s = float(self._offsets[-1])
        self.start_rad = np.array(start_rad, dtype=float)
        self.end_rad = np.array(end_rad, dtype=float)
        self.peak_voltage = math.nan          # set by the final check

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, q̈), each shape (2,), at time ``t_s`` from the start."""
        q, qd, qdd = self.sample_many(np.array([float(t_s)]))
        return q[0], qd[0], qdd[0]

    def sample_many(self, times_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, q̈), each shape (n, 2), at each of ``times_s``."""
        times = np.clip(np.asarray(times_s, dtype=float).reshape(-1), 0.0, self.duration_s)
        q = np.tile(self.end_rad, (len(times), 1))
        qd, qdd = np.zeros_like(q), np.zeros_like(q)
        if not self._pieces:
            return q, qd, qdd
        index = np.clip(np.searchsorted(self._offsets, times, side='right') - 1,
                        0, len(self._pieces) - 1)
        for i, piece in enumerate(self._pieces):
            mine = (index == i) & (times < self.duration_s)
            if np.any(mine):
                q[mine], qd[mine], qdd[mine] = piece.sample(times[mine] - self._offsets[i])
        return q, qd, qdd

    def path_at(self, t_s: float):
        """(the path, path position σ) the trajectory is on at ``t_s``, when it has one piece
        (a path with a stop has several: None)."""
        if len(self._pieces) != 1 or not 0.0 <= t_s < self.duration_s:
            return None
        piece = self._pieces[0]
        return piece.path, float(piece.state(t_s)[0][0])

    def grid_times(self) -> list:
        """Per piece, the times of its grid points from the trajectory's start."""
        return [offset + piece.times for offset, piece in zip(self._offsets, self._pieces)]

    def check_times(self) -> np.ndarray:
        """Every grid time and stage midpoint: where the constraints were imposed and between."""
        times = []
        for offset, piece in zip(self._offsets, self._pieces):
            mid = 0.5 * (piece.times[1:] + piece.times[:-1])
            times.append(offset + np.concatenate([piece.times, mid]))
        return np.sort(np.concatenate(times)) if times else np.zeros(1)

    def scaled(self, factor: float) -> 'Trajectory':
        """The same path, ``factor`` times slower (factor > 1) or faster."""
        pieces = [Piece.from_profile(p.path, p.grid, p.speed ** 2, factor)
                  for p in self._pieces]
        return Trajectory(pieces, self.start_rad, self.end_rad)


class ChainedTrajectory:
    """Trajectories one after another, each starting where and when the last one ends."""

    def __init__(self, parts):
        self.parts = list(parts)
        self.offsets_s = np.concatenate([[0.0], np.cumsum([p.duration_s for p in self.parts])])
        self.duration_s = float(self.offsets_s[-1])

    def sample(self, t_s):
        index = int(np.clip(np.searchsorted(self.offsets_s, t_s, side='right') - 1,
                            0, len(self.parts) - 1))
        return self.parts[index].sample(t_s - self.offsets_s[index])
