"""One planning path: the core hands its plan requests to its ``Planning`` in the step that
asks and takes its timed plans; in-process, the answer is taken in that step, at its
instant."""

import pytest

from arm_control.control.closed_loop import ClosedLoop
from arm_control.control.state_machine import ArmState
from arm_control.plans.goals import StraightLinePlanner

GOAL_XY = (1.1, 0.9)


class Recording:
    """A ``Planning`` that keeps what it is sent and never answers."""

    def __init__(self):
        self.sent = []

    def send(self, requests):
        self.sent.extend(requests)


def started_goal(loop):
    loop.run(0.2)
    loop.core.submit_goal(loop.now, *GOAL_XY)
    loop.step()
    return loop.core


def test_a_core_hands_each_request_to_its_planning_in_the_step_that_asks(
        arm, controller_config):
    loop = ClosedLoop(arm, controller_config)
    planning = loop.core.planning = Recording()
    core = started_goal(loop)
    assert [request.goal.xy for request in planning.sent] == [pytest.approx(GOAL_XY)]
    assert core.last_step.plan_requests == tuple(planning.sent)
    assert not core.requests_waiting                   # handed over, once
    loop.step()
    assert core.last_step.plan_requests == () and len(planning.sent) == 1
    assert core.state == ArmState.PLANNING             # no answer yet


def test_without_a_planning_the_requests_are_held_for_whoever_takes_them(
        arm, controller_config):
    core = started_goal(ClosedLoop(arm, controller_config))
    requests = core.planning.take()
    assert [request.goal.xy for request in requests] == [pytest.approx(GOAL_XY)]
    assert core.planning.take() == []
    assert core.state == ArmState.PLANNING


def test_in_process_planning_answers_in_the_step_that_asks_at_its_instant(
        arm, controller_config):
    loop = ClosedLoop(arm, controller_config, StraightLinePlanner(arm))
    core = started_goal(loop)
    answered = core.goals.plans.last
    assert answered is not None and answered.ok
    assert answered.request.sent_time_s == core.last_step_s
    assert core.state == ArmState.TRACKING
    assert core.last_step.plan_requests == (answered.request,)
