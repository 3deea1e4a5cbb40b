"""Planning in configuration space: known answers, optimality by brute force, free paths."""

import dataclasses
import math
from pathlib import Path

from hypothesis import event, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from arm_control import config
from arm_control.config import PlannerConfig, Rectangle
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.graph import ConfigurationGrid, DIRECTIONS
from arm_control.planning.planner import (Plan, Planner, poses_from_waypoints, travel_rad,
                                          waypoints_from_poses)

FRC_FILE = Path(__file__).resolve().parents[1] / 'config' / 'frc_robot.yaml'
CHECK_STEP_RAD = math.radians(0.1)          # every returned path is checked at this step


@pytest.fixture(scope='module')
def frc():
    """The competition robot's arm and a planner on it at the file's resolution (1°)."""
    arm, planner_config = config.load('planner', FRC_FILE)
    return Planner(arm, planner_config)


@pytest.fixture(scope='module')
def seed_planner(arm):
    return Planner(arm, config.load('planner')[1])


def presets(planner):
    return {name: (x, y) for name, x, y in planner.arm.presets}


def assert_free_path(planner, plan, start=None, goal=None):
    """The plan's path is free at 0.1°, inside the joint travel, from start to goal."""
    assert plan.ok, plan.reason
    path = plan.waypoints_rad
    assert path.ndim == 2 and path.shape[1] == 2 and len(path) >= 2
    assert planner.forbidden.path_is_free(path, CHECK_STEP_RAD)
    assert plan.cost_rad == pytest.approx(travel_rad(path))
    if start is not None:
        np.testing.assert_allclose(path[0], start, atol=1e-12)
    if goal is not None:
        np.testing.assert_allclose(path[-1], goal, atol=1e-12)


def highest_point_m(planner, path, step_rad=CHECK_STEP_RAD):
    """The highest y any point of the arm reaches along a joint-space path."""
    samples = []
    for a, b in zip(path[:-1], path[1:]):
        count = int(np.ceil(np.max(np.abs(b - a)) / step_rad)) + 2
        samples.append(a + np.linspace(0.0, 1.0, count)[:, None] * (b - a))
    q = np.concatenate(samples)
    kinematics = planner.kinematics
    y_elbow = kinematics.upper_m * np.sin(q[:, 0])
    y_tool = y_elbow + kinematics.fore_m * np.sin(q[:, 0] + q[:, 1])
    return float(max(y_elbow.max(), y_tool.max()))


# The grid


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
    assert 'forbidden on both elbow branches' in plan.reason
    assert f'"{part}"' in plan.reason                   # one branch reaches into it ...
    assert 'past its limits' in plan.reason             # ... the other is past a stop


def test_a_goal_above_the_height_limit_says_so(frc):
    plan = frc.plan([math.pi / 2, -math.pi / 2], (0.3, 1.4))
    assert not plan.ok and '"height_limit"' in plan.reason


def test_an_unreachable_goal_gives_the_reach(frc):
    plan = frc.plan([math.pi / 2, -math.pi / 2], (2.5, 0.0))
    assert not plan.ok
    assert 'out of reach' in plan.reason and '0.200 to 1.800 m' in plan.reason
    assert not frc.plan([math.pi / 2, -math.pi / 2], (0.05, 0.0)).ok     # inside the hole


def test_non_finite_input_is_refused_with_a_reason(frc):
    for plan in (frc.plan([math.nan, 0.0], (1.0, 0.5)),
                 frc.plan([math.pi / 2, -math.pi / 2], (math.inf, 0.5)),
                 frc.plan_to_configuration([math.pi / 2, -math.pi / 2], [0.0, math.nan])):
        assert not plan.ok and 'finite' in plan.reason
        assert plan.waypoints_rad.shape == (0, 2)


def test_no_connection_when_a_pole_splits_front_from_back(arm):
    """A pole above the shoulder blocks the upper arm near vertical; with no way round
    through the shoulder's stops, front and back are separate pieces of free space."""
    world = dataclasses.replace(arm.world, regions=arm.world.regions + (
        Rectangle('pole', -0.05, 0.5, 0.05, 10.0),))
    planner = Planner(dataclasses.replace(arm, world=world), PlannerConfig(0.02))
    plan = planner.plan([math.radians(30), math.radians(20)], (-1.0, 0.5))
    assert not plan.ok
    assert plan.reason.startswith('no connection') and 'separates' in plan.reason


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


