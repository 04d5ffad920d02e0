"""The firmware's IMU low-pass filter: gain, cutoff, steady state and white-noise reduction."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crazyflie_driver.sim.onboard import imu_filter as F


def _run(f, x):
    d1, d2 = np.zeros(1), np.zeros(1)
    return np.array([F.lpf2p_step(f, d1, d2, np.array([v]))[0] for v in x])


def _gain(f, hz):
    t = np.arange(4000) / F.SENSOR_RATE_HZ
    y = _run(f, np.sin(2.0 * math.pi * hz * t))[2000:]
    return float(np.sqrt(2.0 * np.mean(y * y)))


def test_unity_dc_gain_and_minus_3_db_at_the_cutoff():
    f = F.ACC_LPF
    assert f.b0 + f.b1 + f.b2 == pytest.approx(1.0 + f.a1 + f.a2)
    assert _gain(f, F.ACC_LPF_HZ) == pytest.approx(1.0 / math.sqrt(2.0), rel=0.02)


def test_rotor_vibration_is_cut_below_the_analogue_roll_off():
    # hover rotor speed ≈ 300 Hz: the bilinear filter passes less than (fc/f)² there (0.5 %)
    assert _gain(F.ACC_LPF, 300.0) < (F.ACC_LPF_HZ / 300.0) ** 2


def test_settled_filter_outputs_its_input():
    f = F.ACC_LPF
    x = np.array([0.3, -0.2, 9.81])
    d1, d2 = F.lpf2p_steady(f, x), F.lpf2p_steady(f, x)
    assert F.lpf2p_step(f, d1, d2, x) == pytest.approx(x)


def test_white_noise_at_1_khz_keeps_the_root_of_its_bandwidth_share():
    y = _run(F.ACC_LPF, np.random.default_rng(1).standard_normal(200000))
    # a second-order Butterworth's noise bandwidth is π/(2√2)·fc ≈ 1.11·fc of the 500 Hz band
    expected = math.sqrt(math.pi / (2.0 * math.sqrt(2.0)) * F.ACC_LPF_HZ / (F.SENSOR_RATE_HZ / 2.0))
    assert np.std(y) == pytest.approx(expected, rel=0.05)


def test_a_cutoff_beyond_nyquist_is_refused():
    with pytest.raises(ValueError, match="half the sample rate"):
        F.lpf2p(1000.0, 600.0)
