"""A run of the arm as time-stamped streams, for plotting: no ROS here.

Streams (times in s; angles in rad, rates in rad/s, voltages in V):

    measured   what the sensors read (``joint_states``): position, velocity   [shoulder, elbow]
    truth      the sim's true state (``sim/ground_truth``): position, velocity
    setpoint   the trajectory's setpoint (``controller/setpoint``): position, velocity
    voltage    the commanded motor voltages (``voltage_command``): value [shoulder_V, elbow_V]
    state      the state machine's state (``arm_state``): name, kept at each change

``bag.load_run`` fills one from a bag the ``recorder`` node wrote; the demo fills one from an
in-process run with ``Recording.from_samples``.
"""

from dataclasses import dataclass
import math

import numpy as np

JOINT_STREAMS = ('measured', 'truth', 'setpoint')


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
