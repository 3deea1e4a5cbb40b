"""Joint trajectories as ROS arms take them (FollowJointTrajectory, JointTrajectory): read as
joint_trajectory_controller reads them, checked against forbidden space and the motors, and
judged by their tolerances. Pure: no ROS."""

import dataclasses
import math

import numpy as np
import pytest
from trajectory_checks import moveit_style, request

from arm_control.control.motions import Motion
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.parameters import ParameterError, read_parameter_files
from arm_control.plans.joint_trajectory import (ErrorCode, in_arm_order, JointTolerance,
                                                SplineTrajectory, start_delay_s,
                                                TrajectoryRefused)
from arm_control.plans.trajectory_goals import (FollowSettings, Tolerances, TrajectoryGoals,
                                                TrajectoryWatch)
from arm_control.timing import TrajectoryLimits
from arm_control.timing.timing import check

START = np.array([1.5708, -1.5708])


@pytest.fixture(scope='module')
def settings():
    return FollowSettings.from_parameters(read_parameter_files((), 'controller'))


@pytest.fixture(scope='module')
def goals(arm, controller_config, settings):
    return TrajectoryGoals(arm, controller_config, settings)


def at_rest(q=START):
    return lambda t: (np.array(q, float), np.zeros(2), np.zeros(2))


def test_the_spline_passes_through_every_point_with_its_velocity_and_acceleration():
    rows = moveit_style(START, (1.0, -1.0), 2.0)
    knots = in_arm_order(request(('shoulder', 'elbow'), rows), START)
    spline = SplineTrajectory(knots, START)
    for t, q, qd, qdd in rows:
        got = spline.sample(t)
        assert np.allclose(got[0], q, atol=1e-9)
        assert np.allclose(got[1], qd if t < 2.0 else 0.0, atol=1e-9)
        if t < 2.0:
            assert np.allclose(got[2], qdd, atol=1e-7)
    # Continuous between segments: a hair either side of an inner knot.
    t = rows[5][0]
    before, after = spline.sample(t - 1e-7), spline.sample(t + 1e-7)
    assert np.allclose(before[0], after[0], atol=1e-6)
    assert np.allclose(before[1], after[1], atol=1e-5)


def test_positions_only_leave_at_the_start_velocity_and_end_at_rest():
    rows = [(1.0, (1.4, -1.3)), (2.0, (1.2, -1.0))]
    knots = in_arm_order(request(('shoulder', 'elbow'), rows), START)
    spline = SplineTrajectory(knots, START, (0.2, 0.0))
    assert np.allclose(spline.sample(0.0)[1], (0.2, 0.0))
    assert np.allclose(spline.sample(1.0)[0], (1.4, -1.3))
    assert np.allclose(spline.sample(2.0 - 1e-9)[1], 0.0, atol=1e-6)
    assert np.allclose(spline.sample(5.0)[0], (1.2, -1.0))


def test_joints_in_any_order_and_partial_goals_hold_the_joint_left_out():
    forward = in_arm_order(request(('shoulder', 'elbow'), [(1.0, (1.2, -1.0), (0, 0))]),
                           START)
    backward = in_arm_order(request(('elbow', 'shoulder'), [(1.0, (-1.0, 1.2), (0, 0))]),
                            START)
    assert np.array_equal(forward.positions, backward.positions)
    partial = in_arm_order(request(('elbow',), [(1.0, (-1.0,))]), START)
    assert np.allclose(partial.positions, [[START[0], -1.0]])
    assert partial.partial == ('shoulder',)


