"""Through ROS, on the robot's clock: the sim reads its sensors and applies the latest command
only at its loop's instants, and the controller sends profiles. A hold is still, a move
arrives, and the readings are stamped at the loop's instants."""

import math

from arm_rig import ArmRig, assert_never_forbidden, DEG
import numpy as np
import pytest

from arm_control import config
from arm_control.model.kinematics import TwoLinkKinematics

ARM, SIM = config.load('sim')
PERIOD_S = 1.0 / SIM.publish_rate_hz
PHASE_S = 0.013
KINEMATICS = TwoLinkKinematics(ARM.shoulder.length_m, ARM.elbow.length_m)


@pytest.fixture
def rig(domain, probe, tmp_path):
    rig = ArmRig(domain, probe, tmp_path, {'sim': (
        '-p', 'command_timing:=robot_loop', '-p', f'robot_loop_phase_s:={PHASE_S}')})
    rig.start_all()
    try:
        rig.ready()
        yield rig
    finally:
        rig.close()


def test_on_the_robot_loop_a_hold_is_still_and_a_move_arrives(rig):
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
              for _, m in rig.joint_states[-20:]]
    offsets = [(s - PHASE_S) / PERIOD_S - round((s - PHASE_S) / PERIOD_S) for s in stamps]
    assert max(abs(o) for o in offsets) < 1e-3          # at the loop's instants
    assert rig.voltages.last().layout.data_offset == 6  # a profile

    rig.spin_for(1.0)
    since = rig.truth[-1][0]
    rig.spin_for(2.0)
    held = [m for t, m in rig.truth if t > since]
    speeds = np.abs([m.velocity for m in held])
    positions = np.array([m.position for m in held])
    assert np.max(speeds) < 0.1, np.max(speeds, axis=0)
    assert np.max(np.ptp(positions, axis=0)) < math.radians(0.5)

    began = rig.truth[-1][0]
    rig.send(1.1, 0.9)
    assert rig.wait_said('goal_reached', 10.0, began), rig.event_log(began)
    assert rig.wait_held(rig.true_q(), 2.0 * DEG, timeout_s=3.0)
    tool = KINEMATICS.forward(rig.true_q())
    assert math.dist(tool, (1.1, 0.9)) < 0.03
    assert_never_forbidden(rig, began)
