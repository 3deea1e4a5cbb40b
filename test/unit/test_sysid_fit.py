"""The fit finds the arm: exactly from exact data, within its stated uncertainty from noisy
data, and the command lag where it is. Runs on the sim's demo arm, in-process, seeded."""

import dataclasses
from pathlib import Path

from conftest import with_joint
import numpy as np
import pytest

from arm_control import config, parameters
from arm_control.model.plant import ArmPlant
from arm_control.model.world import ForbiddenSpace
from arm_control.sysid.excitation import per_motor_current_a
from arm_control.sysid.fit import fit_log, hac_covariance, weighted_least_squares
from arm_control.sysid.quality import assess, identified_values
from arm_control.sysid.regressor import BASE_NAMES, base_parameters, regressor
from arm_control.sysid.settings import SysIdConfig
from arm_control.sysid.simulated import identification_run

CONFIG = Path(__file__).resolve().parents[2] / 'config'


@pytest.fixture(scope='module')
def settings():
    return SysIdConfig.from_parameters(
        parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sysid'))


@pytest.fixture(scope='module')
def demo():
    """The demo arm: arm.yaml with sysid_demo_arm.yaml's heavier forearm and friction."""
    params = parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sim')
    params.update(parameters.read_parameter_file(CONFIG / 'sysid_demo_arm.yaml', 'sim'))
    return config.ArmConfig.from_parameters(params)


@pytest.fixture(scope='module')
def noisy_run(demo, settings, arm):
    return identification_run(demo, arm, settings, seed=4)


def quiet(arm):
    """The same arm with perfect sensors."""
    for joint in ('shoulder', 'elbow'):
        arm = with_joint(arm, joint, potentiometer_noise_rad=0.0, velocity_noise_rad_s=0.0)
    return arm


def fit(run, arm, settings, **changes):
    options = dict(window_s=settings.smoothing_window_s, max_lag_s=settings.max_command_lag_s,
                   min_speed_rad_s=settings.min_speed_rad_s)
    options.update(changes)
    return fit_log(run.log, arm, **options)


def test_least_squares_recovers_the_parameters_from_exact_torques(demo):
    rng = np.random.default_rng(7)
    q = rng.uniform(-3.0, 3.0, (400, 2))
    qd = rng.uniform(-3.0, 3.0, (400, 2))
    qdd = rng.uniform(-20.0, 20.0, (400, 2))
    rows = regressor(demo, q, qd, qdd).reshape(-1, 8)
    truth = base_parameters(demo)
    torque = rows @ truth
    weights = np.tile([1.0, 3.0], 400)
    estimate, residual = weighted_least_squares(rows, torque, weights)
    assert np.allclose(estimate, truth, rtol=1e-9, atol=1e-9)
    # Instruments that differ from the design (but see the same motion) change nothing.
    instruments = regressor(demo, q + 0.01, qd, qdd).reshape(-1, 8)
    estimate, _ = weighted_least_squares(rows, torque, weights, instruments)
    assert np.allclose(estimate, truth, rtol=1e-9, atol=1e-9)
    assert np.max(np.abs(hac_covariance(rows * weights[:, None], residual * weights, 10))) \
        < 1e-12


def test_the_pipeline_finds_the_arm_from_noise_free_samples(demo, arm, settings):
    """Perfect sensors at 50 Hz: only the filtering's approximations remain."""
    run = identification_run(quiet(demo), arm, settings, seed=0)
    result = fit(run, arm, settings)
    truth = base_parameters(demo)
    error = np.abs(result.parameters - truth) / truth
    inertial = [BASE_NAMES.index(n) for n in ('shoulder_inertia', 'elbow_inertia',
                                              'shoulder_moment', 'elbow_moment')]
    assert np.all(error[inertial] < 0.005), dict(zip(BASE_NAMES, error))
    assert np.all(error < 0.03), dict(zip(BASE_NAMES, error))
    assert abs(result.lag_s) < 0.5e-3
    assert np.all(result.residual_rms_v < 0.01)


def test_noisy_samples_give_the_arm_within_the_stated_uncertainty(noisy_run, demo, arm,
                                                                  settings):
    result = fit(noisy_run, arm, settings)
    truth = base_parameters(demo)
    z = (result.parameters - truth) / result.standard_errors
    assert np.all(np.abs(z) < 3.0), dict(zip(BASE_NAMES, np.round(z, 2)))
    # ... and the uncertainty is small enough to matter: masses to a per cent, friction to
    # a fifth of its value.
    relative = result.standard_errors / truth
    assert np.all(relative[:4] < 0.02) and np.all(relative[4:] < 0.2), relative


def test_least_squares_without_the_plan_is_biased_where_the_instruments_are_not(
        noisy_run, demo, arm, settings):
    """Closed loop: the noisy accelerations pull least squares' inertias down, the more the
    shorter the smoothing window (at 0.42 s, well beyond the instrumented estimate's error)."""
    without_plan = dataclasses.replace(noisy_run, log=dataclasses.replace(
        noisy_run.log, reference_time_s=np.zeros(0), reference_rad=np.zeros((0, 2))))
    truth = base_parameters(demo)
    inertia = BASE_NAMES.index('elbow_inertia')
    plain = fit(without_plan, arm, settings, max_lag_s=0.0, window_s=0.42).parameters[inertia]
    instrumented = fit(noisy_run, arm, settings, max_lag_s=0.0, window_s=0.42).parameters[inertia]
    assert abs(instrumented - truth[inertia]) < abs(plain - truth[inertia])


def test_a_command_lag_is_found(noisy_run, demo, arm, settings):
    """Commands that took effect 20 ms after they were logged (a slow bus)."""
    log = noisy_run.log
    delayed = dataclasses.replace(noisy_run, log=dataclasses.replace(
        log, command_time_s=log.command_time_s - 0.020,
        reference_time_s=log.reference_time_s - 0.020))
    result = fit(delayed, arm, settings)
    assert result.lag_s == pytest.approx(0.020, abs=0.002)
    z = (result.parameters - base_parameters(demo)) / result.standard_errors
    assert np.all(np.abs(z) < 3.0)


def test_the_identification_run_is_safe_and_short(noisy_run, demo, settings):
    """On the true arm: never in forbidden space, no motor over max_current_a, under 60 s."""
    true_state = noisy_run.true_state
    assert np.all(ForbiddenSpace(demo).is_free(true_state[:, :2]))
    plant = ArmPlant(demo, settings.centre_rad)
    for joint in range(2):
        current = per_motor_current_a(plant.dynamics, demo, joint,
                                      noisy_run.log.voltage_v[:, joint], true_state[:, 2 + joint])
        assert np.max(np.abs(current)) <= settings.max_current_a + 1.0   # noisy velocity
    assert noisy_run.arm_time_s < 60.0
    assert noisy_run.session.stopped is None


def test_stalls_of_the_command_stream_are_ridden_through_within_the_current_cap(
        demo, arm, settings):
    """The node starved of CPU for 0.45 s three times (in the elbow's slow sweeps, the
    multi-sine and the elbow's fast sweeps): the robot gets the last command, then 0 V. The
    excitation rejoins the plan each time instead of stopping, never enters forbidden space,
    keeps every motor under max_current_a, and the fit (which leaves the stalls out) still
    finds the arm."""
    stalls = ((12.0, 0.45), (27.5, 0.45), (39.0, 0.45))
    run = identification_run(demo, arm, settings, seed=2, stalls=stalls)
    assert run.session.stopped is None and len(run.session.stalls) == 3
    assert np.all(ForbiddenSpace(demo).is_free(run.true_state[:, :2]))
    assert np.all(run.peak_current_a <= settings.max_current_a)
    assert run.arm_time_s < 60.0
    result = fit(run, arm, settings)
    z = (result.parameters - base_parameters(demo)) / result.standard_errors
    assert np.all(np.abs(z) < 3.0), dict(zip(BASE_NAMES, np.round(z, 2)))


def test_a_joint_that_never_moves_identifies_nothing_of_its_own(demo, arm, settings):
    """Only the elbow excited, the shoulder held: the shoulder's inertia, moment and
    friction are never seen (σ = ∞), are reported with that reason and are not written;
    the elbow's are found."""
    still = dataclasses.replace(settings, quasistatic_range_rad=(0.0, 1.0),
                                multisine_amplitude_rad=(0.0, 0.9), dynamic_step_rad=(0.0, 0.7))
    result = fit(identification_run(demo, arm, still, seed=3), arm, settings)
    quality = assess(result, arm)
    shoulder = [BASE_NAMES.index(n) for n in ('shoulder_inertia', 'shoulder_moment',
                                              'shoulder_viscous', 'shoulder_coulomb')]
    assert np.all(np.isinf(result.standard_errors[shoulder]))
    assert set(quality.unidentified) == {BASE_NAMES[k] for k in shoulder}
    assert all(quality.reasons[k] is not None for k in shoulder)
    values, _ = identified_values(result, arm)
    assert set(values.values) == {'elbow.viscous_friction_nm_s_per_rad',
                                  'elbow.coulomb_friction_nm'}
    elbow = [BASE_NAMES.index(n) for n in ('elbow_inertia', 'elbow_moment', 'elbow_viscous',
                                           'elbow_coulomb')]
    z = (result.parameters - base_parameters(demo))[elbow] / result.standard_errors[elbow]
    assert np.all(np.abs(z) < 4.0), z                  # one run: a wide bound
