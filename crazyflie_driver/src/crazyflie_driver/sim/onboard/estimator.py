"""The onboard state estimate of every vehicle (numpy rows): what the firmware believes, not the truth.

``stabilizer.estimator`` 2 (Kalman) fuses external position/pose; 1 (complementary, also what 0
"auto" and an unbuilt 3 fall back to) ignores them: it knows no x/y position at all and takes
its height from the barometer. That is the trap users hit when they stream motion capture
without switching estimators, and it is kept.

The Kalman model is the honest reduced one of docs/simulation.md ("Onboard estimator"): attitude
is the truth; the position estimate is truth + e, and at each measurement m the error follows a
scalar Kalman gain K per axis, e <- (1-K)·e + K·(m - truth), with K from the measurement's
standard deviation, the process noise ``kalman.pNAcc_*`` over the time since the last measurement
and the firmware's variance floor. While flying, a tilt-estimate error makes the horizontal
velocity estimate drift (and an accelerometer bias the vertical one), so without measurements
the estimate runs away quadratically; measurements pull the velocity error back.
"""
from __future__ import annotations

import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from crazyflie_driver.sim.vehicle_rows import Rows, Vector

COMPLEMENTARY, KALMAN = 1, 2
GRAVITY = 9.81                      # m/s²
PREDICT_EVERY = 10                  # ticks: the Kalman filter predicts at 100 Hz
VAR_FLOOR = 1e-6                    # m², covariance diagonal clamp (lower)
VAR_CEIL = 100.0                    # m², covariance diagonal clamp (upper)
INITIAL_STD = (100.0, 100.0, 1.0)   # m, initial position standard deviation x, y, z after a reset
VELOCITY_GAIN_MIN = 0.5             # fraction of the velocity error removed per measurement (EST)
TILT_ERROR_DEG = 0.5                # tilt-estimate error that drives horizontal drift (EST)
ACC_BIAS_Z = 0.02                   # m/s², standard deviation of the vertical accelerometer bias (EST)

# parameter name -> (field, column) ; defaults of the current firmware
DEFAULTS: Dict[str, float] = {
    "locSrv.extPosStdDev": 0.01, "locSrv.extQuatStdDev": 4.5e-3,
    "kalman.pNAcc_xy": 0.5, "kalman.pNAcc_z": 1.0,
    "kalman.initialX": 0.0, "kalman.initialY": 0.0, "kalman.initialZ": 0.0, "kalman.initialYaw": 0.0,
    "kalman.maxPos": 100.0, "kalman.maxVel": 10.0,
}


def estimator_kind(param_value: float) -> int:
    """``stabilizer.estimator`` value -> the estimator that runs (auto and unbuilt ones: complementary)."""
    return KALMAN if int(param_value) == KALMAN else COMPLEMENTARY



def _bounded(variance: float) -> float:
    """A variance within the firmware's floor and ceiling (NaN stays NaN)."""
    return min(max(variance, VAR_FLOOR), VAR_CEIL) if variance == variance else variance

class EstimatorStates(Rows):
    FIELDS = {
        "kind": ((), np.int8),
        "err": ((3,), float),             # position estimate - truth, m
        "verr": ((3,), float),            # velocity estimate - truth, m/s
        "var": ((3,), float),             # position variance after the last measurement, m²
        "last_meas": ((), float),         # world time of the last position measurement, s
        "drift_acc": ((3,), float),       # acceleration error while flying, m/s²
        "std_pos": ((), float),
        "std_quat": ((), float),
        "pnacc": ((3,), float),           # process noise x, y, z
        "initial": ((4,), float),         # initialX, Y, Z (m), Yaw (rad)
        "max_pos": ((), float),
        "max_vel": ((), float),
        "ext_pos": ((3,), float),         # last external position / pose (locSrv.*)
        "ext_quat": ((4,), float),
        "ext_tick": ((), float),          # ms, world clock, of the last packet for this vehicle
        "resets": ((), np.int32),
    }

    # The columns (one row per vehicle; shapes and dtypes in FIELDS), declared for the type checker.
    kind: np.ndarray
    err: np.ndarray
    verr: np.ndarray
    var: np.ndarray
    last_meas: np.ndarray
    drift_acc: np.ndarray
    std_pos: np.ndarray
    std_quat: np.ndarray
    pnacc: np.ndarray
    initial: np.ndarray
    max_pos: np.ndarray
    max_vel: np.ndarray
    ext_pos: np.ndarray
    ext_quat: np.ndarray
    ext_tick: np.ndarray
    resets: np.ndarray