@pytest.mark.parametrize('names, rows, code', [
    (('shoulder', 'wrist'), [(1.0, (1.2, 0.0))], ErrorCode.INVALID_JOINTS),
    (('elbow', 'elbow'), [(1.0, (1.2, 0.0))], ErrorCode.INVALID_JOINTS),
    ((), [(1.0, ())], ErrorCode.INVALID_JOINTS),
    (('shoulder', 'elbow'), [], ErrorCode.INVALID_GOAL),
    (('shoulder', 'elbow'), [(1.0, (1.2,))], ErrorCode.INVALID_GOAL),
    (('shoulder', 'elbow'), [(1.0, (1.2, math.nan))], ErrorCode.INVALID_GOAL),
    (('shoulder', 'elbow'), [(1.0, (1.2, -1.0)), (1.0, (1.1, -1.0))], ErrorCode.INVALID_GOAL),
    (('shoulder', 'elbow'), [(1.0, (1.2, -1.0), (0.5, 0.0))], ErrorCode.INVALID_GOAL),
    (('shoulder', 'elbow'), [(1.0, (1.2, -1.0), (0, 0)), (2.0, (1.1, -1.0))],
     ErrorCode.INVALID_GOAL),
])
def test_malformed_trajectories_are_refused_with_jtc_codes(names, rows, code):
    with pytest.raises(TrajectoryRefused) as refused:
        in_arm_order(request(names, rows), START)
    assert refused.value.code == code


def test_a_point_at_time_zero_away_from_the_arm_is_refused():
    knots = in_arm_order(request(('shoulder', 'elbow'), [(0.0, (1.0, -1.0)), (1.0, (1.1, -1))]),
                         START)
    with pytest.raises(TrajectoryRefused) as refused:
        SplineTrajectory(knots, START)
    assert refused.value.code == ErrorCode.INVALID_GOAL


def test_stamps_start_now_later_or_are_too_old():
    rows = [(1.0, (1.2, -1.0))]
    assert start_delay_s(request(('shoulder', 'elbow'), rows), 100.0) == 0.0
    assert start_delay_s(request(('shoulder', 'elbow'), rows, stamp_s=100.5), 100.0) == 0.5
    with pytest.raises(TrajectoryRefused) as refused:
        start_delay_s(request(('shoulder', 'elbow'), rows, stamp_s=90.0), 100.0)
    assert refused.value.code == ErrorCode.OLD_HEADER_TIMESTAMP


def test_a_feasible_trajectory_is_taken_as_given(goals):
    rows = moveit_style(START, (1.2, -1.0), 3.0)
    prepared = goals.prepare(request(('shoulder', 'elbow'), rows), 10.0, at_rest())
    assert prepared.note == '' and prepared.begin_s == 10.0
    assert math.isclose(prepared.trajectory.duration_s, 3.0)


def test_a_trajectory_through_the_floor_is_refused_naming_the_point(goals, arm):
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    low = (0.2, -0.6)                   # the forearm's tip below the floor
    assert kinematics.forward(low)[1] < 0.0
    rows = [(0.0, START), (2.0, (0.6, -0.9)), (4.0, low), (6.0, (1.2, -1.0))]
    with pytest.raises(TrajectoryRefused) as refused:
        goals.prepare(request(('shoulder', 'elbow'), rows), 0.0, at_rest())
    assert refused.value.code == ErrorCode.INVALID_GOAL
    assert 'between point 1 (2.000 s) and point 2 (4.000 s)' in refused.value.reason


def too_fast():
    return request(('shoulder', 'elbow'), moveit_style(START, (0.3, -0.3), 0.4))


def test_a_timing_the_motors_cannot_give_is_refused_when_so_set(arm, controller_config,
                                                                settings):
    rejecting = TrajectoryGoals(arm, controller_config,
                                dataclasses.replace(settings, infeasible_timing='reject'))
    with pytest.raises(TrajectoryRefused) as refused:
        rejecting.prepare(too_fast(), 0.0, at_rest())
    assert refused.value.code == ErrorCode.INVALID_GOAL


def test_a_timing_the_motors_cannot_give_is_retimed_to_one_they_can(goals, arm,
                                                                    controller_config):
    prepared = goals.prepare(too_fast(), 0.0, at_rest())
    trajectory = prepared.trajectory
    assert prepared.note and trajectory.duration_s > 0.4
    limits = TrajectoryLimits.from_config(arm, controller_config)
    assert check(trajectory, ArmDynamics(arm), limits).passes
    assert np.allclose(trajectory.sample(0.0)[0], START, atol=1e-9)
    assert np.allclose(trajectory.sample(trajectory.duration_s)[0], (0.3, -0.3), atol=1e-6)


