"""Time-optimal trajectories: ends, limits, free space, optimality and preemption.

The electrical limits (current limits, bus sag, brownout) have their own tests in
test_trajectory_electrical.py; here the default arm's supply is in force wherever the limits
come from the config (``TrajectoryLimits.from_config``), and absent (a stiff supply) where a
test builds its limits by hand.
"""

import dataclasses
import math

import numpy as np
import pytest

from arm_control import config
from arm_control.config import Rectangle
from arm_control.control.trajectory import (BlendedPath, estimated_duration_s,
                                            sure_acceleration_rad_s2,
                                            time_optimal_trajectory, Trajectory,
                                            TrajectoryError, TrajectoryLimits)
from arm_control.control.trajectory.moving_start import piece_duration, time_moving
from arm_control.control.trajectory.path import FINE_GRID, grid_for, initial_radii
from arm_control.control.trajectory.rows import PathTerms
from arm_control.control.trajectory.timing import time_from_rest
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.electrical import PowerSupply
from arm_control.model.plant import ArmPlant
from arm_control.model.world import ForbiddenSpace

STEP_RAD = 0.001745
VOLTAGE_TOLERANCE = 0.05         # V: as the trajectory module accepts

# Joint-space paths of the default arm, each checked free below.
PATHS = {
    'up to the front': [(1.5708, -1.5708), (0.3, 0.5)],
    'front over the top to the back': [(0.3, 0.5), (1.5708, 0.0), (2.8, -0.5)],
    'short hop': [(1.0, -1.0), (1.1, -0.9)],
    'three corners': [(0.2, 0.3), (1.0, 1.0), (2.0, 0.5), (2.6, -0.8)],
}


@pytest.fixture(scope='module')
def setup():
    arm, controller = config.load('controller')
    return (arm, ArmDynamics(arm), ForbiddenSpace(arm),
            TrajectoryLimits.from_config(arm, controller))


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


def test_limits_from_config_keep_the_feedback_reserve(setup):
    """The reserve for feedback on the braking side, the driving one's on the other."""
    arm, _, _, limits = setup
    _, controller = config.load('controller')
    volts = arm.battery.nominal_voltage
    assert limits.budget == pytest.approx((volts - controller.driving_voltage_reserve,
                                           volts - controller.feedback_voltage_reserve))


@pytest.mark.parametrize('name', sorted(PATHS))
def test_starts_on_the_first_waypoint_and_ends_at_rest_on_the_last(setup, name):
    _, dynamics, forbidden, limits = setup
    waypoints = np.array(PATHS[name])
    assert forbidden.path_is_free(waypoints, STEP_RAD)
    trajectory = time_optimal_trajectory(waypoints, dynamics, forbidden, limits)
    q0, qd0, _ = trajectory.sample(0.0)
    np.testing.assert_allclose(q0, waypoints[0], atol=1e-12)
    np.testing.assert_allclose(qd0, 0.0, atol=1e-9)
    for t in (trajectory.duration_s, trajectory.duration_s + 1.0):
        q, qd, qdd = trajectory.sample(t)
        np.testing.assert_array_equal(q, waypoints[-1])
        np.testing.assert_array_equal(qd, 0.0)
        np.testing.assert_array_equal(qdd, 0.0)
    # Just before the end it is already there, slowly: q(t) is continuous into the end.
    q, qd, _ = trajectory.sample(trajectory.duration_s - 1e-4)
    assert np.max(np.abs(q - waypoints[-1])) < 1e-3
    assert np.max(np.abs(qd)) < 0.5
    np.testing.assert_array_equal(trajectory.sample(-1.0)[0], q0)


@pytest.mark.parametrize('name', sorted(PATHS))
def test_the_limits_hold_and_one_of_them_is_reached(setup, name):
    """Time-optimal under the supply: nothing past its limit (voltage within the bus less
    the reserve, current within its limit less the reserve), and somewhere one is reached."""
    _, dynamics, forbidden, limits = setup
    trajectory = time_optimal_trajectory(PATHS[name], dynamics, forbidden, limits)
    worst = worst_over_limits(trajectory, dynamics, limits)
    assert -0.1 < worst <= VOLTAGE_TOLERANCE


