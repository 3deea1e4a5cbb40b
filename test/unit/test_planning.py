"""Planning in configuration space: known answers, optimality by brute force, free paths."""

import dataclasses
import math

import numpy as np
from planning_checks import assert_free_path, CHECK_STEP_RAD, highest_point_m, presets
import pytest

from arm_control.config import PlannerConfig, Rectangle
from arm_control.planning.plan import NoPlan
from arm_control.planning.planner import Planner
from arm_control.planning.poses import poses_from_waypoints
from arm_control.plans.cache import PresetAnswers
from arm_control.plans.timer import BranchRanking


def test_grid_cells_lie_inside_the_joint_travel(frc):
    grid = frc.grid
    for axis, (low, high) in zip((grid.shoulder, grid.elbow), frc.forbidden.limits):
        centres = axis.centres()
        assert centres[0] - low >= 0.5 * axis.step_rad - 1e-9
        assert high - centres[-1] >= 0.5 * axis.step_rad - 1e-9
        np.testing.assert_allclose(np.diff(centres), frc.config.grid_resolution_rad)
    np.testing.assert_array_equal(
        grid.free.ravel(), frc.forbidden.is_free(grid.configurations))
    assert 0.3 < grid.free.mean() < 0.9


def test_neighbours_join_across_180_degrees_but_never_across_a_hard_stop(frc):
    """The shoulder travels -20° to 200°: the grid runs straight through ±180°, and the
    140° arc beyond the stops (200° round to 340°) is not part of it."""
    grid = frc.grid
    shoulder = grid.shoulder.centres()
    assert shoulder.min() < 0.0 and shoulder.max() > math.pi
    assert np.all(np.diff(shoulder) > 0)
    low_cell, high_cell = grid.node_of(0, 100), grid.node_of(grid.shoulder.count - 1, 100)
    neighbours_of_low = set(grid.indices[low_cell * 8:(low_cell + 1) * 8].tolist())
    assert high_cell not in neighbours_of_low
    # Through 180° on the shoulder (the tower lifts the pivot, so the arm may point
    # back and down): a straight, continuous move, no jump of a turn.
    start, goal = np.radians([170.0, -90.0]), np.radians([195.0, -90.0])
    plan = frc.plan_to_configuration(start, goal)
    assert_free_path(frc, plan, start, goal)
    assert plan.cost_rad == pytest.approx(math.radians(25))


def test_a_move_across_the_hard_stop_arc_goes_the_long_way_round(frc):
    start = np.radians([195.0, -90.0])     # pointing back and down, near its stop
    goal = np.radians([-15.0, 60.0])       # pointing forward and down, near its stop
    plan = frc.plan_to_configuration(start, goal)
    assert_free_path(frc, plan, start, goal)
    assert np.all(frc.forbidden.within_limits(plan.waypoints_rad))
    assert plan.cost_rad >= math.radians(210) - 1e-9   # not the 150° through the stop arc


# Known answers


def test_a_free_straight_move_is_one_segment(frc):
    start, goal = [math.radians(60), math.radians(-60)], [math.radians(80), math.radians(-90)]
    assert frc.forbidden.segment_is_free(start, goal, CHECK_STEP_RAD)
    plan = frc.plan_to_configuration(start, goal)
    assert_free_path(frc, plan, start, goal)
    assert len(plan.waypoints_rad) == 2
    assert plan.cost_rad == pytest.approx(math.radians(20 + 30))


