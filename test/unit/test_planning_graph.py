"""The grid search against brute force (distances, lazy edge checks, costs), property tests of
free paths, the poses a path is sent as, and the clearance from forbidden space."""

import dataclasses
import math

from hypothesis import event, given, HealthCheck, settings, strategies as st
import numpy as np
from planning_checks import assert_free_path, CHECK_STEP_RAD, FRC_FILE, presets
import pytest

from arm_control import config
from arm_control.config import PlannerConfig
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.graph import ConfigurationGrid, DIRECTIONS
from arm_control.planning.plan import NoPlan, Plan, travel_rad
from arm_control.planning.planner import Planner
from arm_control.planning.poses import poses_from_waypoints, waypoints_from_poses


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
        assert plan.why in (NoPlan.NO_CONNECTION, NoPlan.SEPARATED), plan.reason
        return
    event('straight' if len(plan.waypoints_rad) == 2 else 'around')
    assert_free_path(frc, plan, start_q, goal_q)
    assert np.all(frc.forbidden.within_limits(plan.waypoints_rad))
    assert plan.cost_rad >= np.abs(goal_q - start_q).sum() - 1e-9


# Poses and waypoints


def test_waypoints_to_poses_and_back_is_the_identity(frc, planner):
    goals = presets(frc)
    start = frc.plan([math.pi / 2, -math.pi / 2], goals['high_score']).waypoints_rad[-1]
    plan = frc.plan(start, goals['back_score'])
    rng = np.random.default_rng(2)
    limits = planner.forbidden.limits
    random_path = rng.uniform(limits[:, 0], limits[:, 1], (50, 2))
    crossing = np.radians([[170.0, 165.0], [190.0, -170.0], [199.0, 171.0], [-19.0, -171.0]])
    for planner, path in ((frc, plan.waypoints_rad), (planner, random_path),
                          (planner, crossing)):
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
    failure = Plan.failure('because', NoPlan.NO_CONNECTION)
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


def test_a_goal_just_above_the_floor_is_still_planned(planner):
    """1 cm above the floor, inside the clearance a hold keeps: planned all the same."""
    plan = planner.plan((1.5, 1.0), (1.5, 0.01))
    assert_free_path(planner, plan)
    assert planner.kinematics.forward(plan.waypoints_rad[-1]) == pytest.approx(
        (1.5, 0.01), abs=1e-9)
