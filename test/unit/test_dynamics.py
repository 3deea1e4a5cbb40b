"""Physical truths of the coupled two-link model and its integration."""

import math

from conftest import with_joint
import numpy as np
import pytest

from arm_control.model.dynamics import ArmDynamics, rk4
from arm_control.model.plant import ArmPlant

STEP_S = 0.001


def integrate_unpowered(dynamics, state, duration_s):
    """τ = 0 at the joints: motors disconnected, no friction."""
    for _ in range(round(duration_s / STEP_S)):
        state = rk4(dynamics.derivative_with_torque, state, (0.0, 0.0), STEP_S)
    return state


@pytest.mark.parametrize('start', [(0.3, 0.5), (1.0, -2.0), (2.5, 1.0)])
def test_unpowered_swing_conserves_energy(arm, start):
    dynamics = ArmDynamics(arm)
    state = [start[0], start[1], 0.0, 0.0]
    energy = dynamics.energy_j(state)
    swing_j = energy - dynamics.energy_j([-math.pi / 2, 0.0, 0.0, 0.0])  # energy to the bottom
    for _ in range(10):                     # 10 s in 1 s pieces, checked along the way
        state = integrate_unpowered(dynamics, state, 1.0)
        assert abs(dynamics.energy_j(state) - energy) < 1e-3 * swing_j
    assert max(abs(state[2]), abs(state[3])) > 1.0   # it really swung


def test_shorted_motors_only_take_energy_out(arm):
    """At 0 V the motors' back-EMF brakes: energy never rises."""
    dynamics = ArmDynamics(arm)
    state = [0.2, 0.3, 0.0, 0.0]
    energy = dynamics.energy_j(state)
    for _ in range(2000):
        state = rk4(dynamics.derivative, state, (0.0, 0.0), STEP_S)
        now = dynamics.energy_j(state)
        assert now <= energy + 1e-9
        energy = now
    assert state[0] < 0.1                  # and gravity still pulls it down


@pytest.mark.parametrize('position', [(0.0, 0.0), (0.8, -1.2), (2.0, 0.9), (1.5708, -1.5708)])
def test_holding_voltage_holds_the_arm(arm, position):
    plant = ArmPlant(arm, position)
    plant.set_voltage(plant.dynamics.voltage_for(position, (0.0, 0.0), (0.0, 0.0)))
    plant.advance(2.0)
    drift = np.abs(np.array(plant.state[:2]) - np.array(position))
    assert np.all(drift < math.radians(0.5)), drift


@pytest.mark.parametrize('angle', [0.0, 0.7, -0.3, 2.0])
def test_massless_forearm_leaves_a_single_rod(arm, angle):
    """α = −(3/2)·g·cos θ / L for a uniform rod pivoting at one end.

    The forearm keeps its own inertia about its centre (else M is singular), but with no
    mass it adds neither gravity nor inertia about the shoulder once the elbow is free.
    """
    rod = with_joint(arm, 'elbow', mass_kg=0.0)
    dynamics = ArmDynamics(rod)
    alpha = dynamics.derivative([angle, 0.4, 0.0, 0.0], (0.0, 0.0))[2]
    assert alpha == pytest.approx(-1.5 * 9.81 * math.cos(angle) / 1.0, rel=1e-9, abs=1e-12)


def test_inverse_dynamics_inverts_forward_dynamics(arm):
    dynamics = ArmDynamics(arm)
    rng = np.random.default_rng(7)
    for _ in range(200):
        q, qd, torque = rng.uniform(-3, 3, 2), rng.uniform(-4, 4, 2), rng.uniform(-400, 400, 2)
        qdd = dynamics.acceleration(q, qd, torque)
        assert dynamics.inverse_dynamics(q, qd, qdd) == pytest.approx(tuple(torque), abs=1e-9)


def test_feedforward_voltage_produces_the_asked_acceleration(arm):
    dynamics = ArmDynamics(arm)
    rng = np.random.default_rng(3)
    for _ in range(100):
        q, qd, qdd = rng.uniform(-3, 3, 2), rng.uniform(-2, 2, 2), rng.uniform(-5, 5, 2)
        volts = dynamics.voltage_for(q, qd, qdd)
        state = [q[0], q[1], qd[0], qd[1]]
        assert dynamics.derivative(state, volts)[2:] == pytest.approx(list(qdd), abs=1e-9)


def test_mass_matrix_is_symmetric_positive_definite(arm):
    dynamics = ArmDynamics(arm)
    for elbow in np.linspace(-math.pi, math.pi, 37):
        mass = dynamics.mass_matrix((0.0, elbow))
        assert np.allclose(mass, mass.T)
        assert np.all(np.linalg.eigvalsh(mass) > 0.0)