def test_high_front_to_back_cannot_go_straight_and_passes_over_the_top_folded(frc):
    """Front high node to back: the straight joint-space move would lift the forearm
    through the height limit; the plan folds the elbow and passes over the top under it."""
    goals = presets(frc)
    start = frc.plan([math.pi / 2, -math.pi / 2], goals['high_score']).waypoints_rad[-1]
    plan = frc.plan(start, goals['back_score'])
    goal = plan.waypoints_rad[-1]
    assert not frc.forbidden.segment_is_free(start, goal, CHECK_STEP_RAD)
    blocked = [frc.forbidden.why_forbidden(start + t * (goal - start))
               for t in np.linspace(0.0, 1.0, 101)]
    assert any(reason and 'height_limit' in reason for reason in blocked)
    assert_free_path(frc, plan, start)
    assert len(plan.waypoints_rad) >= 3
    np.testing.assert_allclose(frc.kinematics.forward(goal), goals['back_score'], atol=1e-9)
    shoulder = plan.waypoints_rad[:, 0]
    assert shoulder.min() < math.pi / 2 < shoulder.max()              # over the top
    height_limit = next(r for r in frc.arm.world.regions if r.name == 'height_limit')
    assert highest_point_m(frc, plan.waypoints_rad) < height_limit.y_min
    # and it costs more than the blocked straight move, as a detour must
    assert plan.cost_rad > np.abs(goal - start).sum() + 1e-6


def test_every_preset_is_planned_from_the_start_pose_and_from_each_other(frc):
    goals = presets(frc)
    planned_around = 0
    for name, point in goals.items():
        first = frc.plan([math.pi / 2, -math.pi / 2], point)
        assert_free_path(frc, first, [math.pi / 2, -math.pi / 2])
        for other, target in goals.items():
            plan = frc.plan(first.waypoints_rad[-1], target)
            assert_free_path(frc, plan, first.waypoints_rad[-1])
            np.testing.assert_allclose(frc.kinematics.forward(plan.waypoints_rad[-1]), target,
                                       atol=1e-9)
            planned_around += len(plan.waypoints_rad) > 2
    assert planned_around >= 4          # on this robot planning visibly matters


class CountingPlanner:
    """The planner, counting the searches asked of it."""

    def __init__(self, planner):
        self.planner, self.searches = planner, 0

    def plan(self, *args):
        self.searches += 1
        return self.planner.plan(*args)

    def plan_to_configurations(self, *args):
        self.searches += 1
        return self.planner.plan_to_configurations(*args)


def test_a_goal_from_preset_to_preset_is_answered_without_a_search_as_a_search_would(frc):
    ranking = BranchRanking(frc.arm)
    counting = CountingPlanner(frc)
    answers = PresetAnswers(ranking, counting)
    while answers.pending:
        answers.prepare_next()
    counting.searches = 0
    goals = presets(frc)
    start = (math.pi / 2, -math.pi / 2)
    first = answers.plan(start, goals['stow'])           # not from a preset: searched
    assert counting.searches == 1
    start = first.waypoints_rad[-1]
    for name, point in [*goals.items(), *goals.items()]:
        if math.dist(frc.kinematics.forward(start), point) < 1e-6:
            continue
        plan = answers.plan(start, point)
        # the next start as the planner node gets it: the last answer's end, as a pose
        x, y, yaw = poses_from_waypoints(frc.kinematics, plan.waypoints_rad)[-1]
        start = frc.kinematics.configuration_from_pose(x, y, yaw)
        fresh = ranking.plan(frc, plan.waypoints_rad[0], point)
        np.testing.assert_array_equal(plan.waypoints_rad, fresh.waypoints_rad)
    assert counting.searches == 1, 'every later goal went from a preset to a preset'
    off = np.array(first.waypoints_rad[-1]) + 0.01          # near a preset, not on it
    plan = answers.plan(off, goals['high_score'])
    assert counting.searches == 2
    assert_free_path(frc, plan, off)


def test_the_cheaper_elbow_branch_wins(frc):
    start = np.array([math.radians(100), math.radians(-120)])
    point = (1.1, 0.6)
    branches = frc.kinematics.inverse(*point)
    assert all(frc.forbidden.is_free(np.array(q)) for q in branches)
    costs = [frc.plan_to_configuration(start, q).cost_rad for q in branches]
    plan = frc.plan(start, point)
    assert_free_path(frc, plan, start)
    assert plan.cost_rad <= min(costs) + 2 * frc.config.grid_resolution_rad
    cheaper = branches[int(np.argmin(costs))]
    np.testing.assert_allclose(plan.waypoints_rad[-1], cheaper, atol=1e-9)


