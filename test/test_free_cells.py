"""Forbidden space's cells proved free: a configuration in one is free by the exact check,
and along paths most free configurations are found in one."""

from pathlib import Path

import numpy as np
import pytest

from arm_control import config
from arm_control.model.world import ForbiddenSpace, free_cells

FRC_ROBOT = str(Path(__file__).resolve().parents[1] / 'config' / 'frc_robot.yaml')


@pytest.mark.parametrize('files', [(), (FRC_ROBOT,)])
def test_every_configuration_in_a_cell_proved_free_is_free(files):
    arm = config.load('sim', *files)[0]
    space = ForbiddenSpace(arm)
    rng = np.random.default_rng(11)
    low, high = space.limits[:, 0], space.limits[:, 1]
    q = rng.uniform(low - 0.05, high + 0.05, (200_000, 2))
    proved = free_cells(arm).contain(q)
    exact = space.within_limits(q) & ~space.collides(q)
    assert not np.any(proved & ~exact)
    # ... and the cells pay: most free configurations are found in one.
    assert np.count_nonzero(proved) > 0.8 * np.count_nonzero(exact)


def test_checks_through_the_cells_give_the_exact_answer(arm):
    space = ForbiddenSpace(arm)
    rng = np.random.default_rng(12)
    q = rng.uniform(space.limits[:, 0], space.limits[:, 1], (5000, 2))
    np.testing.assert_array_equal(space.is_free(q),
                                  space.within_limits(q) & ~space.collides(q))
