"""The controller's readings, taken in its loop's thread from readers no executor waits on."""

import time

import rclpy
from sensor_msgs.msg import JointState

from arm_control.config import JOINT_NAMES
from arm_control.nodes.common import STATE_STREAM


def test_each_reading_goes_with_the_encoders_sent_before_it(controller):
    """Two periods' messages waiting for one tick, each period's encoders sent before its
    joint states (as a robot sends them): each reading has its own period's encoders, not
    the newest."""
    controller.loop.stop()                          # the test takes the readings itself
    sender = rclpy.create_node('robot')
    try:
        publishers = {topic: sender.create_publisher(JointState, topic, STATE_STREAM)
                      for topic in ('motor_encoders', 'joint_states')}
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and not all(
                p.get_subscription_count() for p in publishers.values()):
            time.sleep(0.01)
        for encoder_rad in (0.1, 0.2):
            stamp = controller.get_clock().now().to_msg()
            publishers['motor_encoders'].publish(JointState(
                name=list(JOINT_NAMES), position=[encoder_rad, -encoder_rad]))
            time.sleep(0.01)
            reading = JointState(name=list(JOINT_NAMES), position=[1.0, -1.0],
                                 velocity=[0.0, 0.0])
            reading.header.stamp = stamp
            publishers['joint_states'].publish(reading)
            time.sleep(0.01)
        time.sleep(0.2)
        readings = controller.sensors.take_new()
        assert [reading.encoder_rad for reading, _ in readings] == [(0.1, -0.1), (0.2, -0.2)]
    finally:
        sender.destroy_node()
