"""The CIM model against its datasheet."""

import math

import pytest

from arm_control.model.motor import GearMotor


@pytest.fixture
def cim(arm):
    return GearMotor.from_datasheet(arm.motor)


def test_stall_torque_and_current_at_12_v(cim):
    assert cim.torque_nm(12.0, 0.0) == pytest.approx(2.42, rel=1e-9)
    assert cim.current_a(12.0, 0.0) == pytest.approx(133.0, rel=1e-9)


def test_free_speed_draws_free_current(cim):
    free_speed_rad_s = 5330.0 * 2.0 * math.pi / 60.0
    assert cim.current_a(12.0, free_speed_rad_s) == pytest.approx(2.7, rel=1e-9)
    # torque falls linearly from stall to (almost) nothing at free speed
    assert cim.torque_nm(12.0, free_speed_rad_s) == pytest.approx(2.42 * 2.7 / 133.0, rel=1e-9)


def test_two_motors_give_twice_the_torque(arm):
    one = GearMotor.from_datasheet(arm.motor, count=1, gear_ratio=159.3)
    two = GearMotor.from_datasheet(arm.motor, count=2, gear_ratio=159.3)
    for volts, speed in ((12.0, 0.0), (6.0, 0.5), (-3.0, -1.0)):
        assert two.torque_nm(volts, speed) == pytest.approx(2.0 * one.torque_nm(volts, speed))


def test_reduction_multiplies_torque_and_divides_speed(arm):
    geared = GearMotor.from_datasheet(arm.motor, gear_ratio=159.3)
    cim = GearMotor.from_datasheet(arm.motor)
    assert geared.torque_nm(12.0, 0.0) == pytest.approx(159.3 * 2.42)
    assert geared.torque_nm(12.0, 10.0 / 159.3) == pytest.approx(159.3 * cim.torque_nm(12.0, 10.0))


def test_voltage_for_inverts_torque(arm):
    motor = GearMotor.from_datasheet(arm.motor, count=2, gear_ratio=159.3)
    for torque, speed in ((100.0, 0.0), (-250.0, 1.2), (30.0, -2.0)):
        assert motor.torque_nm(motor.voltage_for(torque, speed), speed) == pytest.approx(torque)
