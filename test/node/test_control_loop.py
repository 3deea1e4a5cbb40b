"""The control loop in simulated time, in step with a sim that advances the clock one period
after each answer, as the sim node does."""

import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest
from rclpy.clock import ClockType

from arm_control.nodes.control_loop import ControlLoop

PERIOD_S = 0.02
STEPS = 25


class SimClock:
    """A /clock that the test steps: ROS time, active."""

    clock_type = ClockType.ROS_TIME
    ros_time_is_active = True

    def __init__(self, started_s: float = 1.0):
        self.nanoseconds = round(started_s * 1e9)      # 0: no /clock yet

    def now(self):
        return SimpleNamespace(nanoseconds=self.nanoseconds)


def wall_gaps_of_ticks(working: bool) -> np.ndarray:
    """Step the clock a period after each tick; the wall time between ticks (s)."""
    clock, answered, walls = SimClock(), threading.Event(), []

    def tick():
        walls.append(time.monotonic())
        answered.set()
    loop = ControlLoop(clock, PERIOD_S, tick, working=lambda: working)
    loop.start()
    try:
        for _ in range(STEPS):
            assert answered.wait(5.0), 'the loop did not answer the step'
            answered.clear()
            clock.nanoseconds += round(PERIOD_S * 1e9)
        assert answered.wait(5.0)
    finally:
        loop.stop()
    return np.diff(walls)


def test_while_a_plan_is_made_the_clock_keeps_to_real_time():
    """Planning takes wall time: a step answered no sooner than a period of wall time after
    the last keeps the sim, in step with the loop, at real time meanwhile."""
    gaps = wall_gaps_of_ticks(working=True)
    assert len(gaps) == STEPS
    # Over the steps (a tick's own timestamp may come a little after the loop's decision).
    assert gaps.sum() >= STEPS * PERIOD_S - 0.005


def test_otherwise_each_step_is_answered_as_it_comes():
    """With no wall-time work the sim runs as fast as the loop answers: faster than real
    time (here by far; a loaded machine only narrows it)."""
    gaps = wall_gaps_of_ticks(working=False)
    assert len(gaps) == STEPS
    assert gaps.sum() < 0.5 * STEPS * PERIOD_S


def test_a_plan_taken_after_the_steps_command_went_out_starts_at_the_next_step():
    """The sim applies one command per step: once this step's went out, the next command
    acts at the next step, and a trajectory begun now would be a step along by then."""
    clock, answered = SimClock(), threading.Event()
    loop = ControlLoop(clock, PERIOD_S, answered.set)
    clock.nanoseconds = round(3.0e9)
    loop.start()
    try:
        assert answered.wait(5.0)
        time.sleep(0.05)                         # the loop now waits for the next step
        assert loop.next_command_s() == pytest.approx(3.0 + PERIOD_S)
        answered.clear()
        clock.nanoseconds += round(PERIOD_S * 1e9)
        assert answered.wait(5.0)
        time.sleep(0.05)
        assert loop.next_command_s() == pytest.approx(3.0 + 2 * PERIOD_S)
    finally:
        loop.stop()


def test_nothing_is_answered_before_the_sims_clock_starts():
    """A simulated clock reads 0 until the first /clock: no tick is stamped then."""
    clock, ticks = SimClock(started_s=0.0), []
    loop = ControlLoop(clock, PERIOD_S, lambda: ticks.append(clock.nanoseconds))
    loop.start()
    try:
        time.sleep(0.1)
        assert ticks == [] and not loop.started()
        clock.nanoseconds = round(5.0e9)
        deadline = time.monotonic() + 5.0
        while not ticks and time.monotonic() < deadline:
            time.sleep(0.005)
        assert ticks == [round(5.0e9)]
    finally:
        loop.stop()


