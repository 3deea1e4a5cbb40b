"""A flood of inputs is dropped before the core, and every dropped one is counted and said."""

from types import SimpleNamespace

import pytest

from arm_control.control.events import EventKind as Kind, EventLog, parse_event
from arm_control.control.input_gate import InputGate, Rate


def test_three_floods_of_500_a_second_are_taken_at_their_rates_and_the_rest_counted():
    rates = {'goal_point': Rate(100.0, 100.0), 'goal_preset': Rate(20.0, 10.0),
             'driver_velocity': Rate(200.0, 20.0)}
    gate = InputGate(rates)
    core = SimpleNamespace(goals=SimpleNamespace(counts={'rejected': 0}), events=EventLog())
    taken = dict.fromkeys(rates, 0)
    sent, said = 0, 0
    for k in range(5 * 500):                         # 5 s at 500 Hz, each topic
        wall_s = k / 500.0
        for kind in rates:
            sent += 1
            taken[kind] += gate.admit(kind, wall_s)
        if k % 500 == 499:
            said += gate.flush(core, wall_s, wall_s)
    for kind, rate in rates.items():
        assert taken[kind] == pytest.approx(rate.burst + 5.0 * rate.rate_hz, abs=2)
    assert sum(taken.values()) + said == sent                   # answered or counted
    assert core.goals.counts['rejected'] == said == sum(gate.dropped.values())
    events = core.events.take()
    assert [e.kind for e in events] == [Kind.GOALS_REJECTED] * 5      # one a second
    assert sum(int(parse_event(str(e))[2].split()[0]) for e in events) == said


def test_inputs_at_their_rate_all_pass_and_nothing_is_said():
    gate = InputGate()
    assert all(gate.admit('driver_velocity', k / 100.0) for k in range(1000))
    assert gate.flush(SimpleNamespace(), 10.0, 10.0) == 0
