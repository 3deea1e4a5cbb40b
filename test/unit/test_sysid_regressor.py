"""The base parameters: τ = Y·π is the model's inverse dynamics, and what motion cannot see."""

import math

from conftest import with_joint
import numpy as np
import pytest

from arm_control.model.dynamics import ArmDynamics
from arm_control.sysid.regressor import (base_parameters, RealisationError, realise,
                                         regressor, with_values)


def random_arm(arm, rng):
    """The default arm with every inertial and friction parameter drawn at random."""
    for joint in ('shoulder', 'elbow'):
        length = getattr(arm, joint).length_m
        arm = with_joint(arm, joint, mass_kg=rng.uniform(2.0, 40.0),
                         com_from_joint_m=rng.uniform(0.0, length),
                         inertia_about_com_kgm2=rng.uniform(0.01, 3.0),
                         viscous_friction_nm_s_per_rad=rng.uniform(0.0, 20.0),
                         coulomb_friction_nm=rng.uniform(0.0, 15.0))
    return arm


def model_torque(arm, q, qd, qdd):
    """What the motors must give: M(θ)θ̈ + C(θ, θ̇)θ̇ + τg(θ) + friction, from ArmDynamics."""
    dynamics = ArmDynamics(arm)
    return np.array([np.add(dynamics.inverse_dynamics(a, b, c), dynamics.friction_torque(b))
                     for a, b, c in zip(q, qd, qdd)])


def test_regressor_times_base_parameters_is_the_inverse_dynamics(arm):
    rng = np.random.default_rng(15)
    for _ in range(20):
        truth = random_arm(arm, rng)
        q = rng.uniform(-math.pi, math.pi, (50, 2))
        qd = rng.uniform(-4.0, 4.0, (50, 2))
        qdd = rng.uniform(-30.0, 30.0, (50, 2))
        expected = model_torque(truth, q, qd, qdd)
        got = regressor(truth, q, qd, qdd) @ base_parameters(truth)
        assert np.max(np.abs(got - expected)) <= 1e-9 * max(1.0, np.max(np.abs(expected)))


def test_arms_with_the_same_base_parameters_move_alike(arm):
    """Motion cannot tell them apart: a heavier forearm with its centre of mass nearer the
    elbow (same m·r and m·r² + I), the upper arm making up m·La and m·La²."""
    first = with_joint(arm, 'elbow', mass_kg=20.0, com_from_joint_m=0.5,
                       inertia_about_com_kgm2=1.0)
    mass, radius = 25.0, 0.4                                    # m·r = 10 as before
    second = with_joint(first, 'elbow', mass_kg=mass, com_from_joint_m=radius,
                        inertia_about_com_kgm2=20.0 * 0.25 + 1.0 - mass * radius ** 2)
    # The upper arm takes back the forearm's 5 kg at the elbow: ma·ra and ma·ra² + Ia.
    upper = first.shoulder
    moment = upper.mass_kg * upper.com_from_joint_m - 5.0 * upper.length_m
    second = with_joint(second, 'shoulder', com_from_joint_m=moment / upper.mass_kg,
                        inertia_about_com_kgm2=(upper.inertia_about_com_kgm2
                                                + upper.mass_kg * upper.com_from_joint_m ** 2
                                                - 5.0 * upper.length_m ** 2
                                                - moment ** 2 / upper.mass_kg))
    assert np.allclose(base_parameters(first), base_parameters(second), rtol=1e-12)
    rng = np.random.default_rng(2)
    q, qd, qdd = rng.uniform(-3.0, 3.0, (3, 40, 2))
    assert np.allclose(model_torque(first, q, qd, qdd), model_torque(second, q, qd, qdd),
                       rtol=1e-10, atol=1e-9)


def test_realised_parameters_give_back_the_base_parameters(arm):
    rng = np.random.default_rng(3)
    for _ in range(30):
        truth = random_arm(arm, rng)
        base = base_parameters(truth)
        written = with_values(arm, realise(base, arm).values)
        assert np.allclose(base_parameters(written), base, rtol=1e-9, atol=1e-12)


def test_a_link_of_the_files_shape_is_realised_as_it_is(arm):
    """A forearm that is the file's uniform rod (I/m = L²/12), only heavier and its centre
    of mass further out, comes back exactly: mass, centre of mass and inertia."""
    length = arm.elbow.length_m
    truth = with_joint(arm, 'elbow', mass_kg=22.0, com_from_joint_m=0.55,
                       inertia_about_com_kgm2=22.0 * length ** 2 / 12.0)
    values = realise(base_parameters(truth), arm).values
    assert values['elbow.mass_kg'] == pytest.approx(22.0, rel=1e-9)
    assert values['elbow.com_from_joint_m'] == pytest.approx(0.55, rel=1e-9)
    assert values['shoulder.mass_kg'] == pytest.approx(arm.shoulder.mass_kg, rel=1e-9)


def test_base_parameters_no_arm_file_can_hold_are_refused(arm):
    base = base_parameters(arm)
    behind_the_elbow = base.copy()
    behind_the_elbow[3] = -1.0
    with pytest.raises(RealisationError, match='behind the elbow'):
        realise(behind_the_elbow, arm)
    no_inertia = base.copy()
    no_inertia[1] = -0.5
    with pytest.raises(RealisationError, match='not positive'):
        realise(no_inertia, arm)


def test_negative_friction_is_written_as_none(arm):
    base = base_parameters(arm)
    base[5] = -0.3                                   # shoulder Coulomb: noise about 0
    realisation = realise(base, arm)
    assert realisation.values['shoulder.coulomb_friction_nm'] == 0.0
    assert any('written as 0' in note for note in realisation.notes)
