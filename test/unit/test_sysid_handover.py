"""The hand-over after identification: another node is told by the commands it sends, the arm
is held where the plan ended, and lowered onto a rest only along a free way."""

from pathlib import Path

import numpy as np
import pytest

from arm_control import parameters
from arm_control.model.plant import ArmPlant
from arm_control.sysid.handover import HandOver, lowering, REMEMBERED, TAKE_OVER_COMMANDS
from arm_control.sysid.session import Session
from arm_control.sysid.settings import SysIdConfig

CONFIG = Path(__file__).resolve().parents[2] / 'config'


@pytest.fixture(scope='module')
def settings():
    return SysIdConfig.from_parameters(
        parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sysid'))


def test_only_another_nodes_commands_take_the_arm_over():
    handover = HandOver()
    for k in range(2 * REMEMBERED):                 # its own commands come back: not others
        handover.sent([0.1 * k, -0.2 * k])
        handover.heard([0.1 * k, -0.2 * k])
    assert not handover.taken
    for k in range(TAKE_OVER_COMMANDS - 1):
        handover.heard([1.0 + k, 2.0])
    assert not handover.taken
    handover.heard([5.0, 5.0])
    assert handover.taken


def test_the_hold_times_out_only_when_asked():
    handover = HandOver()
    handover.hold_from(10.0)
    assert not handover.expired(1e6, 0.0)
    assert not handover.expired(39.0, 30.0) and handover.expired(40.0, 30.0)


def test_the_held_arm_stays_where_the_plan_ended(arm, settings):
    """On the true arm, held by the session after its excitation: 5 s, under 0.5 deg."""
    centre = np.array(settings.centre_rad)
    plant = ArmPlant(arm, centre, 0.001, 0)
    session = Session(arm, settings, centre)
    session.hold(arm, centre)
    for _ in range(250):
        reading = plant.read()
        plant.set_voltage(session.command(plant.time_s, reading.potentiometer_rad,
                                          reading.velocity_rad_s))
        plant.advance(0.02)
    assert np.max(np.abs(np.array(plant.state[:2]) - centre)) < np.radians(0.5)


def test_lowering_goes_only_along_a_free_way(arm, settings):
    centre = np.array(settings.centre_rad)
    rest = centre + [-0.6, 0.4]
    motion = lowering(arm, centre, rest)
    q, qd, _ = motion.sample(np.array([0.0, motion.duration_s]))
    assert np.allclose(q[0], centre) and np.allclose(q[1], rest) and np.allclose(qd, 0.0)
    with pytest.raises(ValueError, match='forbidden'):
        lowering(arm, centre, (-0.3, -0.2))          # into the floor
