"""A run of the arm as time-stamped streams, saved as .npz or .csv: no ROS here.

Streams (times in s; angles in rad, rates in rad/s, voltages in V):

    measured   what the sensors read (``joint_states``): position, velocity   [shoulder, elbow]
    truth      the sim's true state (``sim/ground_truth``): position, velocity
    setpoint   the trajectory's setpoint (``controller/setpoint``): position, velocity
    voltage    the commanded motor voltages (``voltage_command``): value [shoulder_V, elbow_V]
    state      the state machine's state (``arm_state``): name, kept at each change

The ``recorder`` node fills one from ROS messages; a benchmark fills one from an in-process
run with ``Recording.from_samples``.
"""

import csv
from dataclasses import dataclass
import math
import os
from pathlib import Path

import numpy as np

JOINT_STREAMS = ('measured', 'truth', 'setpoint')
CSV_COLUMNS = ('time_s', 'stream', 'shoulder', 'elbow', 'shoulder_rate', 'elbow_rate', 'state')


@dataclass(frozen=True)
class Sample:
    """One instant of an in-process run; any part may be missing (None)."""

    time_s: float
    measured_rad: tuple[float, float] | None = None
    true_rad: tuple[float, float] | None = None
    setpoint_rad: tuple[float, float] | None = None
    voltage: tuple[float, float] | None = None
    state: str | None = None
    measured_rad_s: tuple[float, float] | None = None
    true_rad_s: tuple[float, float] | None = None
    setpoint_rad_s: tuple[float, float] | None = None


class Recording:
    """Streams of (time, values) appended as they arrive; ``arrays(stream)`` reads them."""

    def __init__(self):
        self._joints = {name: ([], [], []) for name in JOINT_STREAMS}   # time, position, vel
        self._voltage = ([], [])
        self._state = ([], [])

    # -- filling ---------------------------------------------------------------------

    def add_joints(self, stream: str, time_s: float, position, velocity=None) -> None:
        """position/velocity: [shoulder, elbow]; a missing velocity is stored as NaN."""
        times, positions, velocities = self._joints[stream]
        velocity = list(velocity) if velocity is not None and len(velocity) >= 2 \
            else [math.nan, math.nan]
        times.append(float(time_s))
        positions.append([float(position[0]), float(position[1])])
        velocities.append([float(velocity[0]), float(velocity[1])])

    def add_voltage(self, time_s: float, voltage) -> None:
        self._voltage[0].append(float(time_s))
        self._voltage[1].append([float(voltage[0]), float(voltage[1])])

    def add_state(self, time_s: float, state: str) -> None:
        """Kept only when it differs from the last state (a latched topic repeats itself)."""
        times, names = self._state
        if not names or names[-1] != state:
            times.append(float(time_s))
            names.append(str(state))

    @classmethod
    def from_samples(cls, samples) -> 'Recording':
        """A recording of an in-process run: a list of ``Sample``."""
        recording = cls()
        for s in samples:
            for stream, position, velocity in (
                    ('measured', s.measured_rad, s.measured_rad_s),
                    ('truth', s.true_rad, s.true_rad_s),
                    ('setpoint', s.setpoint_rad, s.setpoint_rad_s)):
                if position is not None:
                    recording.add_joints(stream, s.time_s, position, velocity)
            if s.voltage is not None:
                recording.add_voltage(s.time_s, s.voltage)
            if s.state is not None:
                recording.add_state(s.time_s, s.state)
        return recording

    # -- reading ---------------------------------------------------------------------

    def arrays(self, stream: str) -> dict[str, np.ndarray]:
        """``{'time_s': (N,), ...}``: position and velocity (N, 2) for the joint streams,
        value (N, 2) for voltage, name (N,) for state."""
        if stream in JOINT_STREAMS:
            times, positions, velocities = self._joints[stream]
            return {'time_s': np.array(times, float),
                    'position': np.array(positions, float).reshape(-1, 2),
                    'velocity': np.array(velocities, float).reshape(-1, 2)}
        if stream == 'voltage':
            return {'time_s': np.array(self._voltage[0], float),
                    'value': np.array(self._voltage[1], float).reshape(-1, 2)}
        if stream == 'state':
            return {'time_s': np.array(self._state[0], float),
                    'name': np.array(self._state[1], dtype=str)}
        raise KeyError(f"no stream '{stream}': expected one of "
                       f"{', '.join(JOINT_STREAMS + ('voltage', 'state'))}")

    def __len__(self) -> int:
        return (sum(len(times) for times, _, _ in self._joints.values())
                + len(self._voltage[0]) + len(self._state[0]))

    def start_time_s(self) -> float:
        firsts = [times[0] for times, _, _ in self._joints.values() if times]
        firsts += [t[0] for t in (self._voltage[0], self._state[0]) if t]
        return min(firsts, default=0.0)

    # -- files -----------------------------------------------------------------------

    def save(self, path) -> None:
        """Write .npz (arrays named ``stream.field``) or .csv (one row per sample);
        written aside and renamed, so a reader never sees half a file."""
        path = Path(path)
        partial = path.with_name(path.name + '.part')
        if path.suffix == '.csv':
            with open(partial, 'w', newline='') as handle:
                self._write_csv(handle)
        else:
            arrays = {f'{stream}.{field}': values
                      for stream in JOINT_STREAMS + ('voltage', 'state')
                      for field, values in self.arrays(stream).items()}
            with open(partial, 'wb') as handle:
                np.savez_compressed(handle, **arrays)
        os.replace(partial, path)

    def _write_csv(self, handle) -> None:
        writer = csv.writer(handle)
        writer.writerow(CSV_COLUMNS)
        rows = []
        for stream in JOINT_STREAMS:
            data = self.arrays(stream)
            rows += [(t, stream, *p, *v, '') for t, p, v in
                     zip(data['time_s'], data['position'], data['velocity'])]
        data = self.arrays('voltage')
        rows += [(t, 'voltage', *v, '', '', '') for t, v in zip(data['time_s'], data['value'])]
        data = self.arrays('state')
        rows += [(t, 'state', '', '', '', '', n) for t, n in zip(data['time_s'], data['name'])]
        rows.sort(key=lambda row: row[0])
        writer.writerows([repr(float(v)) if isinstance(v, (float, np.floating)) else v
                          for v in row] for row in rows)

    @classmethod
    def load(cls, path) -> 'Recording':
        path = Path(path)
        recording = cls()
        if path.suffix == '.csv':
            with open(path, newline='') as handle:
                for row in csv.DictReader(handle):
                    time_s, stream = float(row['time_s']), row['stream']
                    if stream in JOINT_STREAMS:
                        recording.add_joints(
                            stream, time_s, (float(row['shoulder']), float(row['elbow'])),
                            (float(row['shoulder_rate']), float(row['elbow_rate'])))
                    elif stream == 'voltage':
                        recording.add_voltage(time_s, (float(row['shoulder']),
                                                       float(row['elbow'])))
                    elif stream == 'state':
                        recording.add_state(time_s, row['state'])
            return recording
        with np.load(path) as data:
            for stream in JOINT_STREAMS:
                for t, p, v in zip(data[f'{stream}.time_s'], data[f'{stream}.position'],
                                   data[f'{stream}.velocity']):
                    recording.add_joints(stream, t, p, v)
            for t, v in zip(data['voltage.time_s'], data['voltage.value']):
                recording.add_voltage(t, v)
            for t, n in zip(data['state.time_s'], data['state.name']):
                recording.add_state(t, n)
        return recording