def test_tolerances_follow_jtc_rules(settings):
    given = request(('shoulder', 'elbow'), [(1.0, (1.2, -1.0))],
                    path_tolerance=(JointTolerance('elbow', 0.1, -1.0, 0.0),),
                    goal_tolerance=(JointTolerance('shoulder', 0.002),),
                    goal_time_tolerance_s=0.0)
    tolerances = Tolerances.of(given, settings)
    assert tolerances.path[1, 0] == 0.1 and math.isinf(tolerances.path[1, 1])
    assert math.isinf(tolerances.path[0, 0])               # no path bound by default
    assert tolerances.goal[0, 0] == 0.002
    assert tolerances.goal[1, 0] == settings.goal_position_rad
    assert tolerances.goal_time_s == settings.goal_time_s
    wrong = dataclasses.replace(given, goal_tolerance=(JointTolerance('wrist', 0.1),))
    with pytest.raises(TrajectoryRefused) as refused:
        Tolerances.of(wrong, settings)
    assert refused.value.code == ErrorCode.INVALID_JOINTS


def test_the_watch_gives_jtc_verdicts(settings):
    rows = [(1.0, (1.6, -1.5), (0, 0))]
    knots = in_arm_order(request(('shoulder', 'elbow'), rows), START)
    motion = Motion(SplineTrajectory(knots, START), 0.0)
    given = request(('shoulder', 'elbow'), rows,
                    path_tolerance=(JointTolerance('shoulder', 0.05),),
                    goal_time_tolerance_s=0.5)
    watch = TrajectoryWatch(motion, Tolerances.of(given, settings))
    on_it = np.concatenate(motion.sample(0.5)[:2])
    assert watch.judge(0.5, True, '', on_it) is None
    off = on_it + np.array([0.1, 0.0, 0.0, 0.0])
    assert watch.judge(0.5, True, '', off)[0] == ErrorCode.PATH_TOLERANCE_VIOLATED
    there = np.array([1.6, -1.5, 0.0, 0.0])
    assert watch.judge(1.2, True, '', there)[0] == ErrorCode.SUCCESSFUL
    short = there + np.array([0.05, 0.0, 0.0, 0.0])
    assert watch.judge(1.2, True, '', short) is None       # within goal_time_tolerance
    assert watch.judge(1.6, True, '', short)[0] == ErrorCode.GOAL_TOLERANCE_VIOLATED
    assert watch.judge(0.5, False, 'e-stopped', on_it)[0] == ErrorCode.PATH_TOLERANCE_VIOLATED


def test_the_infeasible_timing_parameter_is_validated():
    params = read_parameter_files((), 'controller')
    params['trajectory_infeasible_timing'] = 'slow'
    with pytest.raises(ParameterError, match='trajectory_infeasible_timing'):
        FollowSettings.from_parameters(params)


def test_an_arm_on_the_floor_may_leave_it_but_not_come_back(goals):
    fallen = np.array([-0.349, 0.6563])            # the upper arm down on the floor
    assert not goals.forbidden.is_free(fallen)
    up = request(('shoulder', 'elbow'), [(3.0, (1.2, -1.0))])
    assert goals.prepare(up, 0.0, at_rest(fallen)).note == ''
    back = request(('shoulder', 'elbow'), [(3.0, (1.2, -1.0)), (6.0, fallen)])
    with pytest.raises(TrajectoryRefused) as refused:
        goals.prepare(back, 0.0, at_rest(fallen))
    assert refused.value.code == ErrorCode.INVALID_GOAL


def test_a_retimed_trajectory_is_never_sooner_than_asked(goals, arm, controller_config):
    asked = request(('shoulder', 'elbow'), moveit_style(START, (0.9, -0.5), 0.6))
    prepared = goals.prepare(asked, 0.0, at_rest())
    assert prepared.note                          # infeasible somewhere as asked ...
    assert math.isclose(prepared.trajectory.duration_s, 0.6, rel_tol=1e-9)   # ... not sooner
    limits = TrajectoryLimits.from_config(arm, controller_config)
    assert check(prepared.trajectory, ArmDynamics(arm), limits).passes
