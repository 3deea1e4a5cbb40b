"""The one planning path: the core emits ``PlanRequest``s and takes ``TimedPlan``s.

Whoever plans is a ``Planning``: ``send(requests)``, and each answer goes to the core's
``on_timed_plan``. Two implementations:

- ``InProcessPlanning`` (tests, benchmarks, simulated time): plans and times each request at
  once in this process (``PlanTimer.plan_and_time``) and answers within the step that sends
  it, at that step's instant (no planning time passes in simulated time).
- ``nodes.plan_link.PlanLink`` (the controller node): the planner node plans, the worker
  process times; the answer comes back on the worker's result thread.

- ``HeldRequests``: keeps them for whoever takes them (``take``); a core made without a
  ``Planning`` has one.

The core hands its requests to its ``Planning`` in the step that asks them, whichever it is.
"""

from typing import Callable, Optional, Protocol, Sequence

from arm_control.plans.messages import PlanRequest, TimedPlan


class Planning(Protocol):
    """Plans asked for by ``send``; answers to the core's ``on_timed_plan``."""

    def send(self, requests: Sequence[PlanRequest]) -> None:
        ...


class HeldRequests:
    """Requests kept, not planned, until ``take`` takes them (each once)."""

    def __init__(self):
        self.requests = []

    def send(self, requests: Sequence[PlanRequest]) -> None:
        self.requests.extend(requests)

    def take(self) -> list[PlanRequest]:
        taken, self.requests = self.requests, []
        return taken


class InProcessPlanning:
    """Each request planned with ``planner`` (anything with ``plan(start_q, goal_xy)``, e.g.
    ``planning.planner.Planner``) and timed by the core's ``PlanTimer`` at once;
    ``on_timed(timed)`` takes the answer (default: the core, at the step that sent it)."""

    def __init__(self, core, planner, on_timed: Optional[Callable[[TimedPlan], None]] = None):
        self.core, self.planner = core, planner
        self.on_timed = on_timed or self.answer_at_once

    def answer_at_once(self, timed: TimedPlan) -> None:
        self.core.on_timed_plan(self.core.last_step_s, timed)

    def send(self, requests: Sequence[PlanRequest]) -> None:
        for request in requests:
            self.on_timed(self.core.plan_timer.plan_and_time(request, self.planner))


def plan_in_process(core, planner):
    """``core`` planning with ``planner`` in its own step (``InProcessPlanning``); None: its
    requests held (``HeldRequests``). Returns the core."""
    core.planning = HeldRequests() if planner is None else InProcessPlanning(core, planner)
    return core
