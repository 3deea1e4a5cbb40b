"""Goals: inverse then forward kinematics, every rejection, the elbow branch chosen."""

import dataclasses
import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from arm_control.config import Rectangle
from arm_control.model.kinematics import TwoLinkKinematics, UnreachableError
from arm_control.plans.goals import (choose_branch, clamp_to_annulus, GoalValidator,
                                     joint_travel_rad, StraightLinePlanner)


@pytest.fixture(scope='module')
def validator(arm):
    return GoalValidator(arm)


# --- IK then FK, over the whole workspace -------------------------------------------------

@settings(derandomize=True, max_examples=400, deadline=None)
@given(radius_fraction=st.floats(0.0, 1.0), heading=st.floats(-math.pi, math.pi))
def test_inverse_then_forward_returns_the_point(arm, radius_fraction, heading):
    """Every point of the annulus, on both branches (and as taken into the joints' ranges)."""
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    inner, outer = kinematics.reach_m
    radius = inner + radius_fraction * (outer - inner)
    x, y = radius * math.cos(heading), radius * math.sin(heading)
    for q in kinematics.inverse(x, y):
        assert kinematics.forward(q) == pytest.approx((x, y), abs=1e-9)
    for branch in GoalValidator(arm).branches(x, y):
        assert kinematics.forward(branch.q_rad) == pytest.approx((x, y), abs=1e-9)


@settings(derandomize=True, max_examples=200, deadline=None)
@given(shoulder=st.floats(-0.349, 3.491), elbow=st.floats(-3.0, 3.0))
def test_one_branch_is_the_configuration_it_came_from(arm, shoulder, elbow):
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    x, y = kinematics.forward((shoulder, elbow))
    solutions = [np.array(q) for q in kinematics.inverse(x, y)]
    wrapped = np.array([math.remainder(shoulder, 2 * math.pi), elbow])
    assert min(np.max(np.abs(np.remainder(q - wrapped + math.pi, 2 * math.pi) - math.pi))
               for q in solutions) < 1e-6


def test_the_jacobian_is_the_derivative_of_forward_kinematics(arm):
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    rng = np.random.default_rng(11)
    for _ in range(50):
        q = rng.uniform(-3, 3, 2)
        step = 1e-6
        numeric = np.column_stack([
            (np.array(kinematics.forward(q + step * e)) - kinematics.forward(q - step * e))
            / (2 * step) for e in np.eye(2)])
        assert np.allclose(kinematics.jacobian(q), numeric, atol=1e-6)


# --- rejections, each with its reason ---------------------------------------------------

@pytest.mark.parametrize('point, cause', [
    ((math.nan, 1.0, 0.0), 'not finite'),
    ((1.0, math.inf, 0.0), 'not finite'),
    ((1.0, 1.0, -math.inf), 'not finite'),
    ((1.0e300, 1.0, 0.0), 'out of reach'),
    ((2.0, 1.0, 0.0), 'out of reach'),
    ((0.05, 0.1, 0.0), 'out of reach'),
    ((1.0, 1.0, 0.002), 'off the plane'),
    ((1.0, -0.5, 0.0), 'forbidden'),
    ((0.0, 0.205, 0.0), 'forbidden'),
    ((1.8, 0.0, 0.0), 'forbidden'),         # on the floor line: within the clearance
    ((1.2, 0.01, 0.0), 'forbidden'),        # 1 cm above it, still within 1 deg of it
])
def test_bad_goals_are_rejected_with_the_reason(validator, point, cause):
    check = validator.check(*point)
    assert not check.ok and check.goal is None
    assert check.category == cause
    assert check.reason.endswith((')', 'm', 'finite number', 'mm)'))  # a whole sentence


def test_a_goal_keeps_the_clearance_from_forbidden_space(validator, arm):
    """Every branch the validator offers is clear of forbidden space by world.clearance_rad
    on both joints: holding there, overshoot and noise stay out."""
    margin = arm.world.clearance_rad
    rng = np.random.default_rng(8)
    for x, y in rng.uniform((-1.8, 0.0), (1.8, 1.8), (300, 2)):
        if not validator.kinematics.is_reachable(x, y):
            continue
        for q in validator.free_configurations(x, y):
            assert validator.forbidden.clear_by(np.array(q), margin)


def test_a_goal_in_another_frame_is_rejected(validator):
    check = validator.check(1.0, 1.0, 0.0, 'map')
    assert not check.ok
    assert "'map'" in check.reason and 'arm_base' in check.reason


