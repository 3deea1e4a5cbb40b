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


@pytest.mark.parametrize('work_s', [0.001, 0.005, 0.02])
def test_the_core_work_inputs_take_is_bounded_whatever_each_costs(work_s):
    """Three floods of 500 a second, each input taken costing ``work_s`` of the core's time
    (a loaded machine stretches it): their work stays within the share of the wall time
    (plus one burst and one input), and every input is answered or counted."""
    gate = InputGate()
    core = SimpleNamespace(goals=SimpleNamespace(counts={'rejected': 0}), events=EventLog())
    sent = taken = said = 0
    spent_s = 0.0
    for k in range(5 * 500):
        wall_s = k / 500.0
        for kind in gate.rates:
            sent += 1
            if gate.admit(kind, wall_s):
                taken += 1
                gate.spent(work_s)
                spent_s += work_s
        if k % 500 == 499:
            said += gate.flush(core, wall_s, wall_s)
    assert spent_s <= gate.work_share * 5.0 + gate.work_burst_s + work_s
    assert taken + said == sent and gate.busy > 0
