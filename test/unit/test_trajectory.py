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
from trajectory_checks import (dense, follow_open_loop, PATHS, STEP_RAD, VOLTAGE_TOLERANCE,
                               worst_over_limits)

from arm_control import config
from arm_control.config import Rectangle
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.world import ForbiddenSpace
from arm_control.timing import (BlendedPath, time_optimal_trajectory, Trajectory, TrajectoryError,
                                TrajectoryLimits)
from arm_control.timing.path import initial_radii
from arm_control.timing.rows import PathTerms


@pytest.fixture(scope='module')
def setup():
    arm, controller = config.load('controller')
    return (arm, ArmDynamics(arm), ForbiddenSpace(arm),
            TrajectoryLimits.from_config(arm, controller))


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


def test_blended_path_is_smooth_on_its_knots_too(setup):
    """On a knot itself (the timing's grids cut the blends there), the direction and the
    curvature are those just beside it: it once took the next segment's direction without
    its blend's correction, a whole kink off, so that a waypoint moved by 4e-16 rad (a pose
    and back) made one of the FRC robot's moves take 3.92 s instead of 2.09 s."""
    points = np.array(PATHS['three corners'])
    path = BlendedPath(points, [0.4, 0.3])
    for knot in path.knots[1:-1]:
        beside = np.array([np.nextafter(knot, -np.inf), knot, np.nextafter(knot, np.inf)])
        for order in (0, 1, 2):
            values = path(beside, order)
            np.testing.assert_allclose(values, np.repeat(values[:1], 3, axis=0), atol=1e-9)
    assert np.all(np.linalg.norm(path(path.knots, 1), axis=1) <= 1.0 + 1e-12)


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
