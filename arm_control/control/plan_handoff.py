"""The core's side of planning: the goal being planned, its request, when it must be
answered, and what an answer means for the arm (a ``Verdict``)."""

from dataclasses import dataclass
from enum import Enum
import math
from typing import Optional

from arm_control.plans.goals import Goal
from arm_control.plans.messages import PlanRequest, TimedPlan


class PlanHandoff:
    """The goal being planned: its request, when it must be answered, and what an answer
    means for the arm."""

    def __init__(self, planner_timeout_s: float):
        self.planner_timeout_s = planner_timeout_s
        self.pending: Optional[PlanRequest] = None
        self._outbox: list[PlanRequest] = []
        self._next_id = 1
        self.started_s = math.nan
        self.last: Optional[TimedPlan] = None

    def start(self, now_s: float) -> None:
        """A goal becomes current: it must have a plan within the planner timeout."""
        self.started_s = now_s

    @property
    def deadline_s(self) -> float:
        return self.started_s + self.planner_timeout_s

    def ask(self, now_s: float, goal: Goal, start_q, start_velocity_rad_s,
            start_time_s: Optional[float], lead_s: float) -> None:
        request = PlanRequest(self._next_id, goal, (float(start_q[0]), float(start_q[1])),
                              tuple(float(v) for v in start_velocity_rad_s), start_time_s,
                              now_s, lead_s)
        self._next_id += 1
        self.pending, self._outbox = request, [request]

    @property
    def requests(self) -> tuple[PlanRequest, ...]:
        """Requests not yet taken."""
        return tuple(self._outbox)

    def take(self) -> list[PlanRequest]:
        """Requests to send to the planner (each once)."""
        out, self._outbox = self._outbox, []
        return out

    def drop(self) -> None:
        self.pending, self._outbox = None, []

    def overdue(self, now_s: float) -> bool:
        return self.pending is not None and now_s > self.deadline_s

    def answer(self, now_s: float, timed: TimedPlan, idle_from_s: float) -> 'PlanAnswer':
        """What ``timed`` means now (see ``Verdict``). ``idle_from_s``: when the current
        motion ends (a plan from rest begins then at the earliest)."""
        request = timed.request
        if self.pending is None or request.request_id != self.pending.request_id:
            return PlanAnswer(Verdict.IGNORE)
        self.pending, self.last = None, timed
        if not timed.ok:
            return PlanAnswer(Verdict.FAIL, reason=timed.reason)
        if request.start_time_s is None:
            return PlanAnswer(Verdict.TAKE, begin_s=max(now_s, idle_from_s))
        if now_s <= request.start_time_s:
            return PlanAnswer(Verdict.TAKE, begin_s=request.start_time_s)
        if now_s + 2.0 * request.lead_s > self.deadline_s:
            return PlanAnswer(Verdict.FAIL, reason=f'the plan for {request.goal.label} came '
                                                   'too late to take over the moving arm')
        return PlanAnswer(Verdict.RETRY, lead_s=2.0 * request.lead_s)


class Verdict(Enum):
    IGNORE = 'ignore'   # an answer to an older request
    FAIL = 'fail'       # no plan, or one too late to take over the moving arm: ``reason``
    RETRY = 'retry'     # too late to take over, but there is time to ask again: ``lead_s``
    TAKE = 'take'       # the plan begins at ``begin_s``


@dataclass(frozen=True)
class PlanAnswer:
    verdict: Verdict
    begin_s: float = math.nan
    lead_s: float = math.nan
    reason: str = ''
