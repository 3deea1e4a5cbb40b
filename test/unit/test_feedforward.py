"""The period feedforward: a voltage held over each control period that keeps the arm on the
trajectory, within the battery voltage it is given."""

import math

import numpy as np
import pytest

from arm_control import config
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.feedforward import PeriodFeedforward
from arm_control.model.plant import ArmPlant
from arm_control.model.world import ForbiddenSpace
from arm_control.timing import time_optimal_trajectory, TrajectoryLimits

UP_TO_THE_FRONT = [(1.5708, -1.5708), (0.3, 0.5)]


@pytest.fixture(scope='module')
def setup():
    arm, controller = config.load('controller')
    return (arm, ArmDynamics(arm), ForbiddenSpace(arm),
            TrajectoryLimits.from_config(arm, controller))


def drive_held(arm, trajectory, voltage_for_period, period_s=0.02, hold_s=0.3):
    """The noise-free plant driven at 50 Hz by a voltage held over each period (given the
    time and the battery's open-circuit voltage, V_bus + R·I_supply, as the plant reports
    them): the true state at every period's start, and at the end."""
    plant = ArmPlant(arm, trajectory.start_rad)
    states = []
    for k in range(int(math.ceil((trajectory.duration_s + hold_s) / period_s))):
        states.append(np.array(plant.state))
        power = plant.power
        battery = power.bus_voltage + arm.battery.resistance_ohm * power.supply_current_a
        plant.set_voltage(voltage_for_period(k * period_s, battery))
        plant.advance(period_s)
    return np.array(states), np.array(plant.state)


def test_the_period_feedforward_keeps_the_held_arm_on_the_trajectory(setup):
    """Held 20 ms at a time, the deadbeat feedforward moves the arm as its reference (within
    0.06 deg: the plant holds what its motor controllers apply for each 1 ms step, the
    reference follows them continuously) and brings it to rest on the goal two periods after
    the trajectory ends; the period's average voltage (Simpson) leaves it farther off (by
    how much depends on the trajectory's last stages: 3-10 times)."""
    arm, dynamics, forbidden, limits = setup
    waypoints = UP_TO_THE_FRONT
    trajectory = time_optimal_trajectory(waypoints, dynamics, forbidden, limits)
    feedforward = PeriodFeedforward(dynamics, 0.02, arm.battery.nominal_voltage)
    references = []

    def deadbeat(t, bus):
        voltage = feedforward.step(t, trajectory.sample, bus)
        references.append(feedforward.state.copy())
        return voltage

    def average(t, bus):
        return sum(w * np.array(dynamics.voltage_for(*trajectory.sample(t + f * 0.02)))
                   for f, w in ((0.0, 1 / 6), (0.5, 4 / 6), (1.0, 1 / 6)))

    states, _ = drive_held(arm, trajectory, deadbeat)
    np.testing.assert_allclose(states[:, :2], np.array(references)[:, :2], atol=1e-3)
    np.testing.assert_allclose(states[:, 2:], np.array(references)[:, 2:], atol=0.01)
    after = np.arange(len(states)) * 0.02 >= trajectory.duration_s + 0.04
    deadbeat_off = np.max(np.abs(states[after, :2] - waypoints[-1]))
    assert deadbeat_off < math.radians(0.05)
    held, _ = drive_held(arm, trajectory, average)
    assert np.max(np.abs(held[after, :2] - waypoints[-1])) > 2.0 * deadbeat_off


def test_the_feedforward_stays_within_the_battery_voltage_it_is_given(setup):
    """Given a weak battery, no voltage it asks for goes past it; given none (or one that is
    not a number), its maximum holds."""
    arm, dynamics, forbidden, limits = setup
    trajectory = time_optimal_trajectory(UP_TO_THE_FRONT, dynamics, forbidden, limits)

    def peak(bus):
        feedforward = PeriodFeedforward(dynamics, 0.02, 12.0)
        return max(np.max(np.abs(feedforward.step(t, trajectory.sample, bus)))
                   for t in np.arange(0.0, trajectory.duration_s, 0.02))

    assert peak(None) > 8.5            # the trajectory asks for more than a weak battery gives
    assert peak(8.0) == pytest.approx(8.0)
    assert peak(math.nan) == peak(None)
    assert peak(13.0) <= 12.0


def test_holding_still_the_voltage_is_kept_not_solved_again(setup):
    """At rest at the trajectory's end the feedforward keeps the voltage that held its
    reference there, without running the model again: the voltage a solve from the setpoint
    gives (within 1e-9 V), the reference on the setpoint at rest. A weaker battery is a new
    problem, solved anew."""
    arm, dynamics, forbidden, limits = setup
    trajectory = time_optimal_trajectory(UP_TO_THE_FRONT, dynamics, forbidden, limits)
    feedforward = PeriodFeedforward(dynamics, 0.02, 12.0)
    times = iter(np.arange(0.0, trajectory.duration_s + 2.0, 0.02))
    for t in times:
        if t > trajectory.duration_s + 0.5:
            break
        feedforward.step(t, trajectory.sample, 12.0)
    runs = []
    model = feedforward._simulate
    feedforward._simulate = lambda *args, **kwargs: runs.append(1) or model(*args, **kwargs)
    kept = [feedforward.step(t, trajectory.sample, 12.0) for t, _ in zip(times, range(20))]
    assert not runs
    end = trajectory.sample(trajectory.duration_s + 10.0)
    fresh = PeriodFeedforward(dynamics, 0.02, 12.0)
    solved = [fresh.step(0.02 * k, lambda _t: end, 12.0) for k in range(3)]
    np.testing.assert_allclose(kept, [solved[-1]] * len(kept), atol=1e-9)
    np.testing.assert_array_equal(feedforward.state, np.concatenate([end[0], np.zeros(2)]))
    feedforward.step(next(times), trajectory.sample, 11.0)
    assert runs
