"""The Kalman filter against the simulated arm's true state (arm paper §5)."""

import math

import numpy as np
import pytest

from arm_control import config
from arm_control.control import estimator as estimator_module
from arm_control.control.estimator import ArmEstimator
from arm_control.control.linearisation import StepLinearisation
from arm_control.control.robot_loop import RobotLoop
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.plant import ArmPlant

PERIOD_S = 0.02                      # the controller's 50 Hz
KP_V_PER_RAD, KD_V_S_PER_RAD = 30.0, 2.0
VOLTAGE_NOISE_V = 0.5


@pytest.fixture(scope='module')
def process_noise_rad_s2():
    return config.load('controller')[1].process_noise_rad_s2


def swinging(t):
    """Both joints swinging through reversals: (q, q̇, q̈) at time t."""
    centre, amplitude = np.array([1.2, -1.2]), np.array([0.6, 0.8])
    rate = np.array([0.8, 1.1])
    phase = rate * t
    return (centre + amplitude * np.sin(phase), amplitude * rate * np.cos(phase),
            -amplitude * rate ** 2 * np.sin(phase))


def is_symmetric_positive_definite(p):
    return np.allclose(p, p.T, rtol=0.0, atol=1e-15) and np.linalg.eigvalsh(p).min() > 0.0


class Loop:
    """Plant, filter and a closed-loop-ish drive: feedforward along a reference, PD on the
    raw sensors, plus random volts; the filter sees what a controller would see."""

    def __init__(self, arm, process_noise_rad_s2, seed, reference=swinging):
        self.rng = np.random.default_rng(seed)
        self.reference = reference
        self.dynamics = ArmDynamics(arm)
        self.plant = ArmPlant(arm, reference(0.0)[0], seed=seed)
        self.estimator = ArmEstimator(arm, process_noise_rad_s2)
        self.reading = self.plant.read()
        self.estimator.reset(self.reading.potentiometer_rad, self.reading.encoder_rad)
        self.t = 0.0

    def step(self, voltage=None):
        """One 50 Hz cycle; returns (filter error, raw error) against the true state."""
        if voltage is None:
            q, qd, qdd = self.reference(self.t)
            r = self.reading
            voltage = (np.array(self.dynamics.voltage_for(q, qd, qdd))
                       + KP_V_PER_RAD * (q - r.potentiometer_rad)
                       + KD_V_S_PER_RAD * (qd - r.velocity_rad_s)
                       + self.rng.normal(0.0, VOLTAGE_NOISE_V, 2))
        self.plant.set_voltage(voltage)
        self.plant.advance(PERIOD_S)
        self.t += PERIOD_S
        r = self.reading = self.plant.read()
        self.estimator.predict(r.voltage, PERIOD_S)
        self.estimator.update(r.potentiometer_rad, r.velocity_rad_s, r.encoder_rad)
        raw = np.concatenate([r.potentiometer_rad, r.velocity_rad_s])
        return self.estimator.state - r.true_state, raw - r.true_state

    def run(self, seconds, **kwargs):
        errors = [self.step(**kwargs) for _ in range(round(seconds / PERIOD_S))]
        return np.array([e for e, _ in errors]), np.array([r for _, r in errors])


def rms(errors):
    return np.sqrt(np.mean(errors ** 2, axis=0))


def test_reset_starts_at_the_reading_at_rest(arm, process_noise_rad_s2):
    estimator = ArmEstimator(arm, process_noise_rad_s2)
    estimator.reset([1.0, -0.5], [0.2, 0.1])
    np.testing.assert_allclose(estimator.state, [1.0, -0.5, 0.0, 0.0])
    np.testing.assert_allclose(estimator.encoder_zero_rad, [0.8, -0.6])
    np.testing.assert_allclose(estimator.position_std_rad,
                               [j.potentiometer_noise_rad for j in arm.joints])


def test_filter_beats_the_raw_sensors_on_a_long_run(arm, process_noise_rad_s2):
    """20 s at 50 Hz: position RMS well under the potentiometers', velocity under the raw
    reported velocity's; the covariance stays symmetric positive definite every cycle and
    the filter's own σ describes its errors."""
    loop = Loop(arm, process_noise_rad_s2, seed=11)
    filtered, raw, within_3_sigma = [], [], []
    for _ in range(round(20.0 / PERIOD_S)):
        error, raw_error = loop.step()
        filtered.append(error)
        raw.append(raw_error)
        assert np.all(np.isfinite(loop.estimator.state))
        assert is_symmetric_positive_definite(loop.estimator.covariance)
        within_3_sigma.append(np.abs(error[:2]) <= 3.0 * loop.estimator.position_std_rad)
    filtered, raw = rms(np.array(filtered)), rms(np.array(raw))
    assert np.all(filtered[:2] < 0.6 * raw[:2]), (filtered, raw)    # measured ≈ 0.25-0.3
    assert np.all(filtered[2:] < 0.9 * raw[2:]), (filtered, raw)    # measured ≈ 0.8
    assert np.all(np.mean(within_3_sigma, axis=0) > 0.95)
    assert loop.estimator.jump_count == 0 and loop.estimator.rezero_count == 0
    travel = np.ptp([swinging(t)[0] for t in np.arange(0.0, 20.0, 1.0)], axis=0)
    assert np.all(travel > 1.0)                                       # it really moved


