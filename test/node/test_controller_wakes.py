"""The controller node in process: what its executor gathers on each wake (joint states wake
it 50 times a second, and rclpy's executor walks every entity of the node each time)."""

import rclpy
from rclpy.event_handler import EventHandler

from arm_control.nodes.controller import ControllerNode


def test_the_controller_s_topics_add_no_qos_event_handlers_to_each_wake(domain):
    """Its publishers and subscriptions come without rclpy's default QoS event handlers (the
    other end of a mismatch says so itself): the only handlers left are rclpy's own, on
    the publishers every node has (/rosout, /parameter_events)."""
    rclpy.init(args=['--ros-args', '-p', 'realtime_priority:=0'], domain_id=domain)
    node = None
    try:
        node = ControllerNode()
        handlers = [w for w in node.waitables if isinstance(w, EventHandler)]
        assert len(handlers) <= 2, f'{len(handlers)} QoS event handlers gathered on each wake'
    finally:
        if node is not None:
            node.loop.stop()
            node.plans.close()
            node.destroy_node()
        rclpy.try_shutdown()
