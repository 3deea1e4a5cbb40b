"""The CIM model against its datasheet, and WPILib's motor catalogue."""

import math

import pytest

from wpimath.system.plant import DCMotor

from arm_control.config import wpilib_motors
from arm_control.model.motor import GearMotor


@pytest.fixture
def cim(arm):
    return GearMotor.from_datasheet(arm.shoulder.motor)


def test_stall_torque_and_current_at_12_v(cim):
    assert cim.torque_nm(12.0, 0.0) == pytest.approx(2.42, rel=1e-9)
    assert cim.current_a(12.0, 0.0) == pytest.approx(133.0, rel=1e-9)  # per motor


def test_free_speed_draws_free_current(cim):
    free_speed_rad_s = 5330.0 * 2.0 * math.pi / 60.0
    assert cim.current_a(12.0, free_speed_rad_s) == pytest.approx(2.7, rel=1e-9)
    # torque falls linearly from stall to (almost) nothing at free speed
    assert cim.torque_nm(12.0, free_speed_rad_s) == pytest.approx(2.42 * 2.7 / 133.0, rel=1e-9)


def test_two_motors_give_twice_the_torque(arm):
    one = GearMotor.from_datasheet(arm.shoulder.motor, count=1, gear_ratio=159.3)
    two = GearMotor.from_datasheet(arm.shoulder.motor, count=2, gear_ratio=159.3)
    for volts, speed in ((12.0, 0.0), (6.0, 0.5), (-3.0, -1.0)):
        assert two.torque_nm(volts, speed) == pytest.approx(2.0 * one.torque_nm(volts, speed))


def test_reduction_multiplies_torque_and_divides_speed(arm):
    geared = GearMotor.from_datasheet(arm.shoulder.motor, gear_ratio=159.3)
    cim = GearMotor.from_datasheet(arm.shoulder.motor)
    assert geared.torque_nm(12.0, 0.0) == pytest.approx(159.3 * 2.42)
    assert geared.torque_nm(12.0, 10.0 / 159.3) == pytest.approx(159.3 * cim.torque_nm(12.0, 10.0))


def test_voltage_for_inverts_torque(arm):
    motor = GearMotor.from_datasheet(arm.shoulder.motor, count=2, gear_ratio=159.3)
    for torque, speed in ((100.0, 0.0), (-250.0, 1.2), (30.0, -2.0)):
        assert motor.torque_nm(motor.voltage_for(torque, speed), speed) == pytest.approx(torque)


@pytest.mark.parametrize('name', ['CIM', 'NEO', 'NEO550', 'falcon500', 'krakenX60', 'neoVortex',
                                  'miniCIM', 'bag', 'vex775Pro'])
def test_a_motor_named_from_the_catalogue_has_wpilibs_constants(name):
    """R, Kv and Kt derived from the catalogue's datasheet match WPILib's own."""
    wpilib = getattr(DCMotor, name)(1)
    motor = GearMotor.from_datasheet(wpilib_motors()[name])
    assert motor.resistance_ohm == pytest.approx(wpilib.R, rel=1e-9)
    assert motor.kv_rad_per_s_per_v == pytest.approx(wpilib.Kv, rel=1e-9)
    assert motor.kt_nm_per_a == pytest.approx(wpilib.Kt, rel=1e-9)
