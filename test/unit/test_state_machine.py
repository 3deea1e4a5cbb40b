"""The state machine's table: each row works, nothing else does, and 0 V states are sticky.

That the controller really takes each row is tested in ``test_arm_controller.py``.
"""

import pytest

from arm_control.control.state_machine import (ArmState, COMMANDING, InvalidTransition,
                                               StateMachine, STOPPED, TRANSITIONS, Trigger)

ALL_PAIRS = [(state, trigger) for state in ArmState for trigger in Trigger]


@pytest.mark.parametrize('state, trigger', sorted(TRANSITIONS, key=str))
def test_each_transition_leads_where_the_table_says(state, trigger):
    machine = StateMachine(state)
    assert machine.can(trigger)
    assert machine.fire(trigger) == TRANSITIONS[(state, trigger)]
    assert machine.state == TRANSITIONS[(state, trigger)]
    assert machine.history == [(state, trigger, machine.state)]


@pytest.mark.parametrize('state, trigger',
                         [pair for pair in ALL_PAIRS if pair not in TRANSITIONS])
def test_any_other_trigger_is_refused_and_changes_nothing(state, trigger):
    machine = StateMachine(state)
    assert not machine.can(trigger)
    with pytest.raises(InvalidTransition, match=f"'{trigger}' is not allowed"):
        machine.fire(trigger)
    assert machine.state == state and machine.history == []


def test_states_are_either_commanding_or_zero_volts():
    assert COMMANDING | STOPPED == set(ArmState)
    assert not COMMANDING & STOPPED


def test_an_estop_is_left_only_by_reset():
    leaving = {trigger for (state, trigger), target in TRANSITIONS.items()
               if state == ArmState.ESTOPPED and target != ArmState.ESTOPPED}
    assert leaving == {Trigger.RESET}


def test_every_commanding_state_can_be_estopped_disabled_and_lose_its_sensors():
    for state in COMMANDING:
        assert TRANSITIONS[(state, Trigger.ESTOP)] == ArmState.ESTOPPED
        assert TRANSITIONS[(state, Trigger.DISABLE)] == ArmState.DISABLED
        assert TRANSITIONS[(state, Trigger.SENSORS_LOST)] == ArmState.NO_SENSORS


def test_zero_volt_states_reach_a_commanding_state_only_by_an_explicit_trigger():
    """Out of 0 V only through: sensors returning, reset, enable; and then only to hold
    (back at a goal it held, holding it)."""
    way_out = {trigger for (state, trigger), target in TRANSITIONS.items()
               if state in STOPPED and target in COMMANDING}
    assert way_out == {Trigger.SENSORS_BACK, Trigger.SENSORS_BACK_HELD, Trigger.RESET,
                       Trigger.ENABLE}
    for (state, trigger), target in TRANSITIONS.items():
        if state in STOPPED and target in COMMANDING:
            assert target == (ArmState.HOLDING if trigger == Trigger.SENSORS_BACK_HELD
                              else ArmState.WAITING)


def test_every_state_is_reachable_from_the_start():
    reached, frontier = {ArmState.NO_SENSORS}, [ArmState.NO_SENSORS]
    while frontier:
        state = frontier.pop()
        for (source, _), target in TRANSITIONS.items():
            if source == state and target not in reached:
                reached.add(target)
                frontier.append(target)
    assert reached == set(ArmState)


def test_states_publish_as_their_names():
    assert str(ArmState.ESTOPPED) == 'estopped'
    assert f'{ArmState.DRIVER}' == 'driver'