_EDGES = {}


def brute_force_edges(forbidden, grid, step_rad):
    """The grid's edges rebuilt here from scratch: every pair of 8-neighbour cells, both
    free, joined when the straight segment is free at ``step_rad``; cost |Δθa| + |Δθb|."""
    key = (id(forbidden), grid.resolution_rad, step_rad)
    if key not in _EDGES:
        n_s, n_e = grid.shoulder.count, grid.elbow.count
        centres = np.stack(np.meshgrid(grid.shoulder.centres(), grid.elbow.centres(),
                                       indexing='ij'), -1)
        pairs = [(i * n_e + j, k * n_e + m, centres[i, j], centres[k, m])
                 for i in range(n_s) for j in range(n_e) for d_s, d_e in DIRECTIONS
                 for k, m in [(i + d_s, j + d_e)] if 0 <= k < n_s and 0 <= m < n_e]
        a = np.array([p[2] for p in pairs])
        b = np.array([p[3] for p in pairs])
        count = int(math.ceil(grid.resolution_rad / step_rad)) + 1
        t = np.linspace(0.0, 1.0, count)
        samples = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
        free = np.all(forbidden.is_free(samples), axis=1)
        _EDGES[key] = [(u, v, float(np.abs(qb - qa).sum()))
                       for (u, v, qa, qb), ok in zip(pairs, free) if ok]
    return _EDGES[key]


def brute_force_distances(forbidden, grid, source, step_rad):
    """Bellman–Ford from ``source`` over ``brute_force_edges``: relax every edge until
    nothing changes."""
    edges = brute_force_edges(forbidden, grid, step_rad)
    distance = [math.inf] * grid.node_count
    distance[source] = 0.0
    for _ in range(grid.node_count):
        changed = False
        for u, v, w in edges:
            if distance[u] + w < distance[v] - 1e-12:
                distance[v] = distance[u] + w
                changed = True
        if not changed:
            break
    return np.array(distance)


@pytest.fixture(scope='module')
def frc_forbidden():
    return ForbiddenSpace(config.load('planner', FRC_FILE)[0])


@pytest.mark.parametrize('world', ['seed', 'frc'])
def test_grid_distances_equal_brute_force(arm, frc_forbidden, world):
    forbidden = frc_forbidden if world == 'frc' else ForbiddenSpace(arm)
    rng = np.random.default_rng(5)
    for resolution in (0.35, 0.25):
        for method in ('scipy', 'heapq'):
            grid = ConfigurationGrid(forbidden, resolution, 0.01)
            free_nodes = np.flatnonzero(grid.free.ravel())
            source = int(rng.choice(free_nodes))
            expected = brute_force_distances(forbidden, grid, source, 0.01)
            grid.check_all_edges()
            distance, _ = grid.shortest_paths([source], [0.0], method)
            reached = np.isfinite(expected)
            np.testing.assert_array_equal(np.isfinite(distance), reached)
            # The tie-break adds at most 1e-5 of each edge's length.
            np.testing.assert_allclose(distance[reached], expected[reached], rtol=2e-5,
                                       atol=1e-9)


def test_lazy_edge_checks_find_the_brute_force_shortest_path(frc_forbidden):
    """Without checking edges up front, each found path is still the true shortest."""
    forbidden = frc_forbidden
    grid = ConfigurationGrid(forbidden, 0.25, 0.01)
    free_nodes = np.flatnonzero(grid.free.ravel())
    rng = np.random.default_rng(11)
    compared = 0
    for source in rng.choice(free_nodes, 3, replace=False):
        expected = brute_force_distances(forbidden, grid, int(source), 0.01)
        for target in rng.choice(free_nodes, 8, replace=False):
            found = grid.shortest_path([int(source)], [0.0], [int(target)], [0.0])
            if not math.isfinite(expected[target]):
                assert found is None
                continue
            nodes, cost, _ = found
            assert cost == pytest.approx(expected[target], rel=2e-5, abs=1e-9)
            assert nodes[0] == source and nodes[-1] == target
            assert forbidden.path_is_free(grid.configurations[nodes], 0.01)
            compared += 1
    assert compared >= 12


