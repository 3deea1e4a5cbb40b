"""Coulomb friction makes the arm stiff near rest: c·tanh(ω/ω_s) has the slope c/ω_s at
ω = 0, a damping far above the motors' back-EMF. RK4 on a step h decays a mode ẋ = −λx only
for h·λ below 2.785, so every model the controller steps must keep its steps within that
(``ArmDynamics.stable_step_s``). Runs on the sysid demo arm (friction on both joints),
in-process, seeded."""

from pathlib import Path

from conftest import with_joint
import numpy as np
import pytest

from arm_control import config, parameters
from arm_control.control.estimator import ArmEstimator
from arm_control.control.robot_loop import RobotLoop
from arm_control.model.dynamics import ArmDynamics, RK4_STABLE_STEP
from arm_control.model.feedforward import PeriodFeedforward
from arm_control.planning.planner import Planner

CONFIG = Path(__file__).resolve().parents[2] / 'config'
TALL_REACH = (1.6423, -0.4176)       # the suite's (0.2, 1.75) m: arm out, near upright
STOW = (1.98, -2.6)                  # the suite's (0.25, 0.45) m
POSES = [(0.2618, -0.4617), TALL_REACH, (0.84, -1.68), (1.5708, -1.5708), (2.5, 2.0)]


@pytest.fixture(scope='module')
def demo():
    params = parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sim')
    params.update(parameters.read_parameter_file(CONFIG / 'sysid_demo_arm.yaml', 'sim'))
    return config.ArmConfig.from_parameters(params)


def fastest_mode_at_rest(dynamics, q) -> float:
    """The largest |eigenvalue| of ∂f/∂x at (q, 0), by central differences."""
    x, jacobian, eps = np.array([*q, 0.0, 0.0]), np.zeros((4, 4)), 1e-7
    for i in range(4):
        dx = np.zeros(4)
        dx[i] = eps
        jacobian[:, i] = (np.array(dynamics.derivative(x + dx, (0.0, 0.0)))
                          - np.array(dynamics.derivative(x - dx, (0.0, 0.0)))) / (2 * eps)
    return float(np.max(np.abs(np.linalg.eigvals(jacobian))))


def test_the_stiffest_rate_bounds_the_fastest_mode_at_rest(demo, arm):
    """Over poses, the linearised arm's fastest mode at rest is within the bound and comes
    near it (the bound drops only gravity's slow terms); friction makes it several times the
    frictionless arm's."""
    for model in (demo, arm):
        dynamics = ArmDynamics(model)
        rates = [fastest_mode_at_rest(dynamics, q) for q in POSES]
        assert max(rates) <= dynamics.stiffest_rate_per_s() * 1.001
        assert max(rates) >= 0.75 * dynamics.stiffest_rate_per_s()
    assert ArmDynamics(demo).stiffest_rate_per_s() > 3.0 * ArmDynamics(arm).stiffest_rate_per_s()
    dynamics = ArmDynamics(demo)
    assert dynamics.stable_step_s(0.02) * dynamics.stiffest_rate_per_s() == \
        pytest.approx(RK4_STABLE_STEP)
    assert ArmDynamics(arm).stable_step_s(0.01) == 0.01      # no friction: as asked


def test_the_feedforward_holds_an_arm_with_friction_at_a_steady_voltage(demo):
    """Come to rest on a setpoint (its reference a little off it, as on arriving), the
    feedforward's voltage settles within 0.2 s to the one that holds the arm there,
    V = k·τg(q) (friction is zero at rest), and stays: its reference on the setpoint. An RK4
    step past the stable one grows the reference's speed near rest instead, and the deadbeat
    step answers with volts that swing by volts, period after period."""
    dynamics = ArmDynamics(demo)
    feedforward = PeriodFeedforward(dynamics, 0.02, demo.battery.nominal_voltage)
    near = (np.array(TALL_REACH) + 0.01, np.zeros(2), np.zeros(2))
    here = (np.array(TALL_REACH), np.zeros(2), np.zeros(2))
    feedforward.step(0.0, lambda _t: near, 12.0)
    volts = np.array([feedforward.step(0.02 * k, lambda _t: here, 12.0)
                      for k in range(1, 150)])
    holding = np.array(dynamics.voltage_for(TALL_REACH, (0.0, 0.0), (0.0, 0.0)))
    np.testing.assert_allclose(volts[10:], np.tile(holding, (139, 1)), atol=0.01)
    np.testing.assert_allclose(feedforward.state, [*TALL_REACH, 0.0, 0.0], atol=1e-6)


def test_the_arm_with_friction_reaches_and_holds_the_tall_reach(demo, controller_config):
    """The controller and the planner on the demo arm, on the robot's clock (profiles, 4 ms
    late, 1 ms physics), from the stow to the tall reach: the move ends within 1.5 s of the
    goal, and from then on no joint swings 0.5 deg (bench/robot_clock.py's hold bar)."""
    planner = Planner(demo, config.load('planner')[1])
    loop = RobotLoop(demo, controller_config, planner, start=STOW, seed=6)
    loop.run(0.5)
    loop.submit_goal(0.2, 1.75)
    loop.run(4.0)
    assert loop.core.goals.counts['reached'] == 1
    states = np.array([s for t, s in loop.history if t > 2.0])
    assert np.degrees(np.max(np.ptp(states[:, :2], axis=0))) < 0.5


def test_the_estimator_predicts_an_arm_with_strong_friction_at_rest(demo):
    """With 3x the demo arm's Coulomb friction (its stiffest rate ~1400 /s), the filter's
    prediction at rest under the holding voltage stays at rest: no speed grows from a
    nudge of 0.001 rad/s."""
    sticky = with_joint(with_joint(demo, 'shoulder', coulomb_friction_nm=30.0), 'elbow',
                        coulomb_friction_nm=15.0)
    estimator = ArmEstimator(sticky, 1.0)
    estimator.reset(TALL_REACH, (0.0, 0.0))
    estimator._kf.x[2:4] = 0.001
    holding = ArmDynamics(sticky).voltage_for(TALL_REACH, (0.0, 0.0), (0.0, 0.0))
    for _ in range(50):
        estimator.predict(holding, 0.02)
    assert np.max(np.abs(estimator._kf.x[2:4])) < 0.001
