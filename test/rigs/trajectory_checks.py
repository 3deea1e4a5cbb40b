"""What the trajectory tests check a trajectory with: the default arm's paths, dense samples,
the model's voltage along it, and the plant driven open loop by its feedforward; and the
joint trajectories a ROS client sends (``request``, ``moveit_style``)."""

import math

import numpy as np

from arm_control.model.dynamics import ArmDynamics
from arm_control.model.plant import ArmPlant
from arm_control.plans.joint_trajectory import TrajectoryPoint, TrajectoryRequest


STEP_RAD = 0.001745
VOLTAGE_TOLERANCE = 0.05         # V: as the trajectory module accepts

# Joint-space paths of the default arm, each checked free below.
PATHS = {
    'up to the front': [(1.5708, -1.5708), (0.3, 0.5)],
    'front over the top to the back': [(0.3, 0.5), (1.5708, 0.0), (2.8, -0.5)],
    'short hop': [(1.0, -1.0), (1.1, -0.9)],
    'three corners': [(0.2, 0.3), (1.0, 1.0), (2.0, 0.5), (2.6, -0.8)],
}


def dense(trajectory, count=4000):
    """States and the model's feedforward volts on a dense uniform time grid."""
    times = np.linspace(0.0, trajectory.duration_s, count)
    q, qd, qdd = trajectory.sample_many(times)
    return times, q, qd, qdd


def trajectory_voltage(trajectory, dynamics, times):
    """The model's feedforward volts (n, 2) along the trajectory at ``times``."""
    return dynamics.voltages(*trajectory.sample_many(times))


def peak_voltage(trajectory, dynamics, count=4000):
    times = np.linspace(0.0, trajectory.duration_s, count)
    return float(np.max(np.abs(trajectory_voltage(trajectory, dynamics, times))))


def worst_over_limits(trajectory, dynamics, limits, count=2000):
    """How far past its limits (V) the trajectory goes at its worst, with the sim's exact
    electrical model: each joint's voltage against the bus it leaves less the reserve
    (driving along the joint's motion, braking against it), its volts above the back-EMF
    against I_limit·R less the same reserve."""
    supply = limits.supply
    times = np.linspace(0.0, trajectory.duration_s, count)
    q, qd, qdd = trajectory.sample_many(times)
    reserves = limits.reserves_v
    worst = -math.inf
    for volts, speed in zip(dynamics.voltages(q, qd, qdd), qd):
        power = supply.solve(volts, speed)
        assert not power.browned_out
        for j, motor in enumerate(dynamics.motors):
            moving = abs(speed[j]) > 1e-3
            emf = motor.back_emf_v(speed[j])
            reserve_v = reserves[0] if not moving or volts[j] * speed[j] >= 0.0 else reserves[1]
            reserve_i = reserves[0] if not moving or (volts[j] - emf) * speed[j] >= 0.0 \
                else reserves[1]
            worst = max(worst, abs(volts[j]) - (min(power.bus_voltage, supply.nominal_voltage)
                                                - reserve_v),
                        abs(volts[j] - emf) - (supply.current_window_v[j] - reserve_i))
    return worst


def follow_open_loop(arm, trajectory, start_velocity=(0.0, 0.0), step_s=0.001, hold_s=0.3):
    """Drive the plant with the model's feedforward at the sampled setpoint, no feedback."""
    dynamics = ArmDynamics(arm)
    plant = ArmPlant(arm, trajectory.start_rad, physics_step_s=step_s)
    plant.reset(trajectory.start_rad, start_velocity)
    for k in range(int(round((trajectory.duration_s + hold_s) / step_s))):
        q, qd, qdd = trajectory.sample((k + 0.5) * step_s)
        plant.set_voltage(dynamics.voltage_for(q, qd, qdd))
        plant.advance(step_s)
    return np.array(plant.state)


def request(names, rows, **fields):
    """rows: (time, positions[, velocities[, accelerations]])."""
    points = tuple(TrajectoryPoint(tuple(r[1]), *(tuple(v) for v in r[2:]),
                                   time_from_start_s=r[0]) for r in rows)
    return TrajectoryRequest(tuple(names), points, **fields)


def moveit_style(start, end, duration_s, count=12):
    """A MoveIt-like trajectory: points along a smooth profile with positions, velocities
    and accelerations, the first at the start at time 0."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    rows = []
    for t in np.linspace(0.0, duration_s, count):
        u = t / duration_s                          # s(u) = 10u³ − 15u⁴ + 6u⁵: rest to rest
        s = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
        sd = (30 * u ** 2 - 60 * u ** 3 + 30 * u ** 4) / duration_s
        sdd = (60 * u - 180 * u ** 2 + 120 * u ** 3) / duration_s ** 2
        rows.append((float(t), start + s * (end - start), sd * (end - start),
                     sdd * (end - start)))
    return rows
