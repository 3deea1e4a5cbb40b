"""The controller's settings are checked whole, at start and at run time: a change the loop
could not take is refused with the parameter named, and gains are bounded by what the loop
holds at its rate with one period of delay."""

import dataclasses

import numpy as np
import pytest

from arm_control.control.closed_loop import ClosedLoop
from arm_control.control.gain_limits import gain_problem, joint_loops
from arm_control.control.live_settings import changed_names, controller_settings
from arm_control.parameters import ParameterError, read_parameter_files

START = np.array([1.5708, -1.5708])


@pytest.fixture(scope='module')
def params():
    return read_parameter_files([], 'controller')


def with_values(params, **values):
    return {**params, **{name.replace('__', '.'): v for name, v in values.items()}}


def test_the_defaults_are_taken(params):
    settings = controller_settings(params)
    assert np.all(settings.max_acceleration_rad_s2 > 0.0)
    assert changed_names(settings, settings) == []


@pytest.mark.parametrize('values, named', [
    # Below the battery's 12 V, but it leaves the shoulder's current limit no volts above
    # the back-EMF: the retune raised outside the callback and the controller died.
    (dict(feedback_voltage_reserve=8.0), 'current_limit_a'),
    # Leaves the shoulder no sure acceleration in some pose: no brake, no hold.
    (dict(feedback_voltage_reserve=5.0), 'feedback_voltage_reserve'),
    (dict(shoulder_pid=[1e6, 0.0, 0.0]), 'shoulder_pid'),
    (dict(elbow_pid=[0.0, 10.0, 0.0]), 'elbow_pid'),          # an integral alone: unstable
    (dict(presets__stow=[5.0, 5.0]), 'presets.stow'),          # out of reach
])
def test_a_combination_the_loop_cannot_take_is_refused_with_the_parameter_named(
        params, values, named):
    with pytest.raises(ParameterError, match=named.replace('.', r'\.')):
        controller_settings(with_values(params, **values))


def test_a_change_names_what_changed(params):
    old = controller_settings(params)
    new = controller_settings(with_values(params, dwell_s=0.5, presets__stow=[0.3, 0.4]), old)
    assert changed_names(old, new) == ['dwell_s', 'presets']
    assert new.max_acceleration_rad_s2 is old.max_acceleration_rad_s2        # kept as found
    braking = controller_settings(with_values(params, feedback_voltage_reserve=1.0), old)
    assert np.all(braking.max_acceleration_rad_s2 < old.max_acceleration_rad_s2)


def instability_scales(arm, config):
    loops = joint_loops(arm, config.period_s)
    return [loop.instability_scale(gains) for loop, gains in
            zip(loops, (config.shoulder_pid, config.elbow_pid))]


def test_gains_above_the_bound_are_refused_with_the_bound_below_it_taken(params):
    settings = controller_settings(params)
    arm, config = settings.arm, settings.config
    scale = instability_scales(arm, config)[0]
    assert 1.0 < scale < 10.0                      # the defaults: inside, not far inside
    bound = [g * scale for g in config.shoulder_pid]
    above = dataclasses.replace(config, shoulder_pid=tuple(1.01 * g for g in bound))
    problem = gain_problem(arm, above)
    assert problem is not None and 'shoulder_pid' in problem
    assert f'{bound[0]:.4g}' in problem            # the bound itself, to set it by
    below = dataclasses.replace(config, shoulder_pid=tuple(0.99 * g for g in bound))
    assert gain_problem(arm, below) is None


@pytest.mark.parametrize('gains', [(90.0, 10.0, 4.0), (40.0, 0.0, 0.0), (0.0, 0.0, 2.0),
                                   (300.0, 50.0, 2.0)])
def test_the_bound_is_where_the_modelled_loop_stops_decaying(params, gains):
    """The model iterated as difference equations, not through its eigenvalues: a kick's
    motion and command die out below the bound and grow above it (with damping alone, the
    arm comes to rest wherever the kick left it)."""
    settings = controller_settings(params)
    loop = joint_loops(settings.arm, settings.config.period_s)[1]
    scale = loop.instability_scale(gains)

    def kick_after(factor, periods=3000):
        kp, ki, kd = (factor * scale * g for g in gains)
        x, u, z = np.array([0.01, 0.1]), 0.0, 0.0
        for _ in range(periods):
            v = -kp * x[0] - kd * x[1] + z
            z -= ki * loop.period_s * x[0]
            x, u = loop.phi @ x + loop.gamma * u, v
        return abs(x[1]) + abs(u)
    assert kick_after(0.97) < 1e-3
    assert kick_after(1.03) > 1.0


def hold(arm, config, seconds=3.0):
    """The arm held at its start in closed loop with the simulated plant: the spread of the
    last second's commands (V) and the worst angle error then (rad)."""
    loop = ClosedLoop(arm, config, seed=1, command_delay_s=0.005, reading_age_s=0.005)
    errors = []
    for _ in range(round(seconds / config.period_s)):
        loop.step()
        errors.append(np.max(np.abs(loop.true_q - START)))
    late = round(1.0 / config.period_s)
    return float(np.max(np.std(loop.voltages[-late:], axis=0))), max(errors[-late:])


def test_gains_at_the_bound_keep_a_simulated_hold_stable(params):
    """Both joints at their bound at once hold the arm still; three times it, the loop
    rings at the battery's volts (the bound is not far below what the arm holds)."""
    settings = controller_settings(params)
    arm, config = settings.arm, settings.config
    scales = instability_scales(arm, config)

    def scaled(factor):
        return dataclasses.replace(
            config, shoulder_pid=tuple(factor * scales[0] * g for g in config.shoulder_pid),
            elbow_pid=tuple(factor * scales[1] * g for g in config.elbow_pid))
    spread_v, error_rad = hold(arm, scaled(0.99))
    assert spread_v < 1.0 and error_rad < 0.01
    ringing_v, _ = hold(arm, scaled(3.0))
    assert ringing_v > 3.0
