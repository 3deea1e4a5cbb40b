"""A block of work at real-time priority: raised while it runs, back to normal after, even
when it raises; where the system refuses, a reason that says how to allow it."""

import os
import threading

import pytest

from arm_control.realtime import dds_threads, raise_dds_threads, raise_thread, raised


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


def test_the_dds_threads_are_raised_and_python_s_are_left_alone():
    """A thread named as Fast DDS names its own (``dds.udp.<port>``) goes to SCHED_FIFO; this
    process's other threads stay as they were."""
    named, done = threading.Event(), threading.Event()
    ids = {}

    def dds_like():
        ids['dds'] = threading.get_native_id()
        with open(f"/proc/self/task/{ids['dds']}/comm", 'w') as comm:
            comm.write('dds.udp.7400')
        named.set()
        done.wait(10.0)

    def other():
        ids['other'] = threading.get_native_id()
        done.wait(10.0)
    threads = [threading.Thread(target=dds_like), threading.Thread(target=other)]
    for thread in threads:
        thread.start()
    try:
        assert named.wait(10.0)
        assert ids['dds'] in dds_threads() and ids['other'] not in dds_threads()
        problem = raise_dds_threads(7)
        if problem is None:
            assert os.sched_getscheduler(ids['dds']) == os.SCHED_FIFO
            assert os.sched_getparam(ids['dds']).sched_priority == 7
        else:                                   # no rtprio limit nor CAP_SYS_NICE here
            assert 'rtprio' in problem
        assert os.sched_getscheduler(ids['other']) == os.SCHED_OTHER
        assert policy() == os.SCHED_OTHER
    finally:
        done.set()
        for thread in threads:
            thread.join(10.0)


def test_raising_no_dds_threads_at_priority_zero_does_nothing(tmp_path):
    (tmp_path / '12').mkdir()
    (tmp_path / '12' / 'comm').write_text('dds.ev.0\n')
    (tmp_path / '13').mkdir()
    (tmp_path / '13' / 'comm').write_text('python\n')
    assert dds_threads(str(tmp_path)) == [12]
    assert raise_dds_threads(0, str(tmp_path)) is None


def test_another_thread_is_raised_by_its_id_and_the_caller_left_alone():
    """``raise_thread``: the thread named by its native id goes to SCHED_FIFO (the
    controller raises its plan-results thread so), not the one that asks."""
    started, done = threading.Event(), threading.Event()
    ids = {}

    def other():
        ids['other'] = threading.get_native_id()
        started.set()
        done.wait(10.0)
    thread = threading.Thread(target=other)
    thread.start()
    try:
        assert started.wait(10.0)
        problem = raise_thread(ids['other'], 6)
        if problem is None:
            assert os.sched_getscheduler(ids['other']) == os.SCHED_FIFO
            assert os.sched_getparam(ids['other']).sched_priority == 6
        else:                                   # no rtprio limit nor CAP_SYS_NICE here
            assert 'rtprio' in problem
        assert policy() == os.SCHED_OTHER
        assert raise_thread(ids['other'], 0) is None
    finally:
        done.set()
        thread.join(10.0)