def test_plans_cost_no_more_than_the_brute_force_grid_path(frc_forbidden):
    coarse = dataclasses.replace(frc_forbidden.arm, world=dataclasses.replace(
        frc_forbidden.arm.world, check_step_rad=0.01))
    planner = Planner(coarse, PlannerConfig(0.25))
    grid = planner.grid
    rng = np.random.default_rng(3)
    free_nodes = np.flatnonzero(grid.free.ravel())
    source = int(rng.choice(free_nodes))
    expected = brute_force_distances(planner.forbidden, grid, source, 0.01)
    for target in rng.choice(free_nodes[np.isfinite(expected[free_nodes])], 10):
        start, goal = grid.configurations[source], grid.configurations[target]
        plan = planner.plan_to_configuration(start, goal)
        assert plan.ok, plan.reason
        assert planner.forbidden.path_is_free(plan.waypoints_rad, 0.01)
        # (the tie-break may trade up to 1e-5 of the length for a straighter path)
        assert np.abs(goal - start).sum() - 1e-9 <= plan.cost_rad
        assert plan.cost_rad <= expected[target] * (1 + 2e-5) + 1e-9


# Property: every returned path is free


fraction = st.floats(0.0, 1.0, allow_nan=False)


@settings(max_examples=60, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(start=st.tuples(fraction, fraction), radius_m=st.floats(0.25, 1.75),
       bearing_rad=st.floats(-0.6, math.pi + 0.6))
def test_every_returned_path_is_free_at_a_tenth_of_a_degree(frc, start, radius_m, bearing_rad):
    """Random starts anywhere in the joint travel (some pushed into forbidden space) and
    random reachable goal points, mostly above the robot: a plan, or a reason; a plan's
    path is free."""
    goal = (radius_m * math.cos(bearing_rad), radius_m * math.sin(bearing_rad))
    (s_low, s_high), (e_low, e_high) = frc.forbidden.limits
    start_q = np.array([s_low + start[0] * (s_high - s_low), e_low + start[1] * (e_high - e_low)])
    plan = frc.plan(start_q, goal)
    if not plan.ok:
        event('no plan')
        assert plan.reason and plan.waypoints_rad.shape == (0, 2)
        assert plan.cost_rad == math.inf
        return
    path = plan.waypoints_rad
    event('way out first' if not frc.forbidden.is_free(start_q)
          else 'straight' if len(path) == 2 else 'around')
    np.testing.assert_allclose(path[0], start_q, atol=1e-12)
    np.testing.assert_allclose(frc.kinematics.forward(path[-1]), goal, atol=1e-9)
    free_from = 0 if frc.forbidden.is_free(start_q) else 1     # the way out is not free
    assert frc.forbidden.path_is_free(path[free_from:], CHECK_STEP_RAD)
    assert np.all(frc.forbidden.within_limits(path[1:]))
    assert plan.cost_rad == pytest.approx(travel_rad(path))


@settings(max_examples=40, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(start=st.tuples(fraction, fraction), goal=st.tuples(fraction, fraction))
def test_paths_between_free_configurations_are_free(frc, start, goal):
    """Random free starts and goals (drawn among the free grid cells, moved off-grid by
    up to half a cell): a plan or 'no connection'; a plan's path is free."""
    free = frc.grid.configurations[frc.grid.free.ravel()]
    half_cell = 0.5 * frc.config.grid_resolution_rad

    def pick(draw):
        q = free[min(int(draw[0] * len(free)), len(free) - 1)]
        return q + half_cell * (2 * draw[1] - 1) * np.array([1.0, -0.5])

    start_q, goal_q = pick(start), pick(goal)
    if not (frc.forbidden.is_free(start_q) and frc.forbidden.is_free(goal_q)):
        event('moved into forbidden space')
        return
    plan = frc.plan_to_configuration(start_q, goal_q)
    if not plan.ok:
        event('no plan')
        assert plan.reason.startswith('no connection')
        return
    event('straight' if len(plan.waypoints_rad) == 2 else 'around')
    assert_free_path(frc, plan, start_q, goal_q)
    assert np.all(frc.forbidden.within_limits(plan.waypoints_rad))
    assert plan.cost_rad >= np.abs(goal_q - start_q).sum() - 1e-9


# Poses and waypoints


def test_waypoints_to_poses_and_back_is_the_identity(frc, seed_planner):
    goals = presets(frc)
    start = frc.plan([math.pi / 2, -math.pi / 2], goals['high_score']).waypoints_rad[-1]
    plan = frc.plan(start, goals['back_score'])
    rng = np.random.default_rng(2)
    limits = seed_planner.forbidden.limits
    random_path = rng.uniform(limits[:, 0], limits[:, 1], (50, 2))
    crossing = np.radians([[170.0, 165.0], [190.0, -170.0], [199.0, 171.0], [-19.0, -171.0]])
    for planner, path in ((frc, plan.waypoints_rad), (seed_planner, random_path),
                          (seed_planner, crossing)):
        poses = poses_from_waypoints(planner.kinematics, path)
        assert all(-math.pi <= yaw < math.pi for _, _, yaw in poses)
        back = waypoints_from_poses(planner.kinematics, poses, path[0], planner.forbidden)
        np.testing.assert_allclose(back, path, atol=1e-9)


def test_poses_unwrap_near_the_start_when_a_joint_has_more_than_a_turn(arm):
    wide = dataclasses.replace(arm.elbow, min_angle_rad=-4.0, max_angle_rad=4.0)
    forbidden = ForbiddenSpace(dataclasses.replace(arm, elbow=wide))
    kinematics = Planner(arm, PlannerConfig(0.1)).kinematics
    path = np.array([[1.0, 3.5], [1.0, 3.9], [1.2, 3.0]])       # 3.5 ≡ -2.78, both in travel
    back = waypoints_from_poses(kinematics, poses_from_waypoints(kinematics, path), path[0],
                                forbidden)
    np.testing.assert_allclose(back, path, atol=1e-9)


def test_plan_values():
    failure = Plan.failure('because')
    assert not failure.ok and failure.cost_rad == math.inf
    assert failure.waypoints_rad.shape == (0, 2)
    plan = Plan.through([[0.0, 0.0], [0.1, -0.2], [0.3, -0.2]])
    assert plan.ok and plan.reason == ''
    assert plan.cost_rad == pytest.approx(0.1 + 0.2 + 0.2)
    with pytest.raises(ValueError):
        plan.waypoints_rad[0, 0] = 1.0
    repeated = Plan.through([[0.0, 0.0], [0.0, 0.0], [0.3, -0.2], [0.3, -0.2]])
    np.testing.assert_array_equal(repeated.waypoints_rad, [[0.0, 0.0], [0.3, -0.2]])
    assert Plan.through([[0.1, 0.2], [0.1, 0.2]]).waypoints_rad.shape == (2, 2)


def test_a_start_on_a_grid_cell_gives_no_zero_length_segment(frc):
    grid = frc.grid
    start = grid.configurations[grid.node_of(207, 96)]      # about (187.5°, -75°), back
    goal = np.radians([45.0, -53.0])                          # front, high
    assert not frc.segment_is_free(start, goal)
    plan = frc.plan_to_configuration(start, goal)
    assert_free_path(frc, plan, start, goal)
    assert np.all(np.abs(np.diff(plan.waypoints_rad, axis=0)).sum(axis=1) > 0)


def test_an_edge_through_a_thin_forbidden_sliver_is_found_and_cut(frc_forbidden):
    """Some neighbouring free cells are joined by a segment that grazes forbidden space
    (the tower and the bumpers are thin). The lazy search must never return such an edge:
    from one end to the other it goes round, as far as brute force says."""
    eager = ConfigurationGrid(frc_forbidden, 0.35, 0.01)
    before = eager.indices.copy()
    assert eager.check_all_edges() > 0
    cut = np.flatnonzero(eager.indices != before)
    lazy = ConfigurationGrid(frc_forbidden, 0.35, 0.01)
    for slot in cut:
        a, b = slot // len(DIRECTIONS), int(before[slot])
        expected = brute_force_distances(frc_forbidden, lazy, a, 0.01)[b]
        found = lazy.shortest_path([a], [0.0], [b], [0.0])
        if not math.isfinite(expected):
            assert found is None
            continue
        nodes, cost, _ = found
        assert len(nodes) > 2
        assert cost == pytest.approx(expected, rel=2e-5)
        assert frc_forbidden.path_is_free(lazy.configurations[nodes], 0.01)
    assert lazy.blocked_edges > 0


def test_a_search_leaves_the_graph_layout_alone(frc_forbidden):
    """Edge slots are found by position (node · 8 + direction): scipy must not reorder them
    (the search graph shares its arrays), and each edge costs its joint travel."""
    grid = ConfigurationGrid(frc_forbidden, 0.1, 0.01)
    before = grid.indices.copy()
    source = int(np.flatnonzero(grid.free.ravel())[len(grid.free.ravel()) // 3])
    distance, predecessor = grid.shortest_paths([source], [0.0])
    np.testing.assert_array_equal(grid.indices, before)
    reached = np.flatnonzero(np.isfinite(distance))
    assert len(reached) > 100
    for node in reached[::97]:
        if predecessor[node] == grid.node_count:
            continue
        step = grid.configurations[node] - grid.configurations[predecessor[node]]
        assert np.max(np.abs(step)) == pytest.approx(0.1)
        assert distance[node] - distance[predecessor[node]] == pytest.approx(
            np.abs(step).sum(), rel=2e-5)


# Clearance: where a hold is safe from sensor noise

MARGIN_RAD = math.radians(1.0)


def test_an_arm_lying_on_the_floor_line_is_free_but_not_clear(arm):
    forbidden = ForbiddenSpace(arm)
    on_the_floor = (0.0, 0.5)                   # upper arm along y = 0: touching is allowed
    assert forbidden.is_free(on_the_floor)
    assert not forbidden.clear_by(on_the_floor, MARGIN_RAD)
    assert forbidden.clear_by((0.5, 0.5), MARGIN_RAD)
    np.testing.assert_array_equal(
        forbidden.clear_by(np.array([on_the_floor, (0.5, 0.5)]), MARGIN_RAD), [False, True])


@pytest.mark.parametrize('start, distance_rad', [((0.0, 0.5), MARGIN_RAD),
                                                 ((-0.1, 0.5), 0.1 + MARGIN_RAD)])
def test_the_nearest_clear_configuration_lifts_the_upper_arm(arm, start, distance_rad):
    """Lying on, or 5.7 deg into, the floor with the forearm raised: the nearest clear
    configuration raises the shoulder just past the margin, straight up out of it."""
    forbidden = ForbiddenSpace(arm)
    target = forbidden.nearest_clear(start, MARGIN_RAD, reach_rad=0.35)
    assert target is not None and forbidden.clear_by(target, MARGIN_RAD)
    assert distance_rad - 1e-9 <= np.linalg.norm(target - start) \
        <= distance_rad + MARGIN_RAD / 2
    assert target[0] > start[0]
    samples = start + np.linspace(0.0, 1.0, 200)[:, None] * (target - start)
    free = forbidden.is_free(samples)
    assert np.all(free[np.argmax(free):])           # once out, it stays out


def test_no_clear_configuration_within_reach_is_none(arm):
    assert ForbiddenSpace(arm).nearest_clear((-0.349, 0.5), MARGIN_RAD, reach_rad=0.2) is None


def test_a_goal_just_above_the_floor_is_still_planned(seed_planner):
    """1 cm above the floor, inside the clearance a hold keeps: planned all the same."""
    plan = seed_planner.plan((1.5, 1.0), (1.5, 0.01))
    assert_free_path(seed_planner, plan)
    assert seed_planner.kinematics.forward(plan.waypoints_rad[-1]) == pytest.approx(
        (1.5, 0.01), abs=1e-9)
