"""Shortest-path trees toward the presets: a plan read off one is as short as a search's, free,
and stays exact when an edge on it turns out blocked."""

import math
from pathlib import Path

import numpy as np
import pytest

from arm_control import config
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.graph import ConfigurationGrid, DIRECTIONS
from arm_control.planning.planner import Planner
from arm_control.planning.trees import GoalTrees
from arm_control.plans.goals import GoalValidator

FRC_FILE = Path(__file__).resolve().parents[2] / 'config' / 'frc_robot.yaml'
CHECK_STEP_RAD = math.radians(0.1)


@pytest.fixture(scope='module')
def frc_planners():
    """Two planners on the FRC robot: one searching, one with every preset branch's tree."""
    arm, planner_config = config.load('planner', FRC_FILE)
    searching, prepared = Planner(arm, planner_config), Planner(arm, planner_config)
    validator = GoalValidator(arm)
    goals = [q for _, x, y in arm.presets for q in validator.free_configurations(x, y)]
    assert all(prepared.prepare(q) for q in goals)
    assert not prepared.prepare(goals[0])                  # once is enough
    return searching, prepared, goals


def assert_as_short_as_a_search(searching, prepared, start, goals) -> list:
    """The prepared planner's plans from ``start`` to each goal: found where a search finds
    one, as short, between the same ends, and free. Returns those found."""
    found_plans = []
    for found, read in zip(searching.plan_to_configurations(start, goals),
                           prepared.plan_to_configurations(start, goals)):
        assert found.ok == read.ok, (found.reason, read.reason)
        if not found.ok:
            continue
        assert read.cost_rad == pytest.approx(found.cost_rad, abs=1e-9)
        np.testing.assert_allclose(read.waypoints_rad[[0, -1]], found.waypoints_rad[[0, -1]])
        assert searching.forbidden.path_is_free(read.waypoints_rad, CHECK_STEP_RAD)
        found_plans.append(read)
    return found_plans


def test_a_plan_read_off_a_preset_tree_is_as_short_as_a_search_and_free(frc_planners):
    searching, prepared, goals = frc_planners
    forbidden = searching.forbidden
    rng = np.random.default_rng(21)
    starts = rng.uniform(forbidden.limits[:, 0], forbidden.limits[:, 1], (400, 2))
    starts = starts[forbidden.is_free(starts)][:25]
    for start in starts:
        assert_as_short_as_a_search(searching, prepared, start, goals)


def test_a_tree_meeting_a_blocked_edge_is_built_again_and_stays_exact():
    """On a coarse grid some neighbours' optimistic edges graze thin regions: a tree built
    before they were checked leads through them; reading it finds, cuts and rebuilds, and the
    path it gives is free and as short as the true graph's shortest."""
    forbidden = ForbiddenSpace(config.load('planner', FRC_FILE)[0])
    eager = ConfigurationGrid(forbidden, 0.35, 0.01)
    before = eager.indices.copy()
    assert eager.check_all_edges() > 0
    cut = np.flatnonzero(eager.indices != before)
    lazy = ConfigurationGrid(forbidden, 0.35, 0.01)
    trees = GoalTrees(lazy)
    for slot in cut:
        a, b = slot // len(DIRECTIONS), int(before[slot])
        goal = lazy.configurations[b]
        trees.build(goal, (np.array([b]), np.array([0.0])))
        read = trees.path(goal, np.array([a]), np.array([0.0]))
        true_cost = eager.shortest_path([a], [0.0], [b], [0.0])
        if true_cost is None:
            assert read is None
            continue
        nodes, cost = read
        assert nodes[0] == a and nodes[-1] == b and len(nodes) > 2
        assert cost == pytest.approx(true_cost[1], rel=1e-9)
        assert forbidden.path_is_free(lazy.configurations[nodes], 0.01)
    assert lazy.blocked_edges > 0


def test_a_plan_from_a_preset_read_backwards_off_its_tree_is_as_short_as_a_search(frc_planners):
    """The graph is symmetric: from a preset's branch, the tree toward it gives the shortest
    paths out of it as well."""
    searching, prepared, presets = frc_planners
    forbidden = searching.forbidden
    rng = np.random.default_rng(5)
    goals = rng.uniform(forbidden.limits[:, 0], forbidden.limits[:, 1], (400, 2))
    goals = goals[forbidden.is_free(goals)][:12]
    read = [plan for start in presets
            for plan in assert_as_short_as_a_search(searching, prepared, start, goals)]
    assert any(len(plan.waypoints_rad) > 2 for plan in read)    # not all in straight sight