class Estimator:
    """Estimates of all vehicles; methods are called under the world lock."""

    def __init__(self) -> None:
        self.s = EstimatorStates()

    def add(self, rng: np.random.Generator, position: Vector, now: float) -> int:
        i = self.s.append_row()
        heading = rng.uniform(0.0, 2.0 * math.pi)
        tilt = GRAVITY * math.radians(TILT_ERROR_DEG)
        self.s.drift_acc[i] = (tilt * math.cos(heading), tilt * math.sin(heading), rng.normal(0.0, ACC_BIAS_Z))
        self.boot(i, position, now)
        return i

    def boot(self, i: int, truth: Vector, now: float) -> None:
        s = self.s
        s.kind[i] = COMPLEMENTARY
        s.std_pos[i] = DEFAULTS["locSrv.extPosStdDev"]
        s.std_quat[i] = DEFAULTS["locSrv.extQuatStdDev"]
        s.pnacc[i] = (DEFAULTS["kalman.pNAcc_xy"], DEFAULTS["kalman.pNAcc_xy"], DEFAULTS["kalman.pNAcc_z"])
        s.initial[i] = 0.0
        s.max_pos[i] = DEFAULTS["kalman.maxPos"]
        s.max_vel[i] = DEFAULTS["kalman.maxVel"]
        s.ext_pos[i] = 0.0
        s.ext_quat[i] = (0.0, 0.0, 0.0, 1.0)
        s.ext_tick[i] = 0.0
        self.reset(i, truth, now)

    def reset(self, i: int, truth: Vector, now: float) -> None:
        """The Kalman filter re-initialised: position at kalman.initialX/Y/Z, large uncertainty."""
        s = self.s
        s.err[i] = s.initial[i, :3] - np.asarray(truth, dtype=float)
        s.verr[i] = 0.0
        s.var[i] = np.square(INITIAL_STD)
        s.last_meas[i] = now
        s.resets[i] += 1

    # --- parameters ------------------------------------------------------------------------------
    def set_param(self, i: int, name: str, value: float, truth: Sequence[float], now: float) -> bool:
        s = self.s
        if name == "stabilizer.estimator":
            kind = estimator_kind(value)
            if kind != s.kind[i]:
                s.kind[i] = kind
                if kind == KALMAN:
                    self.reset(i, truth, now)
            return True
        if name == "kalman.resetEstimation":
            if value:
                self.reset(i, truth, now)
            return True
        simple = {"locSrv.extPosStdDev": (s.std_pos, None), "locSrv.extQuatStdDev": (s.std_quat, None),
                  "kalman.pNAcc_xy": (s.pnacc, (0, 1)), "kalman.pNAcc_z": (s.pnacc, (2,)),
                  "kalman.initialX": (s.initial, (0,)), "kalman.initialY": (s.initial, (1,)),
                  "kalman.initialZ": (s.initial, (2,)), "kalman.initialYaw": (s.initial, (3,)),
                  "kalman.maxPos": (s.max_pos, None), "kalman.maxVel": (s.max_vel, None)}
        if name not in simple:
            return False
        target, cols = simple[name]
        if cols is None:
            target[i] = float(value)
        else:
            for c in cols:
                target[i, c] = float(value)
        return True

    # --- measurements -----------------------------------------------------------------------------
    def measure(self, i: int, position: Sequence[float], quaternion: Optional[Sequence[float]],
                truth: np.ndarray, now: float) -> bool:
        """An external position (and quaternion) for row ``i``; False when the estimator ignores it."""
        s = self.s
        m = np.asarray(position, dtype=float)
        s.ext_pos[i] = m
        if quaternion is not None:
            s.ext_quat[i] = np.asarray(quaternion, dtype=float)
        s.ext_tick[i] = round(now * 1000.0)
        if s.kind[i] != KALMAN or not np.all(np.isfinite(m)):
            return False
        # per axis in Python floats: the same IEEE arithmetic as numpy's, without its per-call cost
        # (this runs for every measurement of every vehicle)
        dt3 = max(now - float(s.last_meas[i]), 1e-3) ** 3
        std2 = float(s.std_pos[i]) ** 2
        err, verr, var = s.err[i].tolist(), s.verr[i].tolist(), s.var[i].tolist()
        for k, (pn, mk, tk) in enumerate(zip(s.pnacc[i].tolist(), m.tolist(), truth.tolist())):
            prior = _bounded(var[k] + pn * pn * dt3)
            gain = prior / (prior + std2)
            err[k] = (1.0 - gain) * err[k] + gain * (mk - tk)
            verr[k] *= 1.0 - max(gain, VELOCITY_GAIN_MIN)
            var[k] = _bounded((1.0 - gain) * prior)
        s.err[i], s.verr[i], s.var[i] = err, verr, var
        s.last_meas[i] = now
        return True

    # --- the tick ---------------------------------------------------------------------------------
    def update(self, tick: int, now: float, thrust: np.ndarray, truth_pos: np.ndarray) -> None:
        """Kalman prediction at 100 Hz: drift of the estimate while flying (``thrust`` (N,) > 0); the
        firmware's bounds."""
        if tick % PREDICT_EVERY or not len(self.s):
            return
        s = self.s
        kalman = s.kind == KALMAN
        if not np.count_nonzero(kalman):                 # estimator 1 everywhere: nothing drifts, nothing to bound
            return
        dt = PREDICT_EVERY * 1e-3
        coasting = kalman & (thrust > 0.0)
        if np.count_nonzero(coasting):
            acc = s.drift_acc * coasting[:, None]
            s.err += s.verr * dt + 0.5 * acc * dt * dt
            s.verr += acc * dt
        # the firmware resets the filter when its estimate leaves these bounds
        wild = kalman & ((np.abs(s.err + truth_pos).max(axis=1) > s.max_pos)
                                     | (np.abs(s.verr).max(axis=1) > s.max_vel))
        for i in np.flatnonzero(wild):
            self.reset(int(i), truth_pos[i], now)

    # --- the estimate -------------------------------------------------------------------------------
    def position(self, i: int, truth_pos: np.ndarray, ground_asl: float) -> np.ndarray:
        s = self.s
        if s.kind[i] == KALMAN:
            return truth_pos + s.err[i]
        return np.array([0.0, 0.0, truth_pos[2] + ground_asl])

    def velocity(self, i: int, truth_vel: np.ndarray) -> np.ndarray:
        s = self.s
        if s.kind[i] == KALMAN:
            return truth_vel + s.verr[i]
        return np.array([0.0, 0.0, truth_vel[2]])

    def row_estimate(self, i: int, truth_pos: List[float], truth_vel: List[float],
                     ground_asl: float) -> Tuple[List[float], List[float]]:
        """``position`` and ``velocity`` of row ``i`` as Python floats (the same sums)."""
        s = self.s
        if s.kind[i] == KALMAN:
            e, ve = s.err[i].tolist(), s.verr[i].tolist()
            return ([truth_pos[0] + e[0], truth_pos[1] + e[1], truth_pos[2] + e[2]],
                    [truth_vel[0] + ve[0], truth_vel[1] + ve[1], truth_vel[2] + ve[2]])
        return [0.0, 0.0, truth_pos[2] + ground_asl], [0.0, 0.0, truth_vel[2]]

    def positions(self, truth_pos: np.ndarray, ground_asl: float) -> np.ndarray:
        """Estimated positions (N,3) of all vehicles."""
        s = self.s
        kalman = (s.kind == KALMAN)[:, None]
        baro = np.zeros_like(truth_pos)
        baro[:, 2] = truth_pos[:, 2] + ground_asl
        return np.where(kalman, truth_pos + s.err, baro)

    def velocities(self, truth_vel: np.ndarray) -> np.ndarray:
        s = self.s
        kalman = (s.kind == KALMAN)[:, None]
        vz_only = np.zeros_like(truth_vel)
        vz_only[:, 2] = truth_vel[:, 2]
        return np.where(kalman, truth_vel + s.verr, vz_only)
