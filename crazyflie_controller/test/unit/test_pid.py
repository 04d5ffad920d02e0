"""PID: terms, limits, timing from timestamps, derivative modes, reset and preload."""
import pytest

from crazyflie_controller.pid import PID, PidGains

Z = PidGains(kp=5000, kd=6000, ki=3500, min_output=10000, max_output=60000,
             integrator_min=-1000, integrator_max=1000)


def gains(**kw):
    base = dict(kp=1.0, kd=0.0, ki=0.0, min_output=-100.0, max_output=100.0,
                integrator_min=-10.0, integrator_max=10.0)
    base.update(kw)
    return PidGains(**base)


def test_proportional_term_and_output_clamp():
    pid = PID(gains(kp=2.0, max_output=5.0, min_output=-3.0))
    assert pid.update(1.0, 0.0, 0.0) == pytest.approx(2.0)
    assert pid.update(10.0, 0.0, 0.1) == 5.0
    assert pid.update(-10.0, 0.0, 0.2) == -3.0


def test_integral_uses_timestamps_and_is_clamped():
    pid = PID(gains(kp=0.0, ki=2.0, integrator_max=0.5))
    pid.update(1.0, 0.0, 10.0)            # first call: no dt yet, nothing integrated
    assert pid.integral == 0.0
    pid.update(1.0, 0.0, 10.1)            # 0.1 s of error 1
    assert pid.integral == pytest.approx(0.1)
    assert pid.update(1.0, 0.0, 10.3) == pytest.approx(2.0 * 0.3)
    pid.update(1.0, 0.0, 20.0)            # a long dt saturates the integrator
    assert pid.integral == 0.5
    assert pid.i_term == pytest.approx(1.0)


def test_time_that_does_not_advance_neither_integrates_nor_differentiates():
    pid = PID(gains(kp=0.0, ki=1.0, kd=1.0), derivative="error")
    pid.update(1.0, 0.0, 1.0)
    pid.update(1.0, 0.0, 1.5)
    integral = pid.integral
    out = pid.update(5.0, 0.0, 1.5)        # same stamp: no integration, no division by zero
    assert pid.integral == integral
    assert out == pytest.approx(integral)
    pid.update(5.0, 0.0, 1.4)              # time going back: same
    assert pid.integral == integral


def test_derivative_on_measurement_ignores_target_jumps():
    pid = PID(Z, derivative="measurement")
    pid.reset(0.0)
    pid.set_i_term(40000)
    pid.update(0.5, 0.5, 0.02, measurement_rate=0.0)
    out = pid.update(1.0, 0.5, 0.04, measurement_rate=0.0)   # goal jumps 0.5 m up
    p, i, d = pid.last_terms
    assert d == 0.0
    assert out == pytest.approx(40000 + 5000 * 0.5 + 3500 * 0.5 * 0.02 * 1, rel=1e-3)
    assert out < 60000


def test_derivative_on_error_kicks_on_a_target_jump_as_the_original_did():
    pid = PID(Z, derivative="error")
    pid.reset(0.0)
    pid.set_i_term(40000)
    pid.update(0.5, 0.5, 0.02)
    assert pid.update(1.0, 0.5, 0.04) == 60000   # 6000 * 0.5 / 0.02 = 150000: saturates


def test_derivative_uses_measured_rate_and_target_rate():
    pid = PID(gains(kp=0.0, kd=2.0))
    pid.update(0.0, 0.0, 0.0)
    assert pid.update(0.0, 0.0, 0.02, measurement_rate=0.5) == pytest.approx(-1.0)   # moving away: brakes
    assert pid.update(0.0, 0.0, 0.04, target_rate=0.5, measurement_rate=0.5) == pytest.approx(0.0)
    # without a rate, the measurement is differenced over dt
    pid2 = PID(gains(kp=0.0, kd=2.0))
    pid2.update(0.0, 1.0, 0.0)
    assert pid2.update(0.0, 1.1, 0.1) == pytest.approx(-2.0 * 1.0)


def test_reset_clears_integral_and_history_and_preload_sets_the_i_term():
    pid = PID(Z, derivative="error")
    pid.update(1.0, 0.0, 0.0)
    pid.update(1.0, 0.0, 0.5)
    assert pid.integral != 0.0
    pid.reset(1.0)
    assert pid.integral == 0.0 and pid.last_output == 0.0
    pid.set_i_term(42000.0)
    assert pid.i_term == pytest.approx(42000.0)
    assert pid.integral == pytest.approx(12.0)
    # original behaviour: the error before a reset counts as 0, so the first sample kicks
    assert pid.update(0.45, 0.0, 1.02) == 60000


def test_preload_is_limited_by_the_integrator_range():
    pid = PID(gains(ki=2.0, integrator_max=3.0))
    pid.set_i_term(100.0)
    assert pid.integral == 3.0
    pid_no_i = PID(gains(ki=0.0))
    pid_no_i.set_i_term(5.0)
    assert pid_no_i.i_term == 0.0


def test_gains_are_checked_and_read_from_params():
    g = PidGains.from_params({"kp": 40, "kd": 20, "ki": 2, "minOutput": -10, "maxOutput": 10,
                              "integratorMin": -0.1, "integratorMax": 0.1}, "X")
    assert (g.kp, g.kd, g.ki, g.min_output, g.max_output, g.integrator_min, g.integrator_max) == \
        (40, 20, 2, -10, 10, -0.1, 0.1)
    with pytest.raises(ValueError, match="X: parameter kd is missing"):
        PidGains.from_params({"kp": 1}, "X")
    with pytest.raises(ValueError, match="Z: parameter kp must be a number"):
        PidGains.from_params({"kp": "fast", "kd": 0, "ki": 0, "minOutput": 0, "maxOutput": 1,
                              "integratorMin": 0, "integratorMax": 0}, "Z")
    with pytest.raises(ValueError, match="minOutput"):
        gains(min_output=5.0, max_output=1.0)
    with pytest.raises(ValueError, match="derivative mode"):
        PID(gains(), derivative="future")