@pytest.mark.parametrize('point, part', [((0.60, -0.50), 'intake'),
                                         ((-0.45, -0.65), 'back_bumper')])
def test_a_goal_inside_the_robot_body_is_refused_on_both_branches(frc, point, part):
    plan = frc.plan([math.pi / 2, -math.pi / 2], point)
    assert not plan.ok
    assert plan.waypoints_rad.shape == (0, 2) and plan.cost_rad == math.inf
    assert plan.why == NoPlan.FORBIDDEN_GOAL
    assert f'"{part}"' in plan.reason                   # one branch reaches into it ...
    assert 'past its limits' in plan.reason             # ... the other is past a stop


def test_a_goal_above_the_height_limit_says_so(frc):
    plan = frc.plan([math.pi / 2, -math.pi / 2], (0.3, 1.4))
    assert not plan.ok and '"height_limit"' in plan.reason


def test_an_unreachable_goal_gives_the_reach(frc):
    plan = frc.plan([math.pi / 2, -math.pi / 2], (2.5, 0.0))
    assert not plan.ok
    assert plan.why == NoPlan.OUT_OF_REACH and '0.200 to 1.800 m' in plan.reason   # the reach
    assert not frc.plan([math.pi / 2, -math.pi / 2], (0.05, 0.0)).ok     # inside the hole


def test_non_finite_input_is_refused_with_a_reason(frc):
    for plan in (frc.plan([math.nan, 0.0], (1.0, 0.5)),
                 frc.plan([math.pi / 2, -math.pi / 2], (math.inf, 0.5)),
                 frc.plan_to_configuration([math.pi / 2, -math.pi / 2], [0.0, math.nan])):
        assert not plan.ok and plan.why == NoPlan.BAD_INPUT
        assert plan.waypoints_rad.shape == (0, 2)


def test_no_connection_when_a_pole_splits_front_from_back(arm):
    """A pole above the shoulder blocks the upper arm near vertical; with no way round
    through the shoulder's stops, front and back are separate pieces of free space."""
    world = dataclasses.replace(arm.world, regions=arm.world.regions + (
        Rectangle('pole', -0.05, 0.5, 0.05, 10.0),))
    planner = Planner(dataclasses.replace(arm, world=world), PlannerConfig(0.02))
    plan = planner.plan([math.radians(30), math.radians(20)], (-1.0, 0.5))
    assert not plan.ok
    assert plan.why == NoPlan.SEPARATED, plan.reason


def test_a_start_inside_the_intake_takes_the_shortest_way_out_first(frc):
    """The arm was pushed with its forearm into the intake: the path leaves by the least
    joint travel (checked against a fine brute-force search), then goes on, free."""
    start = np.array(frc.kinematics.inverse(0.60, -0.52)[1])            # tool in the intake
    assert 'intake' in frc.forbidden.why_forbidden(start)
    plan = frc.plan(start, presets(frc)['mid_score'])
    assert plan.ok, plan.reason
    path = plan.waypoints_rad
    np.testing.assert_allclose(path[0], start)
    assert frc.forbidden.is_free(path[1])
    assert frc.forbidden.path_is_free(path[1:], CHECK_STEP_RAD)
    way_out = np.abs(path[1] - path[0]).sum()
    # Brute force: the nearest free configuration on a 0.2° lattice around the start.
    lattice_step = math.radians(0.2)
    offsets = np.arange(-150, 151) * lattice_step
    lattice = start + np.stack(np.meshgrid(offsets, offsets, indexing='ij'), -1).reshape(-1, 2)
    free = frc.forbidden.is_free(lattice)
    nearest = np.abs(lattice[free] - start).sum(axis=1).min()
    assert nearest > math.radians(2)                           # it really is pushed in
    assert way_out <= nearest + 2 * frc.config.grid_resolution_rad
    assert way_out >= nearest - 2 * lattice_step


