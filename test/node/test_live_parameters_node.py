"""A node's live parameters, in process: ROS's own are refused at run time, and a check that
raises refuses the change instead of ending the node. And the controller's drained inputs."""

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32

from arm_control.nodes.common import declare_parameters, Drained, take_all


def test_use_sim_time_is_refused_and_a_raising_check_refuses_the_change(domain):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        node = rclpy.create_node('controller', context=context)

        def check(values):
            if values['dwell_s'] > 1.0:
                raise RuntimeError('the check itself failed')
            return None
        declare_parameters(node, 'controller', ('dwell_s',), check)
        result = node.set_parameters([Parameter('use_sim_time', value=True)])[0]
        assert not result.successful and 'use_sim_time' in result.reason
        assert node.get_parameter('use_sim_time').value is False
        assert not node.get_clock().ros_time_is_active          # the clock never switched
        assert not node.set_parameters([Parameter('dwell_s', value=2.0)])[0].successful
        assert node.set_parameters([Parameter('dwell_s', value=0.5)])[0].successful
        assert not node.set_parameters([Parameter('loop_rate_hz', value=10.0)])[0].successful
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_a_drained_subscription_wakes_no_executor_and_gives_every_message_in_order(domain):
    """``Drained``: the executor never calls its callback (nor waits on it); ``take_all``
    hands over every message that came, oldest first, and then nothing."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        node = rclpy.create_node('drained', context=context)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        called, taken = [], []
        subscription = node.create_subscription(Int32, 'numbers', called.append, qos,
                                                callback_group=Drained())
        publisher = node.create_publisher(Int32, 'numbers', qos)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        for _ in range(50):
            if publisher.get_subscription_count():
                break
            executor.spin_once(timeout_sec=0.1)
        for k in range(5):
            publisher.publish(Int32(data=k))
        for _ in range(10):
            executor.spin_once(timeout_sec=0.05)
        take_all(subscription, lambda message: taken.append(message.data))
        assert called == []
        assert taken == [0, 1, 2, 3, 4]
        take_all(subscription, lambda message: taken.append(message.data))
        assert taken == [0, 1, 2, 3, 4]
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
