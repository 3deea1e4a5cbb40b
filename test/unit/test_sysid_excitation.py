"""The excitation is checked before it moves anything: clear of forbidden space, within the
current, shrunk where it must be; and its tracking stops when the arm strays."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from arm_control import parameters
from arm_control.config import Rectangle
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.world import ForbiddenSpace
from arm_control.sysid.excitation import (CHECK_STEP_S, design_excitation, DYNAMIC,
                                          ExcitationRun, feedforward, per_motor_current_a)
from arm_control.sysid.settings import SysIdConfig

CONFIG = Path(__file__).resolve().parents[2] / 'config'


@pytest.fixture(scope='module')
def settings():
    return SysIdConfig.from_parameters(
        parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sysid'))


def sampled(excitation, step_s=CHECK_STEP_S / 2):
    """Every 2.5 ms, twice as fine as the design checks."""
    return excitation.sample(np.arange(0.0, excitation.duration_s, step_s))


def assert_safe(arm, settings, excitation, share):
    q, qd, qdd = sampled(excitation)
    # The margin is checked at the corners of a square; half of it must hold everywhere.
    assert np.all(ForbiddenSpace(arm, settings.margin_rad / 2).is_free(q))
    dynamics = ArmDynamics(arm)
    voltage = feedforward(dynamics, q, qd, qdd)
    for joint in range(2):
        current = per_motor_current_a(dynamics, arm, joint, voltage[:, joint], qd[:, joint])
        assert np.max(np.abs(current)) <= share * settings.max_current_a * 1.01
    assert np.max(np.abs(voltage)) < arm.battery.nominal_voltage


def test_the_default_excitation_is_safe_and_under_a_minute(arm, settings):
    start = np.array(settings.centre_rad) + [0.05, -0.05]
    stage_one, _ = design_excitation(arm, settings, start, kinds=('quasistatic', 'multi-sine'))
    stage_two, _ = design_excitation(arm, settings, kinds=(DYNAMIC,),
                                     current_share=settings.stage_two_current_share)
    assert_safe(arm, settings, stage_one, settings.stage_one_current_share)
    assert_safe(arm, settings, stage_two, settings.stage_two_current_share)
    assert [p.name for p in stage_one.parts] == [
        'to the centre', 'shoulder quasistatic', 'elbow quasistatic', 'coupled multi-sine']
    assert stage_one.duration_s + stage_two.duration_s < 60.0
    # Every part starts and ends at rest at the centre (the first from where the arm is).
    q, qd, _ = stage_one.sample([0.0, stage_one.duration_s])
    assert np.allclose(q, [start, settings.centre_rad]) and np.allclose(qd, 0.0)


def test_parts_shrink_to_stay_clear_of_an_obstacle(arm, settings):
    """A shelf just under the tool: the moves that would reach it get smaller."""
    shelf = Rectangle('shelf', 0.9, 0.45, 2.0, 0.5)
    crowded = dataclasses.replace(arm, world=dataclasses.replace(
        arm.world, regions=arm.world.regions + (shelf,)))
    excitation, notes = design_excitation(crowded, settings)
    open_air, before = design_excitation(arm, settings)
    shrunk = set(notes) - set(before)
    assert any('coupled multi-sine: at' in note for note in shrunk), notes
    assert_safe(crowded, settings, excitation, settings.stage_one_current_share)
    assert excitation.duration_s < open_air.duration_s


def test_a_forbidden_centre_is_refused_before_anything_moves(arm, settings):
    low = dataclasses.replace(settings, centre_rad=(0.05, -0.3))    # the forearm in the floor
    with pytest.raises(ValueError, match='not clear of forbidden space'):
        design_excitation(arm, low)
    # From under the floor, the way to the centre crosses forbidden space.
    with pytest.raises(ValueError, match='crosses forbidden space'):
        design_excitation(arm, settings, start_rad=(-0.3, -0.2))


def test_a_motor_never_gets_more_than_max_current(arm, settings):
    excitation, _ = design_excitation(arm, settings)
    run = ExcitationRun(arm, settings, excitation)
    dynamics = ArmDynamics(arm)
    rng = np.random.default_rng(1)
    for k in range(200):
        now = 0.02 * k
        q_ref = excitation.sample(now)[0][0]
        # Readings up to 10 deg off the plan and fast: the PD asks for a lot.
        position = q_ref + rng.uniform(-0.17, 0.17, 2)
        velocity = rng.uniform(-2.0, 2.0, 2)
        voltage = run.command(now, position, velocity)
        for joint in range(2):
            current = per_motor_current_a(dynamics, arm, joint, voltage[joint], velocity[joint])
            assert abs(current) <= settings.max_current_a + 1e-9
    assert run.current_clamped > 0
    assert run.stopped is None


def test_an_arm_that_strays_stops_the_excitation_and_glides_back(arm, settings):
    excitation, _ = design_excitation(arm, settings)
    run = ExcitationRun(arm, settings, excitation)
    centre = np.array(settings.centre_rad)
    run.command(0.0, centre, np.zeros(2))
    astray = centre + [0.0, settings.abort_tracking_error_rad + 0.05]
    run.command(0.02, astray, np.zeros(2))
    assert run.stopped is not None and 'elbow strayed' in run.stopped
    assert np.allclose(run.reference[0], astray)            # the glide starts where it is
    for now in np.arange(0.04, 10.0, 0.02):
        run.command(now, centre, np.zeros(2))
    assert np.allclose(run.reference[0], centre) and run.finished(10.0)
    assert math.isclose(run.reference[1][1], 0.0, abs_tol=1e-12)