def test_rezeroes_after_a_sim_reset(arm, process_noise_rad_s2):
    """The sim's reset puts the arm back at its start and restarts the encoders from zero."""
    loop = Loop(arm, process_noise_rad_s2, seed=12)
    start = loop.reference(0.0)[0]
    loop.run(2.0)
    before = loop.plant.state[:2]
    assert np.all(np.abs(np.array(before) - start) > 0.3)           # far from the start
    loop.plant.reset(start)
    loop.t = 0.0
    loop.step()
    assert loop.estimator.jump_count == 1
    assert np.all(np.abs(loop.estimator.state[:2] - start) < 0.02)
    filtered, raw = loop.run(6.0)
    np.testing.assert_allclose(loop.estimator.encoder_zero_rad, start, atol=0.01)
    assert np.all(rms(filtered)[:2] < 0.6 * rms(raw)[:2])


def test_rezeroes_when_only_the_encoders_restart(arm, process_noise_rad_s2):
    """A motor controller's power cycle mid-motion: the encoders read 0 where the arm is;
    the potentiometers are unaffected. The zeros move to there and the estimate holds."""
    loop = Loop(arm, process_noise_rad_s2, seed=13)
    loop.run(3.0)
    where = list(loop.plant.state[:2])
    loop.plant.sensors.zero(where)
    filtered, raw = loop.run(4.0)
    assert loop.estimator.rezero_count == 1 and loop.estimator.jump_count == 0
    assert np.all(np.abs(filtered[:, :2]).max(axis=0) < 0.01)
    np.testing.assert_allclose(loop.estimator.encoder_zero_rad, where, atol=0.01)
    assert np.all(rms(filtered)[:2] < 0.6 * rms(raw)[:2])


@pytest.mark.parametrize('voltage, joint, stop', [
    ((12.0, 0.0), 0, 'max_angle_rad'),     # shoulder over the top and down onto its stop
    ((0.0, -12.0), 1, 'min_angle_rad'),    # elbow folded hard against its stop
])
def test_finite_and_at_the_stop_when_driven_into_it(arm, process_noise_rad_s2,
                                                    voltage, joint, stop):
    loop = Loop(arm, process_noise_rad_s2, seed=14, reference=lambda t: swinging(0.0))
    limit = getattr(arm.joints[joint], stop)
    for _ in range(round(4.0 / PERIOD_S)):
        error, _ = loop.step(voltage=voltage)
        assert np.all(np.isfinite(loop.estimator.state))
        assert is_symmetric_positive_definite(loop.estimator.covariance)
    assert loop.plant.state[joint] == limit                         # the plant is at its stop
    state = loop.estimator.state
    assert abs(state[joint] - limit) < 0.01
    assert arm.joints[joint].min_angle_rad <= state[joint] <= arm.joints[joint].max_angle_rad
    assert abs(state[joint + 2]) < 0.1
    assert np.all(np.abs(error[:2]) < 0.01)


def test_bad_input_is_refused_or_skipped(arm, process_noise_rad_s2):
    estimator = ArmEstimator(arm, process_noise_rad_s2)
    with pytest.raises(RuntimeError, match='reset'):
        estimator.predict([0.0, 0.0], PERIOD_S)
    estimator.reset([1.5708, -1.5708], [0.0, 0.0])
    with pytest.raises(ValueError, match='voltage'):
        estimator.predict([math.nan, 0.0], PERIOD_S)
    with pytest.raises(ValueError, match='dt_s'):
        estimator.predict([0.0, 0.0], -PERIOD_S)
    estimator.predict([0.0, 0.0], PERIOD_S)
    before = estimator.state
    estimator.update([math.nan, -1.5708], [0.0, math.inf], [0.0, 0.0])   # only finite ones used
    assert np.all(np.isfinite(estimator.state))
    assert np.all(np.abs(estimator.state - before) < 0.05)


def holding(t):
    """The arm held still, forearm level: (q, q̇, q̈)."""
    return np.array([1.5708, -1.5708]), np.zeros(2), np.zeros(2)


