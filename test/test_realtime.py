"""A block of work at real-time priority: raised while it runs, back to normal after, even
when it raises; where the system refuses, a reason that says how to allow it."""

import os
import threading

import pytest

from arm_control.realtime import raised


def in_a_thread(work):
    """``work()``'s result, run in a thread of its own (the test runner's stays as it is)."""
    result = {}

    def run():
        try:
            result['value'] = work()
        except BaseException as error:          # handed back to the test
            result['error'] = error
    thread = threading.Thread(target=run)
    thread.start()
    thread.join(10.0)
    if 'error' in result:
        raise result['error']
    return result['value']


def policy() -> int:
    return os.sched_getscheduler(0)


def test_a_block_runs_at_fifo_then_the_thread_is_normal_again():
    def work():
        with raised(10) as problem:
            inside = policy(), os.sched_getparam(0).sched_priority
        return problem, inside, policy()
    problem, inside, after = in_a_thread(work)
    if problem is None:
        assert inside == (os.SCHED_FIFO, 10)
    else:                                       # no rtprio limit nor CAP_SYS_NICE here
        assert 'rtprio' in problem and inside[0] == os.SCHED_OTHER
    assert after == os.SCHED_OTHER


def test_an_error_in_the_block_still_returns_the_thread_to_normal():
    def work():
        with pytest.raises(ZeroDivisionError):
            with raised(10):
                1 / 0
        return policy()
    assert in_a_thread(work) == os.SCHED_OTHER


def test_priority_zero_leaves_the_thread_alone():
    def work():
        with raised(0) as problem:
            return problem, policy()
    assert in_a_thread(work) == (None, os.SCHED_OTHER)
