"""The firmware's IMU low-pass filters: what the sensors task does to every raw sample (all vehicles).

The sensors task of the current firmware reads the IMU at 1 kHz and passes each axis of the gyro
and of the accelerometer through a second-order Butterworth low-pass filter (80 Hz and 30 Hz,
designed for a 1 kHz sample rate by the bilinear transform with a pre-warped cutoff) before the
controllers and the estimator see them (docs/simulation.md, "Onboard estimator"). The simulated
Kalman filter is fed the same way: raw accelerometer samples in, filtered samples summed between
predictions. Doubles here where the firmware computes in single precision.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

SENSOR_RATE_HZ = 1000.0               # the sensors task's IMU read rate (both IMU drivers)
ACC_LPF_HZ = 30.0                     # accelerometer low-pass cutoff
GYRO_LPF_HZ = 80.0                    # gyro low-pass cutoff


class Lpf2p(NamedTuple):
    """Coefficients of a second-order low-pass biquad (direct form II; a0 = 1)."""

    b0: float
    b1: float
    b2: float
    a1: float
    a2: float


def lpf2p(sample_hz: float, cutoff_hz: float) -> Lpf2p:
    """The Butterworth (Q = 1/√2) low-pass of ``cutoff_hz`` at ``sample_hz``: the analogue prototype
    1/(s² + √2·s + 1) mapped by the bilinear transform, the cutoff pre-warped so that it stays at
    ``cutoff_hz`` (unity gain at DC, -3 dB at the cutoff)."""
    if not 0.0 < cutoff_hz < sample_hz / 2.0:
        raise ValueError("low-pass cutoff must lie between 0 and half the sample rate (%g Hz), got %r"
                         % (sample_hz / 2.0, cutoff_hz))
    w = math.tan(math.pi * cutoff_hz / sample_hz)
    w2 = w * w
    norm = 1.0 + math.sqrt(2.0) * w + w2
    b0 = w2 / norm
    return Lpf2p(b0, 2.0 * b0, b0, 2.0 * (w2 - 1.0) / norm, (1.0 - math.sqrt(2.0) * w + w2) / norm)


ACC_LPF = lpf2p(SENSOR_RATE_HZ, ACC_LPF_HZ)


def lpf2p_step(f: Lpf2p, d1: np.ndarray, d2: np.ndarray, x: np.ndarray) -> np.ndarray:
    """One sample ``x`` of every row through the filter whose delay elements ``d1``, ``d2`` (same
    shape as ``x``) are updated in place; returns the filtered sample. A non-finite intermediate is
    replaced by the input, as the firmware keeps a bad sample from poisoning its filter."""
    d0 = x - f.a1 * d1 - f.a2 * d2
    bad = ~np.isfinite(d0)
    if bad.any():
        d0 = np.where(bad, x, d0)
    y = f.b0 * d0 + f.b1 * d1 + f.b2 * d2
    d2[...] = d1
    d1[...] = d0
    return y


def lpf2p_steady(f: Lpf2p, x: np.ndarray) -> np.ndarray:
    """The value of both delay elements of a filter that has seen ``x`` forever (its output is ``x``)."""
    return x / (1.0 + f.a1 + f.a2)