@pytest.mark.parametrize('reference, most_kept', [(holding, 0.25), (swinging, 0.0)])
def test_a_kept_jacobian_leaves_the_estimate_as_it_was(arm, process_noise_rad_s2, monkeypatch,
                                                       reference, most_kept):
    """∂f/∂x kept while the arm stays near where it was taken: a held arm takes it anew in
    under three cycles of four (its command moves with the raw sensors' noise here), a
    swinging one in every cycle; either way the estimate and its σ
    are those of a filter that takes it anew every cycle, to well under the sensors' noise."""
    made = []
    jacobian = StepLinearisation.jacobian
    monkeypatch.setattr(StepLinearisation, 'jacobian',
                        staticmethod(lambda *args: made.append(1) or jacobian(*args)))
    runs = []
    for keep in (True, False):
        loop = Loop(arm, process_noise_rad_s2, seed=5, reference=reference)
        if not keep:
            loop.estimator.linearisation.bounds = (0.0,) * 7
        made.clear()
        states, stds = [], []
        for _ in range(250):
            q, qd, qdd = reference(loop.t)          # PD on the sensors, no random volts
            r = loop.reading
            loop.step(np.array(loop.dynamics.voltage_for(q, qd, qdd))
                      + KP_V_PER_RAD * (q - r.potentiometer_rad)
                      + KD_V_S_PER_RAD * (qd - r.velocity_rad_s))
            states.append(loop.estimator.state)
            stds.append(np.sqrt(np.diag(loop.estimator.covariance)))
        runs.append((np.array(states), np.array(stds), len(made)))
    (kept_x, kept_std, kept_made), (new_x, new_std, new_made) = runs
    assert new_made == 250
    assert kept_made <= (1.0 - most_kept) * 250
    np.testing.assert_allclose(kept_x, new_x, rtol=0.0, atol=1e-5)
    np.testing.assert_allclose(kept_std, new_std, rtol=1e-3)


def test_a_step_predicted_again_is_taken_from_the_first(arm, controller_config, planner,
                                                        monkeypatch):
    """On the robot's clock the controller predicts each step twice (to when its command
    acts, then from the reading of that instant); kept, the second is not computed again,
    and the arm moves as when every prediction is computed, held and to a goal, to 1e-11
    (the two ends of a step agree to SAME_STEP_S)."""
    runs = []
    for kept in (estimator_module.PREDICTIONS_KEPT, 0):
        monkeypatch.setattr(estimator_module, 'PREDICTIONS_KEPT', kept)
        computed = []
        loop = RobotLoop(arm, controller_config, planner, seed=4, phase_s=0.007)
        estimator = loop.core.sensing.estimator
        estimator.linearisation.bounds = (0.0,) * 7    # ∂f/∂x at every step, where it is
        integrate = estimator._kf._integrate
        estimator._kf._integrate = lambda x, u: computed.append(1) or integrate(x, u)
        loop.run(0.5)
        loop.submit_goal(1.1, 0.9)
        loop.run(2.5)
        runs.append((np.array([state for _, state in loop.history]), len(computed)))
    (kept_states, kept_computed), (all_states, all_computed) = runs
    np.testing.assert_allclose(kept_states, all_states, rtol=0.0, atol=1e-11)
    assert kept_computed < 0.75 * all_computed


def test_the_noise_a_step_adds_is_white_acceleration_held_over_it(arm, process_noise_rad_s2):
    """Over any step dt, white acceleration of variance σ² held over it adds σ²dt⁴/4 to each
    angle's variance, σ²dt²  to each speed's and σ²dt³/2 between them, and nothing between
    the joints: steps of the two lengths a period takes, in turn."""
    estimator = ArmEstimator(arm, process_noise_rad_s2)
    variance = process_noise_rad_s2 ** 2
    for dt in (0.013, 0.007, 0.013, 0.02):
        q = estimator._process_noise(dt)
        for joint in (0, 1):
            angle, speed = joint, joint + 2
            assert q[angle, angle] == pytest.approx(variance * dt ** 4 / 4, rel=1e-12)
            assert q[speed, speed] == pytest.approx(variance * dt ** 2, rel=1e-12)
            assert q[angle, speed] == q[speed, angle] == pytest.approx(variance * dt ** 3 / 2,
                                                                       rel=1e-12)
        assert q[0, 1] == q[0, 3] == q[2, 3] == 0.0


@pytest.mark.parametrize('speed_rad_s', [0.0, 0.005, -0.005])
def test_near_rest_the_mean_moves_on_the_linearisation_as_rk4_moves_it(
        arm, process_noise_rad_s2, speed_rad_s):
    """Held (within A's bounds), a period's mean on ẋ = f(x₀) + A (x − x₀) is where RK4 on f
    itself takes it, to 1e-8 rad and 1e-6 rad/s (the sensors are good to ~1e-3): the bounds A
    is kept within leave f affine. 0.05 V off the holding volts, the arm starts to move."""
    q = (0.6, -0.8)
    volts = np.array(ArmDynamics(arm).voltage_for(q, (0.0, 0.0), (0.0, 0.0))) + 0.05
    ends, linear = [], []
    for exact in (False, True):
        estimator = ArmEstimator(arm, process_noise_rad_s2)
        estimator.reset(q, (0.0, 0.0))
        estimator._kf.x[2:4] = speed_rad_s
        if exact:
            estimator.linearisation.moved = lambda *args: None
        else:
            along = estimator.linearisation.moved
            estimator.linearisation.moved = \
                lambda *args: linear.append(along(*args)) or linear[-1]
        for _ in range(3):
            estimator.predict(volts, 0.02)
        ends.append(estimator.state)
    assert len(linear) == 3 and all(end is not None for end in linear)
    np.testing.assert_allclose(ends[0][:2], ends[1][:2], rtol=0.0, atol=1e-8)
    np.testing.assert_allclose(ends[0][2:], ends[1][2:], rtol=0.0, atol=1e-6)
    assert np.max(np.abs(ends[1][2:] - speed_rad_s)) > 1e-3          # it does move
