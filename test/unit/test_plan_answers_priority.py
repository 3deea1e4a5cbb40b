"""A goal's refinement runs at ``planning_priority``, as its quick timing does: it has a
deadline (its hand-over), and one that waits in the run queue behind busy processes misses
it, and is retried from later on, ending later."""

from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from arm_control import config
from arm_control.plans import worker as plan_answers
from arm_control.plans.goals import Goal
from arm_control.plans.messages import PathPlan, PlanRequest
from arm_control.plans.timer import PlanTimer

PRIORITY = 7


def test_the_quick_timing_and_its_refinement_both_run_raised(monkeypatch):
    arm, controller = config.load('controller')
    timer = PlanTimer(arm, replace(controller, planning_priority=PRIORITY))
    levels = [0]                        # the priority in effect, innermost last
    seen = {}

    @contextmanager
    def raised(priority):
        levels.append(priority)
        try:
            yield None
        finally:
            levels.pop()
    monkeypatch.setattr(plan_answers, 'raised', raised)
    for name in ('time_plan', 'refine'):
        method = getattr(timer, name)

        def recorded(*args, _name=name, _method=method, **kwargs):
            seen.setdefault(_name, []).append(levels[-1])
            return _method(*args, **kwargs)
        monkeypatch.setattr(timer, name, recorded)
    start, end = (1.5708, -1.5708), (0.9, 1.2)
    goal = Goal(*timer.kinematics.forward(end), 'test')
    request = PlanRequest(1, goal, start, (0.0, 0.0), None, 0.0)
    sent = []
    assert plan_answers.answer(timer, plan_answers.HandoverClock(), request,
                               PathPlan(np.array([start, end])), sent.append,
                               lambda: False)
    assert seen['time_plan'] == [PRIORITY]
    assert seen.get('refine') and set(seen['refine']) == {PRIORITY}
    assert len(sent) >= 2 and np.isfinite(sent[1].handover_s)
