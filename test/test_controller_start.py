"""The controller node as it starts, in process: before it has first looked for the planner,
a goal waits in the queue like one that comes while it looks."""

import os

import rclpy

from arm_control.control.events import EventKind as Kind
from arm_control.nodes.controller import ControllerNode


def test_a_goal_before_the_first_look_for_the_planner_waits_for_it(domain):
    """Constructed and not yet spun, the node has said once that it waits for the planner,
    and a preset sent then is queued until the planner is up, not planned (it would fail at
    the planner timeout: the service is not there yet)."""
    # At real-time priority the node would raise this thread, pytest's, for every later test.
    rclpy.init(args=['--ros-args', '-p', 'realtime_priority:=0'], domain_id=domain)
    node = None
    try:
        node = ControllerNode()
        accepted, _ = node.command(node.core.submit_preset, 'mid_score')
        assert accepted
        assert node.core.goals.waiting_for_planner
        assert [e.kind for e in node.core.events.history].count(Kind.PLANNER_WAITING) == 1
        assert node.core.take_plan_requests() == []
    finally:
        if node is not None:
            node.loop.stop()
            node.plans.close()
            node.destroy_node()
        rclpy.try_shutdown()
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