@pytest.mark.parametrize('frame', ['', 'arm_base'])
def test_a_goal_in_arm_base_is_accepted(validator, frame):
    check = validator.check(1.0, 1.0, 0.0005, frame)
    assert check.ok and check.goal.xy == (1.0, 1.0) and check.reason == ''


def test_the_floor_reason_names_the_region(validator):
    reason = validator.check(1.0, -0.5).reason
    assert '"floor"' in reason


def test_clamping_moves_an_unreachable_goal_onto_the_annulus(arm):
    clamping = GoalValidator(arm, clamp_unreachable_goals=True)
    far = clamping.check(3.0, 4.0)                      # 5 m away, heading kept
    assert far.ok and 'clamped' in far.goal.note
    assert math.hypot(*far.goal.xy) == pytest.approx(1.8, abs=1e-5)
    assert math.atan2(far.goal.y_m, far.goal.x_m) == pytest.approx(math.atan2(4.0, 3.0))
    assert not clamping.check(math.nan, 0.0).ok        # clamping never hides a NaN


def test_clamping_onto_the_inner_circle_meets_the_elbow_fold(arm):
    """The inner circle needs the elbow folded flat, past its stops: the
    clamped goal is still rejected, for that reason."""
    near = GoalValidator(arm, clamp_unreachable_goals=True).check(0.05, 0.1)
    assert not near.ok and 'outside its limits' in near.reason
    assert clamp_to_annulus(0.0, 0.0, 0.2, 1.8) == pytest.approx((0.0, 0.2), abs=1e-5)


def test_clamp_leaves_reachable_points_alone():
    assert clamp_to_annulus(1.0, 0.5, 0.2, 1.8) == (1.0, 0.5)


# --- the elbow branch ----------------------------------------------------------------------

def test_when_one_branch_is_forbidden_the_other_is_chosen(validator):
    """(1.2, 0.3): the positive-elbow branch puts the shoulder below its stop."""
    free = validator.free_configurations(1.2, 0.3)
    assert len(free) == 1 and free[0][1] < 0.0
    assert choose_branch((1.5708, -1.5708), free) == free[0]


@pytest.mark.parametrize('start, elbow_sign', [((0.6, 1.4), +1), ((1.6, -1.4), -1)])
def test_least_joint_travel_wins_without_a_cost(validator, start, elbow_sign):
    free = validator.free_configurations(0.5, 1.2)
    assert len(free) == 2
    chosen = choose_branch(start, free)
    assert math.copysign(1.0, chosen[1]) == elbow_sign
    assert joint_travel_rad(start, chosen) == min(joint_travel_rad(start, q) for q in free)


def test_a_cost_overrides_joint_travel(validator):
    free = validator.free_configurations(0.5, 1.2)
    start = (0.6, 1.4)                                  # nearer the positive-elbow branch
    by_travel = choose_branch(start, free)
    slower_near = {tuple(q): (5.0 if q == by_travel else 1.0) for q in free}
    assert choose_branch(start, free, lambda q: slower_near[tuple(q)]) != by_travel
    assert choose_branch(start, free, lambda q: None) is None
    assert choose_branch(start, []) is None


def test_straight_line_planner_goes_straight_when_free(arm):
    plan = StraightLinePlanner(arm).plan((1.5708, -1.5708), (0.5, 1.2))
    assert plan.ok
    assert len(plan.waypoints_rad) == 2
    assert TwoLinkKinematics(1.0, 0.8).forward(plan.waypoints_rad[-1]) == \
        pytest.approx((0.5, 1.2))


def test_straight_line_planner_refuses_a_move_through_an_obstacle(arm):
    """Arm straight up, swinging down to (1.7, 0.3) m: a box at 45 deg is in the way."""
    box = Rectangle('box', 1.0, 1.0, 1.4, 1.4)
    boxed = dataclasses.replace(arm, world=dataclasses.replace(
        arm.world, regions=arm.world.regions + (box,)))
    assert StraightLinePlanner(arm).plan((1.5708, 0.0), (1.7, 0.3)).ok
    plan = StraightLinePlanner(boxed).plan((1.5708, 0.0), (1.7, 0.3))
    assert not plan.ok and 'through free space' in plan.reason


def test_unreachable_point_raises_with_the_reach(arm):
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    with pytest.raises(UnreachableError, match='reaches 0.200 to 1.800 m'):
        kinematics.inverse(2.0, 0.0)


def test_goal_is_immutable(validator):
    goal = validator.check(1.0, 1.0).goal
    with pytest.raises(dataclasses.FrozenInstanceError):
        goal.x_m = 0.0