@pytest.mark.parametrize('name', sorted(PATHS))
def test_ten_percent_faster_needs_more_than_the_supply_gives(setup, name):
    """The same path 10% faster is beyond the limits: the timing is near the physical edge."""
    _, dynamics, forbidden, limits = setup
    trajectory = time_optimal_trajectory(PATHS[name], dynamics, forbidden, limits)
    faster = trajectory.scaled(0.9)
    assert faster.duration_s == pytest.approx(0.9 * trajectory.duration_s)
    assert worst_over_limits(faster, dynamics, limits) > 0.2


def test_velocity_and_acceleration_limits_hold_and_are_reached(setup):
    arm, dynamics, forbidden, _ = setup
    tight = TrajectoryLimits((0.8, 1.2), (3.0, 5.0), 11.0)
    trajectory = time_optimal_trajectory(PATHS['three corners'], dynamics, forbidden, tight)
    _, _, qd, qdd = dense(trajectory)
    velocity, acceleration = np.abs(qd).max(axis=0), np.abs(qdd).max(axis=0)
    assert np.all(velocity <= np.array(tight.max_velocity_rad_s) * 1.02)
    assert np.all(acceleration <= np.array(tight.max_acceleration_rad_s2) * 1.02)
    assert np.any(velocity > 0.98 * np.array(tight.max_velocity_rad_s))
    assert np.any(acceleration > 0.98 * np.array(tight.max_acceleration_rad_s2))


@pytest.mark.parametrize('distance_rad, velocity_limit', [(1.0, 10.0), (2.0, 1.0)])
def test_acceleration_limited_straight_move_takes_the_bang_bang_time(
        setup, distance_rad, velocity_limit):
    """With volts to spare, a straight shoulder move is bang-bang (or trapezoidal):
    T = 2√(D/A), or D/v + v/A when the speed limit v is reached."""
    _, dynamics, forbidden, _ = setup
    acceleration = 4.0
    limits = TrajectoryLimits((velocity_limit, velocity_limit), (acceleration, acceleration),
                              1e4)
    start = np.array([0.5, 0.3])
    trajectory = time_optimal_trajectory([start, start + (distance_rad, 0.0)], dynamics,
                                         forbidden, limits)
    triangle = 2.0 * math.sqrt(distance_rad / acceleration)
    peak_speed = math.sqrt(distance_rad * acceleration)
    expected = (triangle if peak_speed <= velocity_limit
                else distance_rad / velocity_limit + velocity_limit / acceleration)
    assert trajectory.duration_s == pytest.approx(expected, rel=0.01)


def test_the_time_law_reconstructs_the_models_voltage(setup):
    """V = a·s̈ + b·ṡ² + c + d·ṡ + coulomb + e·q'ṡ along the path equals voltage_for, for
    any (ṡ, s̈)."""
    arm, _, _, _ = setup
    joint = dataclasses.replace(arm.shoulder, viscous_friction_nm_s_per_rad=3.0,
                                coulomb_friction_nm=5.0)
    dynamics = ArmDynamics(dataclasses.replace(arm, shoulder=joint))
    path = BlendedPath(np.array(PATHS['three corners']), [0.3, 0.2])
    grid = np.linspace(0.0, path.length, 37)
    terms = PathTerms.along(dynamics, path, grid)
    rng = np.random.default_rng(4)
    u, x = rng.uniform(-5.0, 5.0, len(grid)), rng.uniform(0.0, 6.0, len(grid))
    speed = np.sqrt(x)
    expected = [dynamics.voltage_for(q, p * s, p * a + pp * s * s)
                for q, p, pp, s, a in zip(terms.q, terms.dq, terms.ddq, speed, u)]
    np.testing.assert_allclose(terms.voltage(u, x), expected, atol=1e-9)


def test_blended_path_is_smooth_and_keeps_its_ends(setup):
    points = np.array(PATHS['three corners'])
    path = BlendedPath(points, [0.4, 0.3])
    np.testing.assert_allclose(path(0.0), points[0], atol=1e-12)
    np.testing.assert_allclose(path(path.length), points[-1], atol=1e-12)
    s = np.linspace(0.0, path.length, 20001)
    step = s[1] - s[0]
    q, dq, ddq = path(s), path(s, 1), path(s, 2)
    # Derivatives agree with finite differences: q is C², no hidden jumps.
    np.testing.assert_allclose(np.gradient(q, step, axis=0)[1:-1], dq[1:-1], atol=1e-4)
    np.testing.assert_allclose(np.gradient(dq, step, axis=0)[1:-1], ddq[1:-1], atol=1e-3)
    assert np.max(np.linalg.norm(np.diff(dq, axis=0), axis=1)) < 1e-3


