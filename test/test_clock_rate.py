"""The control loop's measure of its clock's speed against the wall's (sim time at 5x)."""

import pytest

from arm_control.nodes.control_loop import ClockRate, RATE_WINDOW_S


def fed(pairs):
    rate = ClockRate()
    for clock_s, wall_s in pairs:
        rate.update(clock_s, wall_s)
    return rate.rate


def ticks(speed, seconds, start=(0.0, 0.0), period_s=0.02):
    clock0, wall0 = start
    steps = int(seconds / period_s)
    return [(clock0 + speed * k * period_s, wall0 + k * period_s) for k in range(steps + 1)]


@pytest.mark.parametrize('speed', [1.0, 5.0, 0.5])
def test_the_rate_is_the_clocks_speed(speed):
    assert fed(ticks(speed, 3.0)) == pytest.approx(speed)


def test_a_paused_clock_keeps_the_last_rate_and_a_new_speed_is_followed():
    at_five = ticks(5.0, 2.0)
    paused = [(at_five[-1][0], at_five[-1][1] + k * 0.02) for k in range(1, 100)]
    assert fed(at_five + paused) == pytest.approx(5.0)
    slower = ticks(2.0, 2.0 + 2 * RATE_WINDOW_S, start=paused[-1])
    assert fed(at_five + paused + slower) == pytest.approx(2.0)


def test_a_brief_slowdown_does_not_shrink_a_wall_time_budget():
    """A sim in step with a slow process runs slower for a moment: the rate stays the most
    of the last windows, so a wall-time budget on the clock does not get shorter."""
    at_five = ticks(5.0, 3.0)
    slow = ticks(1.0, RATE_WINDOW_S, start=at_five[-1])[1:]
    assert fed(at_five + slow) == pytest.approx(5.0)
