"""The Kalman estimator's IMU input: raw accelerometer samples pass the firmware's low-pass before
the prediction averages them, and the filter starts settled on the first sample."""
from __future__ import annotations

import types

import numpy as np
import pytest

from crazyflie_driver.sim.onboard import estimator as E
from crazyflie_driver.sim.onboard import kalman

G = 9.81


class NoisyImu:
    """A vehicle at rest: 1 g on body z plus white noise of ``sigma`` m/s² per raw sample."""

    def __init__(self, sigma: float, seed: int = 1) -> None:
        self.sigma, self.rng = sigma, np.random.default_rng(seed)

    def acc_raw(self, samples: int) -> np.ndarray:
        return np.array([0.0, 0.0, G]) + self.rng.standard_normal((samples, 1, 3)) * self.sigma

    def gyro_means(self, rows, omega, window_s):
        return omega


def _resting_kalman():
    """One estimator row on the Kalman filter at the origin, and a body at rest (1 g on body z)."""
    est = E.Estimator()
    est.add(np.random.default_rng(0), (0.0, 0.0, 0.0), 0.0)
    est.set_param(0, "stabilizer.estimator", 2, (0.0, 0.0, 0.0), 0.0)
    bodies = types.SimpleNamespace(specific_force=np.array([[0.0, 0.0, G]]), omega=np.zeros((1, 3)),
                                   position=np.zeros((1, 3)), velocity=np.zeros((1, 3)),
                                   quaternion=np.array([[0.0, 0.0, 0.0, 1.0]]))
    return est, bodies


def _predicted_acc(monkeypatch, imu, seconds: float):
    est, bodies = _resting_kalman()
    seen = []
    predict = kalman.predict
    monkeypatch.setattr(kalman, "predict", lambda k, rows, acc, *a: (seen.append(acc[0].copy()),
                                                                      predict(k, rows, acc, *a)))
    for tick in range(2, int(seconds * 1000) + 1, 2):
        est.update(tick, tick / 1000.0, np.zeros(1), bodies, 2, imu)
    return np.array(seen)


def test_vibration_is_low_passed_before_the_prediction_averages_it(monkeypatch):
    acc = _predicted_acc(monkeypatch, NoisyImu(1.0), 20.0)
    # a plain mean of 10 raw samples keeps 1/√10 = 0.32 of the noise; after the 30 Hz filter
    # (noise bandwidth ≈ 33 Hz of the 500 Hz band) the mean keeps about a quarter
    spread = acc[:, 0].std()
    assert 0.18 < spread < 0.27, spread
    assert abs(acc[:, 2].mean() - G) < 0.02


def test_the_filter_starts_settled_on_its_first_sample(monkeypatch):
    acc = _predicted_acc(monkeypatch, None, 0.05)
    assert np.allclose(acc, [0.0, 0.0, G], atol=1e-9)


def test_process_noise_of_the_loops_before_a_prediction_goes_in_before_it():
    """estimator_kalman.c adds each 1 ms loop's process noise as the loop runs and predicts every
    10th: the noise of loops 1-9 is in P when the prediction at 10 ms propagates it, which puts the
    velocity's noise into the position-velocity covariance (2 % of it at the start)."""
    est, bodies = _resting_kalman()
    ref = kalman.KalmanStates()
    ref.append_row(**{name: np.array(getattr(est.k, name)[0], copy=True) for name in kalman.KalmanStates.FIELDS})
    rows = np.array([0])
    kalman.add_process_noise(ref, rows, 9.0)                      # loops 1-9
    kalman.predict(ref, rows, np.array([[0.0, 0.0, G]]), np.zeros((1, 3)), 0.01, np.array([False]))
    kalman.add_process_noise(ref, rows, 10.0)                     # loop 10, after its prediction
    kalman.finalize(ref, rows)
    for tick in range(2, 11, 2):
        est.update(tick, tick / 1000.0, np.zeros(1), bodies, 2, None)
    assert est.k.P[0, 0, 3] == pytest.approx(ref.P[0, 0, 3], rel=1e-9)
    assert np.allclose(est.k.P[0], ref.P[0], rtol=1e-9, atol=0.0)