def arm_with_post():
    """The default arm with a post in front of it, from the floor to 0.9 m."""
    arm, controller = config.load('controller')
    post = Rectangle('post', 0.5, 0.0, 0.8, 0.9)
    world = dataclasses.replace(arm.world, regions=arm.world.regions + (post,))
    return dataclasses.replace(arm, world=world), controller


def test_blends_that_would_cut_into_forbidden_space_are_tightened():
    """A plan up and over a post: the widest corner blends would clip the post; the
    trajectory's path must not."""
    arm, controller = arm_with_post()
    forbidden = ForbiddenSpace(arm)
    waypoints = np.array([[1.154, -1.047], [1.876, -1.937], [1.876, -2.216],
                          [1.412, -2.805]])
    assert forbidden.path_is_free(waypoints, STEP_RAD)
    widest = BlendedPath(waypoints, initial_radii(waypoints))
    assert not np.all(forbidden.is_free(widest(np.linspace(0.0, widest.length, 5000))))

    trajectory = time_optimal_trajectory(waypoints, ArmDynamics(arm), forbidden,
                                         TrajectoryLimits.from_config(arm, controller))
    _, q, _, _ = dense(trajectory, 20000)
    assert np.all(forbidden.is_free(q))
    np.testing.assert_array_equal(trajectory.sample(trajectory.duration_s)[0], waypoints[-1])


def test_a_corner_with_no_room_to_blend_is_a_stop(setup):
    """An exact reversal cannot be rounded: the arm comes to rest on the corner."""
    _, dynamics, forbidden, limits = setup
    waypoints = np.array([(0.8, -0.5), (1.6, -0.5), (1.2, -0.5)])
    trajectory = time_optimal_trajectory(waypoints, dynamics, forbidden, limits)
    times, q, qd, _ = dense(trajectory, 20000)
    nearest = np.argmin(np.linalg.norm(q - waypoints[1], axis=1))
    assert np.linalg.norm(q[nearest] - waypoints[1]) < 1e-3
    assert np.linalg.norm(qd[nearest]) < 0.1
    assert np.max(q[:, 0]) <= 1.6 + 1e-9


def test_a_path_through_forbidden_space_is_refused(setup):
    _, dynamics, forbidden, limits = setup
    with pytest.raises(TrajectoryError, match='forbidden'):
        time_optimal_trajectory([(0.5, 0.0), (-0.3, 0.0)], dynamics, forbidden, limits)


@pytest.mark.parametrize('bad', [[(0.5, math.nan), (1.0, 0.0)], [], [(1.0, 2.0, 3.0)]])
def test_malformed_waypoints_are_refused(setup, bad):
    _, dynamics, forbidden, limits = setup
    with pytest.raises(TrajectoryError):
        time_optimal_trajectory(bad, dynamics, forbidden, limits)


def test_a_single_waypoint_at_rest_is_a_trajectory_of_no_time(setup):
    _, dynamics, forbidden, limits = setup
    trajectory = time_optimal_trajectory([(1.0, -1.0)], dynamics, forbidden, limits)
    assert isinstance(trajectory, Trajectory)
    assert trajectory.duration_s == 0.0
    q, qd, _ = trajectory.sample(0.3)
    np.testing.assert_array_equal(q, (1.0, -1.0))
    np.testing.assert_array_equal(qd, 0.0)


@pytest.mark.parametrize('name', ['up to the front', 'front over the top to the back',
                                  'three corners'])
def test_feedforward_alone_brings_the_plant_to_the_goal(setup, name):
    """The timing inverts the plant's own model: open-loop feedforward lands on the goal."""
    arm, dynamics, forbidden, limits = setup
    trajectory = time_optimal_trajectory(PATHS[name], dynamics, forbidden, limits)
    state = follow_open_loop(arm, trajectory)
    error = np.abs(state[:2] - np.array(PATHS[name][-1]))
    assert np.all(error < math.radians(0.5)), np.degrees(error)
    assert np.all(np.abs(state[2:]) < 0.05)


