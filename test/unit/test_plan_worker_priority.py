"""The plan worker waits for a goal's request at ``planning_priority``: a request must not
wait in the run queue behind busy processes before it is even read. The thread that hands
the controller its timed plans is the one ``results_thread_id`` names (the node raises it)."""

import math
import os
from pathlib import Path
import threading
import time

import numpy as np
import pytest

from arm_control import config
from arm_control.nodes.plan_worker import PlanWorker
from arm_control.plans.goals import Goal
from arm_control.plans.messages import PathPlan, PlanRequest
from arm_control.realtime import raised


def fifo_allowed() -> bool:
    result = {}

    def probe():
        with raised(1) as problem:
            result['ok'] = problem is None
    thread = threading.Thread(target=probe)
    thread.start()
    thread.join(5.0)
    return result.get('ok', False)


def main_thread_policy(pid: int) -> tuple:
    return os.sched_getscheduler(pid), os.sched_getparam(pid).sched_priority


def children(pid: int) -> list:
    text = Path(f'/proc/{pid}/task/{pid}/children').read_text()
    return [int(child) for child in text.split()]


@pytest.fixture(scope='module')
def worker_and_answers():
    arm, controller = config.load('controller')
    answers, arrived = [], threading.Event()

    def on_timed(timed):
        answers.append((threading.get_native_id(), timed))
        arrived.set()
    worker = PlanWorker(arm, controller, on_timed)
    assert worker.ready.wait(60.0)
    yield worker, controller, answers, arrived
    worker.close()


def test_the_idle_worker_waits_for_requests_at_planning_priority(worker_and_answers):
    worker, controller, _, _ = worker_and_answers
    if not fifo_allowed() or controller.planning_priority <= 0:
        pytest.skip('SCHED_FIFO refused here (no rtprio limit nor CAP_SYS_NICE)')
    wanted = (os.SCHED_FIFO, controller.planning_priority)
    deadline = time.monotonic() + 60.0          # its warm-up runs at normal priority first
    policy = main_thread_policy(worker.process.pid)
    while policy != wanted and time.monotonic() < deadline:
        time.sleep(0.05)
        # One reading: between two, the worker may take a setting (at normal priority).
        policy = main_thread_policy(worker.process.pid)
    assert policy == wanted


def test_a_timed_plan_comes_on_the_thread_results_thread_id_names(worker_and_answers):
    worker, controller, answers, arrived = worker_and_answers
    start, goal = (1.5708, -1.5708), Goal(0.9, 1.5, 'test')
    plan = PathPlan(np.array([start, (0.9, 1.2)]))
    worker.allow_keeping(False)
    worker.submit(PlanRequest(1, goal, start, (0.0, 0.0), None, 0.0), plan)
    deadline = time.monotonic() + 30.0
    while not answers and time.monotonic() < deadline:
        arrived.wait(0.05)
    assert answers, 'no answer from the worker'
    thread_id, timed = answers[0]
    assert thread_id == worker.results_thread_id
    assert timed.request.request_id == 1 and math.isnan(timed.handover_s)
    # The keeper, a child of the worker, never runs at real-time priority.
    for child in children(worker.process.pid):
        assert os.sched_getscheduler(child) == os.SCHED_OTHER
