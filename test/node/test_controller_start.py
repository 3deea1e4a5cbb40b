"""The controller node in process: before it has first looked for the planner, a goal waits
in the queue like one that comes while it looks; once it has yielded the arm to another
controller, it takes no settings; a goal's plan request goes out before what it said."""

import os

import pytest
import rclpy
from rclpy.parameter import Parameter

from arm_control.control.events import EventKind as Kind
from arm_control.nodes.controller import ControllerNode


@pytest.fixture
def controller(domain):
    """A controller node constructed and not spun. At real-time priority it would raise this
    thread, pytest's, for every later test."""
    rclpy.init(args=['--ros-args', '-p', 'realtime_priority:=0'], domain_id=domain)
    node = None
    try:
        node = ControllerNode()
        yield node
    finally:
        if node is not None:
            node.loop.stop()
            node.plans.close()
            node.destroy_node()
        rclpy.try_shutdown()


def test_a_goal_before_the_first_look_for_the_planner_waits_for_it(controller):
    """Constructed and not yet spun, the node has said once that it waits for the planner,
    and a preset sent then is queued until the planner is up, not planned (it would fail at
    the planner timeout: the service is not there yet)."""
    accepted, _ = controller.command(controller.core.submit_preset, 'mid_score')
    assert accepted
    assert controller.core.goals.waiting_for_planner
    assert [e.kind for e in controller.core.events.history].count(Kind.PLANNER_WAITING) == 1
    assert controller.core.take_plan_requests() == []
    assert os.sched_getscheduler(0) == os.SCHED_OTHER


def test_a_controller_that_yielded_refuses_settings_and_keeps_its_own(controller):
    gains = controller.get_parameter('shoulder_pid').value
    controller.claims.yielding = True
    result = controller.set_parameters([Parameter('shoulder_pid', value=[1.0, 0.0, 0.0])])[0]
    assert not result.successful
    assert controller.get_parameter('shoulder_pid').value == gains
    controller.claims.yielding = False
    result = controller.set_parameters([Parameter('shoulder_pid', value=[1.0, 0.0, 0.0])])[0]
    assert result.successful, result.reason


def test_a_plan_request_goes_out_before_the_goal_s_events(controller):
    """The arm waits for the plan, nobody waits for the events: the request is sent first,
    then the events (each also a log line), state and queue."""
    controller.publish_outputs()                # what the start said is out of the way
    order = []
    controller.core.events.say(0.0, Kind.GOAL_QUEUED, 'info', 'goal queued')
    controller.core.take_plan_requests = lambda: ['a request']
    controller.plans.send = lambda requests: order.append(('request', tuple(requests)))
    publish = controller.events_pub.publish

    def publish_event(message):
        order.append(('event', message.data))
        publish(message)
    controller.events_pub.publish = publish_event
    controller.publish_outputs()
    assert [kind for kind, _ in order] == ['request', 'event']
    assert order[0][1] == ('a request',)