# A preempted move: the arm is at the first waypoint moving at start_velocity.
MOVING = {
    'along the path': ([(1.0, -1.0), (2.0, -0.5)], (1.0, 0.5)),
    'across the path': ([(1.0, -1.0), (2.0, -1.0)], (0.0, 1.5)),
    # (at 2.2 rad/s toward the floor the current limits could no longer stop it in time)
    'against the path': ([(1.0, -1.0), (2.0, -1.0), (2.5, 0.5)], (-1.5, -0.75)),
    'fast across a short path': ([(1.2, -1.0), (1.5, -1.0)], (0.0, 3.5)),
    'moving but already there': ([(1.0, -1.0)], (1.0, 1.0)),
}


@pytest.mark.parametrize('name', sorted(MOVING))
def test_a_moving_start_leaves_at_the_current_velocity_and_continues_smoothly(setup, name):
    arm, dynamics, forbidden, limits = setup
    waypoints, velocity = MOVING[name]
    trajectory = time_optimal_trajectory(waypoints, dynamics, forbidden, limits,
                                         start_velocity_rad_s=velocity)
    q0, qd0, _ = trajectory.sample(0.0)
    np.testing.assert_allclose(q0, waypoints[0], atol=1e-12)
    np.testing.assert_allclose(qd0, velocity, atol=1e-6)
    times, q, qd, qdd = dense(trajectory, 20000)
    dt = times[1] - times[0]
    # Continuous velocity: no step bigger than the acceleration limit allows in one sample.
    jumps = np.abs(np.diff(qd, axis=0)).max(axis=0)
    assert np.all(jumps <= np.array(limits.max_acceleration_rad_s2) * dt * 1.05 + 1e-9)
    assert np.all(forbidden.is_free(q))
    assert worst_over_limits(trajectory, dynamics, limits) <= VOLTAGE_TOLERANCE
    np.testing.assert_array_equal(trajectory.sample(trajectory.duration_s)[0], waypoints[-1])
    state = follow_open_loop(arm, trajectory, start_velocity=velocity)
    assert np.all(np.abs(state[:2] - np.array(waypoints[-1])) < math.radians(0.5))


def test_a_moving_start_is_no_slower_than_stopping_first(setup):
    """Keeping the speed the arm already has toward the goal saves time."""
    _, dynamics, forbidden, limits = setup
    waypoints = [(0.5, -0.5), (2.0, -0.5)]
    moving = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, (1.5, 0.0))
    resting = time_optimal_trajectory(waypoints, dynamics, forbidden, limits)
    assert moving.duration_s < resting.duration_s - 0.05     # (the rest start is reshaped)


def test_a_start_faster_than_the_speed_limit_slows_into_it(setup):
    _, dynamics, forbidden, limits = setup
    trajectory = time_optimal_trajectory([(1.0, -1.0), (2.5, -1.0)], dynamics, forbidden,
                                         limits, start_velocity_rad_s=(3.4, 0.0))
    np.testing.assert_allclose(trajectory.sample(0.0)[1], (3.4, 0.0), atol=1e-6)
    times, _, qd, _ = dense(trajectory)
    assert np.all(np.abs(qd[times > 0.2, 0]) <= limits.max_velocity_rad_s[0] * 1.02)


def test_a_start_inside_forbidden_space_follows_the_planned_way_out(setup):
    """The planner leads an arm pushed below the floor straight out; from there on the
    trajectory is free."""
    _, dynamics, forbidden, limits = setup
    start, out = np.array([-0.05, 0.3]), np.array([0.1, 0.3])
    assert not forbidden.is_free(start) and forbidden.is_free(out)
    waypoints = [start, out, (1.2, -0.5)]
    trajectory = time_optimal_trajectory(waypoints, dynamics, forbidden, limits)
    _, q, _, _ = dense(trajectory, 20000)
    along = (q - start) @ (out - start) / np.linalg.norm(out - start) ** 2
    escaped = along >= 1.0 - 1e-9
    assert np.all(forbidden.is_free(q[escaped]))
    assert np.all(np.abs(q[~escaped, 1] - 0.3) < 1e-9)       # on the way-out segment
    np.testing.assert_array_equal(trajectory.sample(trajectory.duration_s)[0], (1.2, -0.5))


# --- reshaping, the exact timing from rest, the voltage windows, the period feedforward ----

def link_heights(arm, q):
    """The lower of the elbow's and the tool's heights (m) for each configuration."""
    elbow = np.sin(q[:, 0]) * arm.shoulder.length_m
    return np.minimum(elbow, elbow + np.sin(q.sum(axis=1)) * arm.elbow.length_m)


