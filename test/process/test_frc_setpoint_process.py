"""The bridge in mode ``setpoint``, end to end: the controller's setpoint and the model's
feedforward go to the robot, whose own loop (frc_robot_sim's PD) closes it."""

from frc_rig import GOALS, reach, running_rig
import pytest


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    yield from running_rig(tmp_path_factory, 'setpoint')


def test_the_robot_s_own_loop_reaches_the_goals_on_the_controller_s_setpoints(rig):
    reach(rig, GOALS)
    rig.watch.poll()
    assert len(rig.watch.samples['profiles']) > 25, 'the robot was sent no setpoints'
    # Voltages went out only as the "commanding nothing" 0 V, never the controller's own.
    assert all(v == [0.0, 0.0] for _, v in rig.watch.samples['commands'])
