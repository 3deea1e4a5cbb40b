"""A robot's .wpilog as an identification log: written as the project's robot side logs it
(``arm_control.frc.wpilog``), read back sample for sample, and fitted with the quality check;
an AdvantageKit-style log with a double per joint reads the same."""

from pathlib import Path

import numpy as np
import pytest
from wpiutil import DataLogWriter
from wpiutil.log import DoubleLogEntry

from arm_control import config, parameters
from arm_control.frc import contract
from arm_control.frc.wpilog import RunLog
from arm_control.sysid.fit import fit_log
from arm_control.sysid.quality import assess
from arm_control.sysid.regressor import base_parameters
from arm_control.sysid.settings import SysIdConfig
from arm_control.sysid.simulated import identification_run
from arm_control.sysid.wpilog import ENTRIES, read_recording, read_wpilog

CONFIG = Path(__file__).resolve().parents[2] / 'config'
PERIOD_S = 0.02


@pytest.fixture(scope='module')
def settings():
    return SysIdConfig.from_parameters(
        parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sysid'))


@pytest.fixture(scope='module')
def demo_run(settings, arm):
    params = parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sim')
    params.update(parameters.read_parameter_file(CONFIG / 'sysid_demo_arm.yaml', 'sim'))
    demo = config.ArmConfig.from_parameters(params)
    return demo, identification_run(demo, arm, settings, seed=5)


def us(time_s):
    """µs on the log's clock, from 1 s (a time of 0 means 'now' to DataLog)."""
    return int(round(1e6 * (1.0 + time_s)))


def held_at(log, times_s):
    """The command in force at each of ``times_s`` (the latest at or before it; 0 V before
    the first), as a robot's reading reports what its loop applies from then on."""
    index = np.searchsorted(log.command_time_s, times_s, side='right') - 1
    return np.where(index[:, None] >= 0, log.voltage_v[np.maximum(index, 0)], 0.0)


def test_the_default_entries_are_the_reading_fields():
    field = contract.READING_FIELD
    names = ('position_rad', 'velocity_rad_s', 'applied_voltage_v', 'bus_voltage_v')
    assert ENTRIES == tuple(f'{contract.READING.name}[{field[name].start}:'
                            f'{field[name].start + field[name].size}]' for name in names)


def test_a_robot_wpilog_reads_back_and_identifies_the_arm(tmp_path, demo_run, arm, settings):
    demo, run = demo_run
    log = run.log
    robot = RunLog(tmp_path / 'robot.wpilog')
    field = contract.READING_FIELD
    for t, q, qd, v in zip(log.joint_time_s, log.position_rad, log.velocity_rad_s,
                           held_at(log, log.joint_time_s)):
        reading = np.full(contract.READING_SIZE, np.nan)
        for name, value in (('time_us', us(t)), ('enabled', 1.0), ('position_rad', q),
                            ('velocity_rad_s', qd), ('applied_voltage_v', v)):
            reading[field[name].indices] = value
        robot.append(contract.READING.name, reading, us(t))
    robot.close()
    back = read_recording(robot.path)
    assert np.allclose(back.position_rad, log.position_rad)
    assert np.allclose(back.voltage_v, held_at(log, log.joint_time_s))
    assert np.allclose(back.command_time_s - 1.0, log.joint_time_s, atol=2e-6)
    assert not back.has_reference()
    # No plan in a robot's log: least squares, whose inertias the closed loop pulls down a
    # little; the moments and friction are found, and the quality check passes them.
    fit = fit_log(back, arm, settings.smoothing_window_s, settings.max_command_lag_s,
                  settings.min_speed_rad_s)
    assert not fit.instrumented
    error = np.abs(fit.parameters - base_parameters(demo)) / base_parameters(demo)
    assert np.all(error[:2] < 0.05) and np.all(error[2:4] < 0.01) and np.all(error[4:] < 0.25), \
        error
    assert np.all(assess(fit, arm).identified)


def test_a_double_per_joint_reads_as_a_pair(tmp_path):
    path = tmp_path / 'akit.wpilog'
    writer = DataLogWriter(str(path))
    names = ['/RealOutputs/Arm/ShoulderRad', '/RealOutputs/Arm/ElbowRad',
             '/RealOutputs/Arm/ShoulderVolts', '/RealOutputs/Arm/ElbowVolts']
    entries = [DoubleLogEntry(writer, name) for name in names]
    for k in range(100):
        for entry, value in zip(entries, (0.01 * k, -0.02 * k, 1.0 + k, -2.0 - k)):
            entry.append(value, us(PERIOD_S * k))
    writer.stop()
    log = read_wpilog(path, ('|'.join(names[:2]), '', '|'.join(names[2:]), ''))
    assert np.allclose(log.position_rad[:, 1], -2.0 * log.position_rad[:, 0])
    assert np.allclose(log.voltage_v[:, 0], 1.0 + np.arange(100))
    assert np.all(np.isnan(log.velocity_rad_s))
    with pytest.raises(ValueError, match='applied voltages'):
        read_wpilog(path)                   # the project's names are not in it
