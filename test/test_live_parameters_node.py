"""A node's live parameters, in process: ROS's own are refused at run time, and a check that
raises refuses the change instead of ending the node."""

import rclpy
from rclpy.parameter import Parameter

from arm_control.nodes.common import declare_parameters


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
