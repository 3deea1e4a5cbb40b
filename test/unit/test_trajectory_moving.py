"""Moving starts, reshaped paths, the exact timing against TOPP-RA, the voltage windows and the
sure acceleration."""

import math

import numpy as np
import pytest
from trajectory_checks import (dense, follow_open_loop, PATHS, trajectory_voltage,
                               VOLTAGE_TOLERANCE, worst_over_limits)

from arm_control import config
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.electrical import PowerSupply
from arm_control.model.world import ForbiddenSpace
from arm_control.timing import (BlendedPath, estimated_duration_s, sure_acceleration_rad_s2,
                                time_optimal_trajectory, TrajectoryLimits)
from arm_control.timing.moving_start import piece_duration, time_moving
from arm_control.timing.path import FINE_GRID, grid_for
from arm_control.timing.rows import PathTerms
from arm_control.timing.timing import time_from_rest


@pytest.fixture(scope='module')
def setup():
    arm, controller = config.load('controller')
    return (arm, ArmDynamics(arm), ForbiddenSpace(arm),
            TrajectoryLimits.from_config(arm, controller))


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
