"""The controller node in process: what its executor gathers on each wake (joint states wake
it 50 times a second, and rclpy's executor walks every entity of the node each time)."""

from rclpy.event_handler import EventHandler


def test_the_controller_s_topics_add_no_qos_event_handlers_to_each_wake(controller):
    """Its publishers and subscriptions come without rclpy's default QoS event handlers (the
    other end of a mismatch says so itself): the only handlers left are rclpy's own, on
    the publishers every node has (/rosout, /parameter_events)."""
    handlers = [w for w in controller.waitables if isinstance(w, EventHandler)]
    assert len(handlers) <= 2, f'{len(handlers)} QoS event handlers gathered on each wake'
