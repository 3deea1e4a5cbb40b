"""What the controller cannot trust, through the real processes: a second publisher of
joint_states 20 deg off is named and ratchets nothing; a second publisher of voltage_command
and a second node of the controller's name are named, and their end said.

Where the arm went is read from the sim's true state, which the controller never sees."""

import time

from arm_rig import DEG
import numpy as np
import pytest
import rclpy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from arm_control.nodes.common import COMMANDS, STATE_STREAM

ROGUE_S = 3.0
ROGUE_OFFSET_RAD = -20 * DEG                 # its shoulder, 20 deg below the true one


def causes(rig, kind, since_s):
    return [cause for _, cause, _ in rig.said(kind, since_s)]


@pytest.mark.parametrize('zeroed', [False, True],
                         ids=['mid_score (the encoders tell)', 'start (the graph tells)'])
def test_a_second_joint_states_publisher_is_named_and_ratchets_nothing(rig, zeroed):
    """At mid_score the encoders say the arm did not move; at the start, where the sim
    zeroed them and they read about zero, only the count of publishers does."""
    assert rig.reach_in_tries(*((0.8, 1.0) if zeroed else (1.1, 0.9)))
    assert rig.wait_still()
    held = rig.true_q()
    began = time.monotonic()
    node = rig.probe.node
    rogue = node.create_publisher(JointState, '/joint_states', STATE_STREAM)
    while time.monotonic() - began < ROGUE_S:              # 50 Hz, as the report's
        q = rig.true_q()
        message = JointState(name=['shoulder', 'elbow'], position=[q[0] + ROGUE_OFFSET_RAD, q[1]],
                             velocity=[0.0, 0.0])
        message.header.stamp = node.get_clock().now().to_msg()
        rogue.publish(message)
        rig.spin_for(0.02)
    worst = max(np.max(np.abs(np.array(m.position) - held))
                for m in rig.truth.messages(began))
    print(f'second joint_states publisher for {ROGUE_S:g} s: the arm within '
          f'{np.degrees(worst):.2f} deg of where it was held; {rig.event_log(began)}')
    assert 'joint_states' in causes(rig, 'untrusted', began), rig.event_log(began)
    assert rig.said('sensors_disagree', began)
    assert not rig.said('arm_moved', began), rig.event_log(began)
    assert worst < 3 * DEG
    node.destroy_publisher(rogue)
    assert rig.spin_until(lambda: 'joint_states' in causes(rig, 'trusted', began), 5.0)


def test_a_second_commander_and_a_second_controller_name_are_named(rig):
    began = time.monotonic()
    node = rig.probe.node
    commander = node.create_publisher(Float64MultiArray, '/voltage_command', COMMANDS)
    twin = rclpy.create_node('controller', context=rig.probe.context)
    try:
        assert rig.spin_until(lambda: {'voltage_command', 'node name'} <=
                              set(causes(rig, 'untrusted', began)), 10.0), rig.event_log(began)
        assert rig.spin_until(lambda: any('voltage_command' in d.get('untrusted', '')
                                          for d in rig.controller_diagnostics(began)), 3.0)
    finally:
        node.destroy_publisher(commander)
        twin.destroy_node()
    assert rig.spin_until(lambda: {'voltage_command', 'node name'} <=
                          set(causes(rig, 'trusted', began)), 10.0), rig.event_log(began)