def test_hard_stops_hold_the_arm_in_range(arm):
    plant = ArmPlant(arm, (0.2, 0.0))
    plant.set_voltage((-12.0, 12.0))            # drive both joints into their stops
    plant.advance(3.0)
    assert plant.state[0] == pytest.approx(arm.shoulder.min_angle_rad)
    assert plant.state[1] == pytest.approx(arm.elbow.max_angle_rad)
    assert plant.state[2] == 0.0 and plant.state[3] == 0.0


def test_commands_are_clamped_to_the_battery_and_nan_refused(arm):
    plant = ArmPlant(arm, (1.0, 0.0))
    plant.set_voltage((30.0, -30.0))
    assert plant.command == (12.0, -12.0)
    with pytest.raises(ValueError):
        plant.set_voltage((math.nan, 0.0))
    assert plant.command == (12.0, -12.0)


def test_the_batch_form_is_the_scalar_form(arm):
    """One model: the arrays the timing uses give what the sim integrates, state by state."""
    dynamics = ArmDynamics(with_joint(with_joint(arm, 'elbow', coulomb_friction_nm=3.0),
                                      'shoulder', viscous_friction_nm_s_per_rad=20.0))
    rng = np.random.default_rng(5)
    x = rng.uniform(-3, 3, (50, 4))
    u = rng.uniform(-12, 12, (50, 2))
    qdd = rng.uniform(-20, 20, (50, 2))
    batch_f = dynamics.derivatives(x, u)
    batch_v = dynamics.voltages(x[:, :2], x[:, 2:], qdd)
    for i in range(len(x)):
        assert batch_f[i] == pytest.approx(dynamics.derivative(list(x[i]), u[i]), rel=1e-12)
        assert batch_v[i] == pytest.approx(
            dynamics.voltage_for(x[i, :2], x[i, 2:], qdd[i]), rel=1e-12)


def test_the_written_out_derivative_is_its_parts(arm):
    """``derivative`` is the forward dynamics of the motors' torque less the friction, to
    the last bit, at random states and volts (seeded)."""
    dynamics = ArmDynamics(arm)
    rng = np.random.default_rng(7)
    for _ in range(500):
        x, u = list(rng.uniform(-3.0, 3.0, 4)), list(rng.uniform(-14.0, 14.0, 2))
        qd = (x[2], x[3])
        motor, friction = dynamics.motor_torque(qd, u), dynamics.friction_torque(qd)
        acc = dynamics.acceleration(x, qd, (motor[0] - friction[0], motor[1] - friction[1]))
        assert dynamics.derivative(x, u) == [x[2], x[3], acc[0], acc[1]]


def test_viscous_friction_slows_an_unpowered_joint(arm):
    rubbing = with_joint(arm, 'elbow', viscous_friction_nm_s_per_rad=50.0)
    free, damped = ArmDynamics(arm), ArmDynamics(rubbing)
    state = [1.0, 0.5, 0.0, 2.0]
    assert damped.derivative(state, (0, 0))[3] < free.derivative(state, (0, 0))[3]


def test_encoders_are_relative_and_lag_by_the_lash(arm):
    plant = ArmPlant(arm, (1.0, -1.0))
    assert np.allclose(plant.read().encoder_rad, 0.0)
    plant.set_voltage((6.0, 0.0))
    plant.advance(0.5)
    reading = plant.read()
    moved = reading.true_state[0] - 1.0
    lash = arm.shoulder.encoder_backlash_rad
    assert moved > 0.05
    assert reading.encoder_rad[0] == pytest.approx(moved - lash / 2, abs=1e-12)


def test_potentiometer_noise_has_the_configured_spread(arm):
    plant = ArmPlant(arm, (1.0, -1.0), seed=11)
    samples = np.array([plant.read().potentiometer_rad for _ in range(4000)])
    assert np.std(samples[:, 0]) == pytest.approx(arm.shoulder.potentiometer_noise_rad, rel=0.05)
    assert np.mean(samples[:, 0]) == pytest.approx(1.0, abs=3e-4)


def test_a_resting_arm_stays_put_until_released(arm):
    plant = ArmPlant(arm, (0.0, 0.0))
    plant.rest()
    plant.advance(1.0)
    assert plant.state == [0.0, 0.0, 0.0, 0.0] and plant.time_s == pytest.approx(1.0)
    plant.release()
    plant.advance(0.5)
    assert plant.state[0] < -0.05                  # gravity takes it once released
