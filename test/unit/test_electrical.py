"""The robot's electrical limits: battery sag, current limits, brownout (DESIGN.md §4b)."""

import math

from conftest import with_joint
import numpy as np
import pytest

from arm_control.model.dynamics import ArmDynamics
from arm_control.model.electrical import PowerSupply
from arm_control.model.plant import ArmPlant


def supply_for(arm):
    return PowerSupply(arm, ArmDynamics(arm).motors)


def unlimited(arm):
    return with_joint(with_joint(arm, 'shoulder', current_limit_a=math.inf),
                      'elbow', current_limit_a=math.inf)


def test_the_worked_example_of_a_stalled_shoulder_at_its_current_limit(arm):
    """DESIGN.md §4b: two CIMs stalled at 80 A, the elbow at rest."""
    power = supply_for(arm).solve((12.0, 0.0), (0.0, 0.0))
    assert power.applied_v[0] == pytest.approx(12.0 / 133.0 * 80.0, abs=5e-4)     # 7.218 V
    assert power.motor_current_a == pytest.approx((80.0, 0.0))
    assert power.power_w == pytest.approx(1154.9, abs=0.05)
    assert power.bus_voltage == pytest.approx(9.592, abs=5e-4)
    assert power.supply_current_a == pytest.approx(120.4, abs=0.05)
    assert not power.browned_out


def test_every_solution_obeys_the_battery_the_limits_and_the_power_balance(arm):
    supply = supply_for(arm)
    dynamics = ArmDynamics(arm)
    rng = np.random.default_rng(2)
    for _ in range(500):
        command = rng.uniform(-12, 12, 2)
        speed = rng.uniform(-4, 4, 2)
        power = supply.solve(command, speed)
        if power.browned_out:
            continue
        bus = power.bus_voltage
        # V_bus = V_nominal − R·I_supply, with I_supply from the power balance
        assert bus == pytest.approx(12.0 - 0.02 * power.supply_current_a, abs=1e-9)
        drawn = sum(m.count * v * i for m, v, i in zip(
            dynamics.motors, power.applied_v, power.motor_current_a))
        assert power.supply_current_a * bus == pytest.approx(drawn, abs=1e-6)
        for j, motor in enumerate(dynamics.motors):
            assert abs(power.applied_v[j]) <= bus + 1e-9
            # within the limit, unless the back-EMF alone already drives more
            emf = motor.back_emf_v(speed[j])
            if abs(emf) < bus - 80.0 * motor.resistance_ohm:
                assert abs(power.motor_current_a[j]) <= 80.0 + 1e-9
            # the motor controller only ever lowers the magnitude of the command
            assert abs(power.applied_v[j]) <= abs(command[j]) + 1e-9 or \
                abs(power.applied_v[j] - emf) <= 80.0 * motor.resistance_ohm + 1e-9


def test_current_limits_keep_the_bus_above_the_brownout(arm):
    """With |V| ≤ V_bus each motor draws at most its stator current from the battery:
    V_bus ≥ 12 − 0.02·(2 + 1)·80 = 7.2 V > 6.75 V, so 80 A limits never brown out."""
    supply = supply_for(arm)
    assert supply.min_bus_voltage() == pytest.approx(7.2)
    rng = np.random.default_rng(4)
    for _ in range(500):
        power = supply.solve(rng.choice([-12.0, 12.0], 2), rng.uniform(-4, 4, 2))
        assert not power.browned_out and power.bus_voltage >= 7.2 - 1e-9


def test_without_limits_stalled_motors_pull_the_bus_down_to_a_divider(arm):
    """Three stalled CIMs straight on the battery: V_bus = V_n·R/(R + 3·R_battery), a
    voltage divider of the motors' resistance and the battery's."""
    power = supply_for(unlimited(arm)).solve((12.0, 12.0), (0.0, 0.0))
    resistance = 12.0 / 133.0
    assert power.bus_voltage == pytest.approx(12.0 * resistance / (resistance + 3 * 0.02))
    assert power.motor_current_a[0] == pytest.approx(power.bus_voltage / resistance)


def test_without_limits_reversing_at_speed_browns_out(arm):
    """Full reverse at 2 rad/s: each motor sees its back-EMF plus the bus, well over 100 A;
    the battery cannot give that power above 6.75 V, so every output goes to 0 V."""
    power = supply_for(unlimited(arm)).solve((-12.0, -12.0), (2.0, 2.0))
    assert power.browned_out
    assert power.applied_v == (0.0, 0.0) and power.supply_current_a == 0.0
    # ... while the motors' back-EMF still brakes them through the bridges
    assert power.motor_current_a[0] < 0.0 and power.motor_current_a[1] < 0.0


def test_a_motor_driven_past_its_free_speed_charges_the_battery(arm):
    """Back-EMF above the applied voltage: the current reverses, the supply current is
    negative and the bus rises above the battery's open-circuit voltage."""
    power = supply_for(arm).solve((3.0, 0.0), (2.0, 0.0))      # emf ≈ 6.7 V at 2 rad/s
    assert power.motor_current_a[0] < 0.0
    assert power.supply_current_a < 0.0 and power.bus_voltage > 12.0


def test_the_plant_reports_the_bus_and_the_currents(arm):
    plant = ArmPlant(arm, (1.0, -0.5))
    plant.set_voltage((12.0, 12.0))
    plant.advance(0.001)                        # at rest: both current limited
    reading = plant.read()
    assert reading.motor_current_a == pytest.approx((80.0, 80.0), rel=0.05)
    assert 7.2 <= reading.bus_voltage < 12.0
    assert np.all(np.abs(reading.voltage) < 12.0)


def test_a_brownout_is_recorded_with_its_duration(arm):
    plant = ArmPlant(unlimited(arm), (1.0, -0.5))
    plant.reset((1.0, -0.5), (2.0, 2.0))
    plant.set_voltage((-12.0, -12.0))
    plant.advance(0.05)
    assert plant.browned_out_since_s is not None
    plant.set_voltage((0.0, 0.0))
    plant.advance(0.05)
    assert plant.browned_out_since_s is None
    assert len(plant.brownouts) == 1
    brownout = plant.brownouts[0]
    assert brownout.start_s == pytest.approx(0.0) and brownout.duration_s >= 0.04
    assert 0.0 < brownout.disabled_s <= brownout.duration_s


@pytest.mark.parametrize('limited', [True, False])
def test_the_batch_forms_are_the_scalar_form(arm, limited):
    """``solve_many`` is ``solve`` on arrays, brownouts included; where the motor controllers
    lower nothing, ``bus_voltages`` is the bus ``solve`` finds."""
    supply = supply_for(arm if limited else unlimited(arm))
    rng = np.random.default_rng(8)
    command, speed = rng.uniform(-12.0, 12.0, (400, 2)), rng.uniform(-4.0, 4.0, (400, 2))
    bus, applied, browned = supply.solve_many(command, speed)
    alone = [supply.solve(c, w) for c, w in zip(command, speed)]
    np.testing.assert_array_equal(browned, [p.browned_out for p in alone])
    np.testing.assert_allclose(bus, [p.bus_voltage for p in alone], atol=1e-12)
    np.testing.assert_allclose(applied, [p.applied_v for p in alone], atol=1e-12)
    as_is = ~browned & np.all(np.abs(applied - command) < 1e-12, axis=1)
    assert np.count_nonzero(as_is) > 20
    np.testing.assert_allclose(supply.bus_voltages(command[as_is], speed[as_is]), bus[as_is],
                               atol=1e-12)