@pytest.mark.parametrize('jump_s', [100.0, -10.0])
def test_a_jump_of_the_clock_does_not_stop_the_ticks(jump_s):
    """A rogue /clock 100 s ahead, once, then the sim's again (or the sim restarted 10 s
    back): every later step is answered, and the loop's time never leaps."""
    clock, answered, times = SimClock(1000.0), threading.Event(), []
    loop = ControlLoop(clock, PERIOD_S, lambda: (times.append(loop.now_s()), answered.set()))
    loop.start()
    try:
        for step in range(2 * STEPS):
            assert answered.wait(5.0), f'step {step} not answered'
            answered.clear()
            if step == STEPS:
                clock.nanoseconds += round(jump_s * 1e9)
                time.sleep(0.005)                   # the loop reads the jumped clock
                if jump_s > 0:
                    clock.nanoseconds -= round(jump_s * 1e9)     # the sim's clock again
            clock.nanoseconds += round(PERIOD_S * 1e9)
        assert answered.wait(5.0)
    finally:
        loop.stop()
    assert np.all(np.diff(times) >= 0.0) and np.max(np.diff(times)) < 2.5 * PERIOD_S
    assert loop.guard.jumps >= 1


def test_a_clock_that_stops_while_readings_come_does_not_stop_the_ticks():
    clock, ticks = SimClock(), []
    reading = {'new': True}

    def tick():
        ticks.append(time.monotonic())
        reading['new'] = False
    loop = ControlLoop(clock, PERIOD_S, tick, has_input=lambda now_s: reading['new'])
    loop.start()
    try:
        began = time.monotonic()
        while time.monotonic() - began < 2.0:           # the clock stands; readings come
            reading['new'] = True
            time.sleep(PERIOD_S)
    finally:
        loop.stop()
    assert len(ticks) >= 3 and loop.clock_stops >= 2


def test_a_reading_taken_late_is_timed_at_its_arrival_in_real_time_only():
    """Readings are taken when the loop ticks: in real time each is timed when the middleware
    received it (never after now), on control time; in simulated time, or with no reception
    instant, at the tick."""
    wall = SimClock(100.0)
    wall.ros_time_is_active = False                 # the system clock, as the node's
    loop = ControlLoop(wall, PERIOD_S, lambda: None)
    now = loop.now_s()
    assert loop.arrived_s(round((now - 0.015) * 1e9)) == pytest.approx(now - 0.015, abs=1e-9)
    assert loop.arrived_s(round((now + 0.5) * 1e9)) == now      # a clock ahead: not later
    assert loop.arrived_s(0) == now
    simulated = ControlLoop(SimClock(100.0), PERIOD_S, lambda: None)
    assert simulated.arrived_s(round(99.985e9)) == simulated.now_s()


class WallClock:
    """The system clock, as a node's without simulated time."""

    clock_type = ClockType.SYSTEM_TIME
    ros_time_is_active = False

    def now(self):
        return SimpleNamespace(nanoseconds=time.time_ns())


def test_holding_still_the_loop_ticks_every_few_periods_and_at_once_when_poked():
    """In real time, ``periods()`` periods between ticks (2 while the arm holds still), one
    otherwise; a poke (a goal) ticks at once, not at the next due tick. Late ticks only
    make the gaps longer: the bounds hold on a loaded machine."""
    ticks, still = [], [True]
    loop = ControlLoop(WallClock(), PERIOD_S, lambda: ticks.append(time.monotonic()),
                       periods=lambda: 2 if still[0] else 1)
    loop.start()
    try:
        time.sleep(0.6)
        held = np.diff(ticks)
        count = len(ticks)
        while len(ticks) == count:                  # just after a tick, poke
            time.sleep(0.0005)
        poked_s = time.monotonic()
        loop.poke()
        while len(ticks) == count + 1:
            time.sleep(0.0005)
        answered_s = ticks[count + 1] - poked_s
        still[0] = False
        time.sleep(0.1)
        moving_from = len(ticks)
        time.sleep(0.4)
        moving = np.diff(ticks[moving_from:])
    finally:
        loop.stop()
    assert len(held) >= 8 and np.percentile(held, 10) >= 1.5 * PERIOD_S, held
    assert answered_s < PERIOD_S, answered_s
    assert len(moving) >= 10 and np.median(moving) < 1.5 * PERIOD_S, moving
