"""PID per joint: the terms, the derivative on the velocity error, anti-windup."""

import math

import pytest

from arm_control.control.pid import ArmPid, JointPid, PidGains

DT_S = 0.02


def test_proportional_alone_is_kp_times_the_error():
    pid = JointPid(PidGains(60.0, 0.0, 0.0), integrator_limit_v=2.0)
    assert pid.update(0.1, 0.0, DT_S) == pytest.approx(6.0)
    assert pid.update(-0.05, 0.0, DT_S) == pytest.approx(-3.0)


def test_derivative_acts_on_the_velocity_error_only():
    """A noisy position error that jumps every period gives no derivative kick."""
    pid = JointPid(PidGains(0.0, 0.0, 4.0), integrator_limit_v=2.0)
    outputs = [pid.update(error, 0.5, DT_S) for error in (0.01, -0.01, 0.02, -0.02)]
    assert outputs == pytest.approx([2.0] * 4)


def test_integral_accumulates_ki_times_the_error_over_time():
    pid = JointPid(PidGains(0.0, 10.0, 0.0), integrator_limit_v=2.0)
    for _ in range(50):                                 # 1 s at 0.01 rad: 10·0.01·1 = 0.1 V
        out = pid.update(0.01, 0.0, DT_S)
    assert out == pytest.approx(0.1)


def test_integral_is_clamped_to_the_limit():
    pid = JointPid(PidGains(0.0, 10.0, 0.0), integrator_limit_v=2.0)
    for _ in range(1000):                               # 20 s of 0.5 rad would be 100 V
        out = pid.update(0.5, 0.0, DT_S)
    assert out == pytest.approx(2.0)
    for _ in range(1000):
        out = pid.update(-0.5, 0.0, DT_S)
    assert out == pytest.approx(-2.0)


def test_integral_does_not_wind_up_while_the_output_is_saturated():
    pid = JointPid(PidGains(0.0, 10.0, 0.0), integrator_limit_v=2.0)
    pid.update(0.01, 0.0, DT_S)
    held = pid.integral_v
    for _ in range(100):                                # pushing further into saturation
        pid.update(0.5, 0.0, DT_S, saturated_sign=+1)
    assert pid.integral_v == pytest.approx(held)
    pid.update(-0.5, 0.0, DT_S, saturated_sign=+1)      # ... but unwinding is allowed
    assert pid.integral_v < held


def test_reset_clears_the_integral():
    pid = ArmPid(PidGains(1.0, 10.0, 0.0), PidGains(1.0, 10.0, 0.0), integrator_limit_v=2.0)
    pid.update((0.1, 0.1), (0.0, 0.0), DT_S)
    assert all(v > 0.0 for v in pid.integral_v)
    pid.reset()
    assert pid.integral_v == (0.0, 0.0)


def test_joints_are_independent():
    pid = ArmPid(PidGains(60.0, 0.0, 4.0), PidGains(50.0, 0.0, 3.0), integrator_limit_v=2.0)
    assert pid.update((0.1, 0.0), (0.0, 1.0), DT_S) == pytest.approx((6.0, 3.0))


def test_a_non_finite_error_is_refused():
    pid = JointPid(PidGains(1.0, 1.0, 1.0), integrator_limit_v=2.0)
    with pytest.raises(ValueError):
        pid.update(math.nan, 0.0, DT_S)
    assert pid.integral_v == 0.0
