"""Forbidden space's cells proved free or forbidden: a configuration in one is so by the exact
check, and along paths most configurations are found in one."""

from pathlib import Path

import numpy as np
import pytest

from arm_control import config
from arm_control.model.world import ForbiddenSpace, free_cells, FreeCells

FRC_ROBOT = str(Path(__file__).resolve().parents[2] / 'config' / 'frc_robot.yaml')


@pytest.mark.parametrize('files', [(), (FRC_ROBOT,)])
def test_every_configuration_in_a_cell_proved_free_or_forbidden_is_so(files):
    arm = config.load('sim', *files)[0]
    space = ForbiddenSpace(arm)
    rng = np.random.default_rng(11)
    low, high = space.limits[:, 0], space.limits[:, 1]
    q = rng.uniform(low - 0.05, high + 0.05, (200_000, 2))
    free, forbidden = free_cells(arm).lookup(q)
    exact = space.within_limits(q) & ~space.collides(q)
    assert not np.any(free & ~exact) and not np.any(forbidden & exact)
    # ... and the cells pay: most free configurations are found in a free one, and most
    # forbidden ones within the joints' travel in a forbidden one.
    travel = np.all((q >= low) & (q <= high), axis=-1)
    assert np.count_nonzero(free) > 0.8 * np.count_nonzero(exact)
    assert np.count_nonzero(forbidden) > 0.9 * np.count_nonzero(travel & ~exact)


def test_checks_through_the_cells_give_the_exact_answer(arm):
    space = ForbiddenSpace(arm)
    rng = np.random.default_rng(12)
    q = rng.uniform(space.limits[:, 0], space.limits[:, 1], (5000, 2))
    np.testing.assert_array_equal(space.is_free(q),
                                  space.within_limits(q) & ~space.collides(q))


@pytest.mark.parametrize('files', [(), (FRC_ROBOT,)])
def test_a_configuration_in_a_cell_proved_clear_has_its_whole_margin_free(files):
    """Cells proved with a margin: every configuration within the margin of one in such a
    cell (on both joints) is free by the exact check."""
    arm = config.load('sim', *files)[0]
    space, margin = ForbiddenSpace(arm), arm.world.clearance_rad
    rng = np.random.default_rng(13)
    q = rng.uniform(space.limits[:, 0] - 0.05, space.limits[:, 1] + 0.05, (50_000, 2))
    proved, _ = free_cells(arm, margin).lookup(q)
    nearby = q[proved][:, None, :] + rng.uniform(-margin, margin, (np.count_nonzero(proved),
                                                                   8, 2))
    nearby = nearby.reshape(-1, 2)
    assert np.all(space.within_limits(nearby) & ~space.collides(nearby))
    # ... and the cells pay: most configurations clear by the margin (at the corners and
    # sides of its square) are found in one.
    square = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1],
                       [0, 0]]) * margin
    corners = q[:, None] + square
    clear = np.all(space.within_limits(corners) & ~space.collides(corners), axis=-1)
    assert np.count_nonzero(proved) > 0.75 * np.count_nonzero(clear)


def test_clear_checks_through_the_cells_give_the_sampled_answer(arm):
    """ForbiddenSpace with a margin answers as its nine-point check does, cells or not."""
    space = ForbiddenSpace(arm, arm.world.clearance_rad)
    rng = np.random.default_rng(14)
    q = rng.uniform(space.limits[:, 0], space.limits[:, 1], (5000, 2))
    square = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1],
                       [0, 0]]) * space.margin_rad
    plain = ForbiddenSpace(arm)
    sampled = np.all(plain.within_limits(q[:, None] + square)
                     & ~plain.collides(q[:, None] + square), axis=-1)
    np.testing.assert_array_equal(space.is_free(q), sampled)


def test_cells_proved_ahead_a_few_tiles_at_a_time_are_those_the_checks_would_prove(arm):
    """Proving every cell ahead (as the planner does while idle, in slices) leaves the same
    verdicts as proving each where a check first meets it."""
    margin = arm.world.clearance_rad
    ahead = [FreeCells(arm), FreeCells(arm, margin)]
    ahead[1].base = ahead[0]
    slices = 0
    while not all(cells.prove_some(40) for cells in ahead):
        slices += 1
    assert slices > 1 and all(cells.tiles_done.all() for cells in ahead)
    rng = np.random.default_rng(15)
    space = ForbiddenSpace(arm)
    q = rng.uniform(space.limits[:, 0], space.limits[:, 1], (20_000, 2))
    for proved, met in zip(ahead, (free_cells(arm), free_cells(arm, margin))):
        for a, b in zip(proved.lookup(q), met.lookup(q)):
            np.testing.assert_array_equal(a, b)