def test_a_start_inside_the_clearance_steps_out_then_goes_straight_when_it_can(planner):
    """The upper arm stretched back, within the clearance of the floor (3/4 of it): free,
    but within the clearance. The shortest path keeps the clearance once out of it: the
    nearest way out, then the straight segment to the goal, which costs the least there is."""
    clearance = planner.arm.world.clearance_rad
    start = np.array([math.pi - 0.75 * clearance, math.radians(-74.04)])
    goal = np.radians([39.4, -64.1])
    assert planner.forbidden.is_free(start)
    assert not planner.forbidden.clear_by(start, clearance)
    plan = planner.plan_to_configuration(start, goal)
    assert_free_path(planner, plan, start, goal)
    out, rest = plan.waypoints_rad[1], plan.waypoints_rad[1:]
    assert np.abs(out - start).sum() <= 2 * planner.config.grid_resolution_rad
    assert planner.forbidden.clear_by(rest, clearance).all()
    assert plan.cost_rad == pytest.approx(np.abs(out - start).sum() + np.abs(goal - out).sum())


def test_a_start_past_a_hard_stop_comes_back_inside(frc):
    start = [frc.forbidden.limits[0, 0] - 0.02, 1.2]     # shoulder 1.1° past its low stop
    assert 'past its limits' in frc.forbidden.why_forbidden(np.array(start))
    plan = frc.plan(start, (0.5, 1.0))
    assert plan.ok, plan.reason
    assert frc.forbidden.path_is_free(plan.waypoints_rad[1:], CHECK_STEP_RAD)
    assert np.abs(plan.waypoints_rad[1] - plan.waypoints_rad[0]).sum() < math.radians(3)


def test_plan_to_a_wrapped_goal_takes_it_into_the_joint_travel(frc):
    """Shoulder -170° is shoulder 190° for a joint that travels -20° to 200°."""
    start = np.radians([150.0, -90.0])
    plan = frc.plan_to_configuration(start, np.radians([-170.0, -90.0]))
    assert_free_path(frc, plan, start, np.radians([190.0, -90.0]))


# Optimality against brute force on small grids


def test_paths_keep_the_clearance_where_one_can(frc, planner):
    """Between presets (each held within the clearance), and from low near the floor to full
    extension low, the whole path keeps the clearance on both joints: an overshoot of up to
    the clearance then stays out of forbidden space."""
    for planner, moves in (
            (frc, [(a, b) for a in presets(frc).values() for b in presets(frc).values()]),
            (planner, [((0.6, 0.1), (1.75, 0.1)), ((-1.5, 0.15), (1.5, 0.15))])):
        clear = planner.clear.forbidden
        for start_xy, goal_xy in moves:
            start = next(q for q in planner.kinematics.inverse(*start_xy)
                         if clear.is_free(planner._in_travel(q)))
            plan = planner.plan(start, goal_xy)
            assert_free_path(planner, plan)
            assert clear.path_is_free(plan.waypoints_rad, CHECK_STEP_RAD), (start_xy, goal_xy)


def test_a_goal_inside_the_clearance_is_still_planned_to_in_free_space(planner):
    """No path keeps the clearance to a goal within it: the free one is the answer."""
    planner = planner
    goal = np.array([planner.arm.world.clearance_rad / 2, math.radians(5.0)])   # near the floor
    assert planner.forbidden.is_free(goal) and not planner.clear.forbidden.is_free(goal)
    plan = planner.plan_to_configuration([math.radians(90), math.radians(-90)], goal)
    assert_free_path(planner, plan, goal=goal)
