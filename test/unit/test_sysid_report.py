"""What identification writes: an overlay that gives the identified π back, with honest ±1σ."""

import dataclasses
from pathlib import Path

from conftest import with_joint
import numpy as np
import pytest
import yaml

from arm_control import config, parameters
from arm_control.sysid.fit import FitResult
from arm_control.sysid.quality import assess, identified_values
from arm_control.sysid.regressor import base_parameters, realise, with_values
from arm_control.sysid.report import overlay_yaml, physical_uncertainty, plot_fit

CONFIG = Path(__file__).resolve().parents[2] / 'config'
IDENTIFIED = {f'{joint}.{field}' for joint in ('shoulder', 'elbow')
              for field in ('mass_kg', 'com_from_joint_m', 'inertia_about_com_kgm2',
                            'viscous_friction_nm_s_per_rad', 'coulomb_friction_nm')}


@pytest.fixture
def demo():
    params = parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sim')
    params.update(parameters.read_parameter_file(CONFIG / 'sysid_demo_arm.yaml', 'sim'))
    return config.ArmConfig.from_parameters(params)


def a_fit(parameters, relative_sigma=0.01) -> FitResult:
    t = np.linspace(0.0, 10.0, 200)
    volts = np.column_stack([np.sin(t), np.cos(t)])
    return FitResult(
        parameters=parameters, covariance=np.diag((relative_sigma * parameters + 1e-3) ** 2),
        lag_s=0.001, lag_sigma_s=0.0005, instrumented=True, residual_rms_nm=np.array([5.0, 2.0]),
        residual_rms_v=np.array([0.08, 0.06]), measured_rms_v=np.array([1.7, 2.3]),
        samples=200, duration_s=10.0, condition_number=4.0, time_s=t, measured_v=volts,
        predicted_v=volts + 0.05, nominal_v=0.5 * volts, column_rms=np.ones(8),
        torque_rms_nm=np.array([100.0, 30.0]), moving_samples=np.full((2, 2), 100))


def test_the_overlay_names_only_what_was_identified_and_gives_it_back(arm, demo, tmp_path):
    fit = a_fit(base_parameters(demo))
    realisation = realise(fit.parameters, arm)
    path = tmp_path / 'identified_params.yaml'
    path.write_text(overlay_yaml(realisation, fit, arm, 'a test'))
    document = yaml.safe_load(path.read_text())
    assert list(document) == ['/**']
    overlay = parameters.read_parameter_file(path, 'controller')
    assert set(overlay) == IDENTIFIED
    layered = parameters.read_parameter_file(CONFIG / 'arm.yaml', 'controller')
    layered.update(overlay)
    written = config.ArmConfig.from_parameters(layered)
    assert np.allclose(base_parameters(written), fit.parameters, rtol=1e-5)
    lines = [line for line in path.read_text().splitlines() if line.startswith('      ')]
    assert len(lines) == len(IDENTIFIED) and all('+/-' in line for line in lines)


def test_uncertainty_of_a_realised_value_matches_sampling(arm, demo):
    """σ carried through realise's Jacobian is the spread of realise over π drawn from
    the covariance (small σ: nearly linear)."""
    fit = a_fit(base_parameters(demo), relative_sigma=0.002)
    sigma = physical_uncertainty(fit.parameters, fit.covariance, arm)
    rng = np.random.default_rng(11)
    draws = rng.multivariate_normal(fit.parameters, fit.covariance, size=4000)
    sampled = {name: np.std([realise(d, arm).values[name] for d in draws])
               for name in ('elbow.mass_kg', 'elbow.com_from_joint_m', 'shoulder.mass_kg')}
    for name, spread in sampled.items():
        assert sigma[name] == pytest.approx(spread, rel=0.1), name


def test_the_plot_is_a_png_of_the_size_asked(demo, tmp_path):
    path = tmp_path / 'fit.png'
    plot_fit(a_fit(base_parameters(demo)), path, size_px=(800, 600))
    header = path.read_bytes()[:24]
    assert header[:8] == b'\x89PNG\r\n\x1a\n'
    assert int.from_bytes(header[16:20], 'big') == 800
    assert int.from_bytes(header[20:24], 'big') == 600


def test_an_identified_arm_is_the_robot_file_with_the_values_changed(arm, demo):
    values = realise(base_parameters(demo), arm).values
    changed = with_values(arm, values)
    assert changed.elbow.mass_kg == pytest.approx(values['elbow.mass_kg'])
    assert changed.elbow.length_m == arm.elbow.length_m and changed.world == arm.world


def test_what_the_data_leave_open_is_reported_and_not_written(arm, demo, tmp_path):
    """The elbow's Coulomb friction known only to ±60 % and within 2σ of the file's 0: not
    written, with its reason; a shoulder friction near 0 while the file says 10 N m is."""
    values = base_parameters(demo)
    values[5] = 0.05                                    # shoulder Coulomb: about none ...
    fit = a_fit(values)
    sigma = np.sqrt(np.diag(fit.covariance))
    sigma[5] = 0.1                                      # ... and known to ±0.2 N m
    sigma[7] = 0.6 * values[7]                          # elbow Coulomb: hardly known
    fit = dataclasses.replace(fit, covariance=np.diag(sigma ** 2),
                              moving_samples=np.array([[100, 100], [0, 300]]))
    arm = with_joint(arm, 'shoulder', coulomb_friction_nm=10.0)
    quality = assess(fit, arm)
    assert list(quality.identified) == [True] * 7 + [False]
    assert quality.reasons[7] is not None and quality.reasons[:7] == (None,) * 7
    realisation, _ = identified_values(fit, arm)
    assert set(realisation.values) == IDENTIFIED - {'elbow.coulomb_friction_nm'}
    path = tmp_path / 'identified_params.yaml'
    path.write_text(overlay_yaml(realisation, fit, arm, 'a test'))
    assert set(parameters.read_parameter_file(path, 'controller')) == set(realisation.values)
    # An inertial base parameter left open: no mass, centre of mass or inertia at all.
    sigma[1] = 0.5 * values[1]
    realisation, quality = identified_values(
        dataclasses.replace(fit, covariance=np.diag(sigma ** 2)), arm)
    assert not quality.inertial_identified
    assert set(realisation.values) == {'shoulder.viscous_friction_nm_s_per_rad',
                                       'shoulder.coulomb_friction_nm',
                                       'elbow.viscous_friction_nm_s_per_rad'}