@pytest.mark.parametrize('name', ['three corners', 'front over the top to the back'])
def test_a_bent_path_is_faster_free_and_keeps_its_room(setup, name):
    """Reshaping (folding the elbow on the way, ...) beats the planner's shortest path by
    several percent, stays free at 0.1 deg steps and keeps 3 cm from the floor wherever the
    planner's path did."""
    arm, dynamics, forbidden, limits = setup
    waypoints = PATHS[name]
    bent = time_optimal_trajectory(waypoints, dynamics, forbidden, limits)
    straight = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, reshape=False)
    assert bent.duration_s < 0.97 * straight.duration_s
    _, q, _, _ = dense(bent, 20000)
    assert np.all(forbidden.is_free(q))
    _, q_straight, _, _ = dense(straight, 20000)
    heights, straight_heights = link_heights(arm, q), link_heights(arm, q_straight)
    assert heights.min() >= min(straight_heights.min(), 0.03) - 1e-3


def test_the_exact_timing_matches_toppra_on_a_straight_path(setup):
    """Two methods, one answer: the closed-form passes (back-EMF exact) and TOPP-RA
    (back-EMF linearised, iterated) time the same path within 2 %."""
    _, dynamics, forbidden, limits = setup
    path = BlendedPath(np.array(PATHS['up to the front']), [])
    grid = grid_for(path, FINE_GRID)
    terms = PathTerms.along(dynamics, path, grid)
    exact, _ = time_from_rest(path, grid, terms, limits)
    x, _ = time_moving(path, grid, terms, limits, 0.0)
    assert piece_duration(grid, np.sqrt(exact)) == pytest.approx(
        piece_duration(grid, np.sqrt(x)), rel=0.02)


def test_braking_keeps_its_reserve_and_driving_uses_the_rest(setup):
    """A joint's voltage reaches the driving limit along its motion, and against it never
    passes the (lower) braking limit, which it also reaches."""
    _, dynamics, forbidden, _ = setup
    limits = TrajectoryLimits((6.0, 6.0), (150.0, 530.0), 12.0, 10.0)
    trajectory = time_optimal_trajectory(PATHS['up to the front'], dynamics, forbidden, limits,
                                         reshape=False)
    times, q, qd, qdd = dense(trajectory, 8000)
    volts = trajectory_voltage(trajectory, dynamics, times)
    moving = np.abs(qd) > 0.05
    along = np.sign(qd) * volts
    assert along[moving].max() <= 12.0 + VOLTAGE_TOLERANCE
    assert along[moving].max() > 11.8
    assert along[moving].min() >= -10.0 - VOLTAGE_TOLERANCE
    assert along[moving].min() < -9.8


@pytest.mark.parametrize('name', sorted(PATHS))
def test_the_quick_estimate_is_near_the_timing(setup, name):
    _, dynamics, forbidden, limits = setup
    estimate = estimated_duration_s(PATHS[name], dynamics, limits)
    timed = time_optimal_trajectory(PATHS[name], dynamics, forbidden, limits, reshape=False)
    assert estimate == pytest.approx(timed.duration_s, rel=0.1)


def test_the_sure_acceleration_is_there_in_every_free_pose(setup):
    """In random free poses, each joint can accelerate at least that much either way from
    rest, with ±11 V commanded and the supply applying what its limits allow."""
    arm, dynamics, forbidden, _ = setup
    supply = PowerSupply(arm, dynamics.motors)
    sure = sure_acceleration_rad_s2(dynamics, forbidden, 11.0)
    assert np.all(sure > 1.0)
    rng = np.random.default_rng(3)
    poses = rng.uniform([0.0, -2.9], [math.pi, 2.9], (300, 2))
    corners = [(-11.0, -11.0), (-11.0, 11.0), (11.0, -11.0), (11.0, 11.0)]
    for q in poses[np.asarray(forbidden.is_free(poses), dtype=bool)]:
        reach = np.array([dynamics.derivative([q[0], q[1], 0.0, 0.0],
                                              supply.solve(v, (0.0, 0.0)).applied_v)[2:]
                          for v in corners])
        assert np.all(reach.max(axis=0) >= 0.99 * sure)
        assert np.all(-reach.min(axis=0) >= 0.99 * sure)
