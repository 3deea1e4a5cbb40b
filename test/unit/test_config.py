"""The parameter file is the one source, and bad values are refused by name."""

import dataclasses
import math

import pytest

from arm_control import config
from arm_control import parameters
from arm_control.config import ArmConfig, SimConfig
from arm_control.parameters import ParameterError, read_parameter_file


@pytest.fixture
def params():
    return read_parameter_file(parameters.default_parameter_file(), 'sim')


def test_default_file_describes_the_seed_arm(params):
    arm = ArmConfig.from_parameters(params)
    assert (arm.shoulder.length_m, arm.elbow.length_m) == (1.0, 0.8)
    assert (arm.shoulder.mass_kg, arm.elbow.mass_kg) == (30.0, 15.0)
    assert (arm.shoulder.motor_count, arm.elbow.motor_count) == (2, 1)
    assert arm.shoulder.gear_ratio == arm.elbow.gear_ratio == 159.3
    assert arm.shoulder.inertia_about_com_kgm2 == pytest.approx(30.0 * 1.0 ** 2 / 12)
    assert arm.elbow.inertia_about_com_kgm2 == pytest.approx(15.0 * 0.8 ** 2 / 12)
    assert SimConfig.from_parameters(params).initial_position == (1.5708, -1.5708)


@pytest.mark.parametrize('name, value, words', [
    ('shoulder.mass_kg', -30.0, 'must be >= 0'),
    ('elbow.gear_ratio', 0.0, 'must be > 0'),
    ('shoulder.length_m', 'long', 'expected a number'),
    ('motors.seed_cim', [2.42, math.nan, 5330.0, 2.7, 12.0], 'expected finite numbers'),
    ('motors.seed_cim', [2.42, 133.0, 5330.0, 140.0, 12.0], 'free current below'),
    ('shoulder.motor', 'warp_drive', "WPILib's DCMotor catalogue"),
    ('elbow.current_limit_a', -5.0, 'must be >= 0'),
    ('battery.brownout_voltage', 13.0, 'must be below battery.nominal_voltage'),
    ('elbow.motor_count', 1.5, 'expected an integer'),
    ('world.regions.floor', [0.0, 0.0, -1.0, 1.0], 'min < max'),
    ('presets.stow', [0.25], 'expected 2 numbers'),
    ('shoulder.min_angle_rad', 4.0, 'must be below shoulder.max_angle_rad'),
])
def test_a_bad_value_is_refused_naming_the_parameter(params, name, value, words):
    params[name] = value
    with pytest.raises(ParameterError) as error:
        ArmConfig.from_parameters(params)
    assert f"'{name}'" in str(error.value) and words in str(error.value)


def test_a_missing_value_is_refused_naming_the_parameter(params):
    del params['elbow.length_m']
    with pytest.raises(ParameterError, match="'elbow.length_m' is missing"):
        ArmConfig.from_parameters(params)


def test_a_joint_may_name_a_motor_of_wpilibs_catalogue(params):
    params['elbow.motor'] = 'NEO'
    elbow = ArmConfig.from_parameters(params).elbow
    assert elbow.motor.free_speed_rpm == pytest.approx(5676.0, rel=1e-3)   # NEO datasheet
    assert elbow.motor.stall_torque_nm == pytest.approx(2.6, rel=1e-3)


def test_a_zero_current_limit_means_none(params):
    params['shoulder.current_limit_a'] = 0.0
    assert ArmConfig.from_parameters(params).shoulder.current_limit_a == math.inf


def test_a_robot_file_layers_over_the_default_naming_only_what_differs():
    """frc_robot.yaml changes the world, the presets and the gains; everything else is
    arm.yaml's, as ``--params-file arm.yaml --params-file frc_robot.yaml`` gives it."""
    robot = parameters.default_parameter_file('frc_robot.yaml')
    default_arm, default_controller = config.load('controller')
    arm, controller = config.load('controller', robot)
    assert arm.shoulder == default_arm.shoulder and arm.elbow == default_arm.elbow
    assert arm.battery == default_arm.battery
    assert 'tower' in [region.name for region in arm.world.regions]
    assert arm.world.clearance_rad == default_arm.world.clearance_rad
    assert controller.shoulder_pid != default_controller.shoulder_pid
    assert controller.loop_rate_hz == default_controller.loop_rate_hz


def test_a_reserve_that_leaves_the_trajectory_no_volts_is_refused_by_name():
    arm, controller = config.load('controller')
    bad = dataclasses.replace(controller, feedback_voltage_reserve=12.5)
    with pytest.raises(ParameterError, match="'feedback_voltage_reserve' = 12.5"):
        bad.check_against(arm)


def test_an_integer_where_a_float_is_expected_is_fine(params):
    params['shoulder.mass_kg'] = 30
    assert ArmConfig.from_parameters(params).shoulder.mass_kg == 30.0


def test_sim_physics_step_must_be_at_most_a_millisecond(params):
    params['physics_step_s'] = 0.02
    with pytest.raises(ParameterError, match="'physics_step_s' = 0.02: must be <= 0.001"):
        SimConfig.from_parameters(params)


def test_unreadable_file_is_a_clear_error(tmp_path):
    broken = tmp_path / 'broken.yaml'
    broken.write_text('/**:\n  ros__parameters: [unclosed\n')
    with pytest.raises(ParameterError, match='cannot read parameter file'):
        read_parameter_file(broken, 'sim')


def test_every_parameter_has_a_description():
    path = parameters.default_parameter_file()
    for node in ('sim', 'controller', 'planner', 'tour', 'viewer', 'recorder', 'sysid'):
        descriptions = parameters.parameter_descriptions(path, node)
        for name in read_parameter_file(path, node):
            assert descriptions.get(name), f'{name} has no comment in {path.name}'


def test_recorder_settings_are_checked_naming_the_parameter():
    params = read_parameter_file(parameters.default_parameter_file(), 'recorder')
    assert config.RecorderConfig.from_parameters(params).output_dir == ''
    with pytest.raises(ParameterError, match="'flush_period_s' = 0"):
        config.RecorderConfig.from_parameters(dict(params, flush_period_s=0))
    with pytest.raises(ParameterError, match="'output_dir' = 7"):
        config.RecorderConfig.from_parameters(dict(params, output_dir=7))
