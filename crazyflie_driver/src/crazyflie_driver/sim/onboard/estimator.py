"""The onboard state estimate of every vehicle (numpy rows): what the firmware believes, not the truth.

``stabilizer.estimator`` 2 (Kalman) fuses external position/pose; 1 (complementary, also what 0
"auto" and an unbuilt 3 fall back to) ignores them: it knows no x/y position at all and takes
its height from the barometer. That is the trap users hit when they stream motion capture
without switching estimators, and it is kept.

The Kalman estimator is the firmware's error-state extended Kalman filter (``kalman.py``; docs/
simulation.md, "Onboard estimator"), run as the firmware's filter task: the accelerometer's raw
samples pass the firmware's 30 Hz low-pass (``imu_filter``) and are averaged with the gyro's
between predictions (100 Hz), process noise is added per 1 ms loop, external positions and poses
are queued and fused at the next loop (here the next even tick), then the attitude error
is folded back and the supervisor resets the filter when its state leaves ``kalman.maxPos`` /
``kalman.maxVel``. It starts from what the vehicle believes (``kalman.initial*``, level, at rest),
not from the truth, and its attitude is its own, driven by the biased, noisy gyro.
"""
from __future__ import annotations

import math
from typing import Dict, List, Optional, Protocol, Sequence, Tuple

import numpy as np

from crazyflie_driver.sim.onboard import kalman
from crazyflie_driver.sim.onboard.body import BodyRows
from crazyflie_driver.sim.onboard.imu_filter import ACC_LPF, lpf2p_steady, lpf2p_step
from crazyflie_driver.sim.vehicle_rows import Rows, Vector

COMPLEMENTARY, KALMAN = 1, 2
PREDICT_EVERY = 10                  # ticks (1 ms): the Kalman filter predicts at 100 Hz


class ImuSource(Protocol):
    """The IMU of every vehicle as the firmware's sensors task reads it (the room provides it)."""

    def acc_raw(self, samples: int) -> np.ndarray:
        """The accelerometer's next ``samples`` raw readings of every row, (samples, N, 3) m/s² in
        the body frame: the true specific force with the sensor's bias and noise, vibration
        included, before the firmware's low-pass filter."""
        ...

    def gyro_means(self, rows: np.ndarray, omega: np.ndarray, window_s: float) -> np.ndarray:
        """The mean filtered gyro readings (n,3, rad/s) of ``rows`` over ``window_s`` given their
        true mean body rates ``omega``."""
        ...

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


class EstimatorStates(Rows):
    FIELDS = {
        "kind": ((), np.int8),
        "exact": ((), bool),              # the estimate is the truth (reference runs of the controllers)
        "imu_sum": ((6,), float),         # filtered acc (m/s²), true body rate (rad/s), summed since the prediction
        "imu_n": ((), float),             # samples in imu_sum
        "acc_d1": ((3,), float),          # the accelerometer low-pass's delay elements, m/s²
        "acc_d2": ((3,), float),
        "acc_settled": ((), bool),        # ... hold the filter's state (False: set from the next sample)
        "predict_ms": ((), float),        # world ms of the last prediction
        "pending": ((), bool),            # an external position waits for the filter's next loop
        "pend_pos": ((3,), float),
        "pend_quat": ((4,), float),       # x, y, z, w
        "pend_pose": ((), bool),          # ... with an orientation
        "std_pos": ((), float),
        "std_quat": ((), float),
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
    exact: np.ndarray
    imu_sum: np.ndarray
    imu_n: np.ndarray
    acc_d1: np.ndarray
    acc_d2: np.ndarray
    acc_settled: np.ndarray
    predict_ms: np.ndarray
    pending: np.ndarray
    pend_pos: np.ndarray
    pend_quat: np.ndarray
    pend_pose: np.ndarray
    std_pos: np.ndarray
    std_quat: np.ndarray
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
        self.k = kalman.KalmanStates()
        self._any_pending = False             # a measurement waits in some row

    @property
    def models(self) -> Tuple[Rows, Rows]:
        return (self.s, self.k)

    def add(self, rng: np.random.Generator, position: Vector, now: float) -> int:
        i = self.s.append_row()
        self.k.append_row()
        self.boot(i, position, now)
        return i

    def boot(self, i: int, truth: Vector, now: float) -> None:
        s = self.s
        s.kind[i] = COMPLEMENTARY
        s.acc_settled[i] = False
        s.exact[i] = False
        s.std_pos[i] = DEFAULTS["locSrv.extPosStdDev"]
        s.std_quat[i] = DEFAULTS["locSrv.extQuatStdDev"]
        self.k.noise[i] = kalman.NOISE_DEFAULTS
        s.initial[i] = 0.0
        s.max_pos[i] = DEFAULTS["kalman.maxPos"]
        s.max_vel[i] = DEFAULTS["kalman.maxVel"]
        s.ext_pos[i] = 0.0
        s.ext_quat[i] = (0.0, 0.0, 0.0, 1.0)
        s.ext_tick[i] = 0.0
        self.reset(i, truth, now)

    def reset(self, i: int, truth: Vector, now: float) -> None:
        """The Kalman filter re-initialised: at kalman.initialX/Y/Z and initialYaw, level, at rest,
        uncertain of its position (the truth is not used: the filter knows only its parameters)."""
        s = self.s
        now_ms = round(now * 1000.0)
        kalman.initialise(self.k, i, s.initial[i], now_ms)
        s.imu_sum[i] = 0.0
        s.imu_n[i] = 0.0
        s.predict_ms[i] = now_ms
        s.pending[i] = False
        s.resets[i] += 1

    # --- parameters ------------------------------------------------------------------------------
    def set_param(self, i: int, name: str, value: float, truth: Sequence[float], now: float) -> bool:
        s = self.s
        if name == "stabilizer.estimator":
            kind = estimator_kind(value)
            if kind != s.kind[i]:
                s.kind[i] = kind
                if kind == KALMAN:
                    s.acc_settled[i] = False       # (its low-pass ran unobserved meanwhile)
                    self.reset(i, truth, now)
            return True
        if name == "kalman.resetEstimation":
            if value:
                self.reset(i, truth, now)
            return True
        simple = {"locSrv.extPosStdDev": (s.std_pos, None), "locSrv.extQuatStdDev": (s.std_quat, None),
                  "kalman.pNAcc_xy": (self.k.noise, (0,)), "kalman.pNAcc_z": (self.k.noise, (1,)),
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
        """An external position (and quaternion) for row ``i``, queued for the filter's next loop;
        False when the estimator ignores it."""
        # Python floats: this runs for every measurement of every vehicle
        s = self.s
        m = [float(v) for v in position]
        s.ext_pos[i] = m
        if quaternion is not None:
            s.ext_quat[i] = [float(v) for v in quaternion]
        s.ext_tick[i] = round(now * 1000.0)
        if s.kind[i] != KALMAN or not all(map(math.isfinite, m)):
            return False
        if s.exact[i]:
            return True
        if s.pending[i]:                       # two in one loop: the firmware's queue takes both in order
            self._fuse(np.array([i]), round(now * 1000.0))
            kalman.finalize(self.k, np.array([i]))
        s.pend_pos[i] = m
        pose = quaternion is not None and all(map(math.isfinite, s.ext_quat[i].tolist()))
        s.pend_pose[i] = pose
        if pose:
            s.pend_quat[i] = s.ext_quat[i]
        s.pending[i] = True
        self._any_pending = True
        return True

    def _fuse(self, rows: np.ndarray, now_ms: float) -> None:
        """The queued positions and poses of ``rows`` (process noise first, as the filter's loop)."""
        s, k = self.s, self.k
        kalman.add_process_noise(k, rows, now_ms)       # (nothing to add when the loop did already)
        kalman.update_position(k, rows, s.pend_pos[rows], s.std_pos[rows])
        poses = rows[s.pend_pose[rows]]
        if len(poses):
            kalman.update_attitude(k, poses, s.pend_quat[poses], s.std_quat[poses])
        s.pending[rows] = False

    # --- the tick ---------------------------------------------------------------------------------
    def update(self, tick: int, now: float, thrust: np.ndarray, bodies: BodyRows, samples: int,
               imu: Optional[ImuSource] = None) -> None:
        """One loop of the filter task, called every ``samples`` ticks: the IMU's samples of those
        ticks accumulated, the prediction every PREDICT_EVERY ticks, process noise, queued
        measurements, fold-back, bounds. ``thrust`` (N,) > 0 means flying; ``bodies`` gives the
        true specific force and body rates; ``imu`` their readings (noise-free without it)."""
        s = self.s
        if not len(s):
            return
        filtering = (s.kind == KALMAN) & ~s.exact
        if not filtering.any():                # estimator 1 everywhere: no filter runs
            return
        self._accumulate(bodies, samples, imu)
        predicting = tick % PREDICT_EVERY == 0
        if not predicting and not self._any_pending:
            return
        rows = np.flatnonzero(filtering)
        self._any_pending = False
        now_ms = round(now * 1000.0)
        touched = s.pending[rows]
        if predicting:
            predicted = self._predict(rows, now_ms, thrust, imu)
            touched = predicted | s.pending[rows]
        if np.any(touched):
            self._loop_end(rows[touched], now_ms, now)

    def _accumulate(self, bodies: BodyRows, samples: int, imu: Optional[ImuSource]) -> None:
        """The IMU samples of the last ``samples`` ticks of every row: the accelerometer's through
        the firmware's low-pass, then summed for the next prediction (the bodies move once per
        control period, so the true values are the same for these samples)."""
        s = self.s
        if imu is not None:
            raw = imu.acc_raw(samples)
        else:
            raw = np.broadcast_to(bodies.specific_force, (samples,) + bodies.specific_force.shape)
        fresh = ~s.acc_settled
        if fresh.any():
            steady = lpf2p_steady(ACC_LPF, raw[0][fresh])
            s.acc_d1[fresh] = steady
            s.acc_d2[fresh] = steady
            s.acc_settled[fresh] = True
        d1, d2 = s.acc_d1, s.acc_d2
        acc = lpf2p_step(ACC_LPF, d1, d2, raw[0])
        for j in range(1, samples):
            acc = acc + lpf2p_step(ACC_LPF, d1, d2, raw[j])
        s.imu_sum[:, :3] += acc
        s.imu_sum[:, 3:] += samples * bodies.omega
        s.imu_n += float(samples)

    def _predict(self, rows: np.ndarray, now_ms: float, thrust: np.ndarray,
                 imu: Optional[ImuSource]) -> np.ndarray:
        """The prediction of ``rows`` on their mean readings since the last one; which rows did."""
        s, k = self.s, self.k
        mean = s.imu_sum[rows] / np.maximum(s.imu_n[rows], 1.0)[:, None]
        dt = (now_ms - s.predict_ms[rows]) / 1000.0
        acc = mean[:, :3]
        gyro = imu.gyro_means(rows, mean[:, 3:], float(PREDICT_EVERY) * 1e-3) if imu is not None else mean[:, 3:]
        ok = dt > 0.0
        # the firmware adds the process noise of every 1 ms loop as it runs: the loops since the
        # last prediction go in before this one's A·P·A' (only the current loop's after it)
        kalman.add_process_noise(k, rows[ok], now_ms - 1.0)
        rows_p = rows[ok]
        acc, gyro, dt = acc[ok], gyro[ok], dt[ok]
        # all rows share one loop period but a reset row may have a shorter one
        for step in np.unique(dt):
            sel = dt == step
            kalman.predict(k, rows_p[sel], acc[sel], gyro[sel], float(step), thrust[rows_p[sel]] > 0.0)
        s.predict_ms[rows_p] = now_ms
        s.imu_sum[rows] = 0.0
        s.imu_n[rows] = 0.0
        return ok

    def _loop_end(self, done: np.ndarray, now_ms: float, now: float) -> None:
        """Process noise, the queued measurements and the fold-back of ``done``; the supervisor's
        bounds."""
        s, k = self.s, self.k
        kalman.add_process_noise(k, done, now_ms)
        waiting = done[s.pending[done]]
        if len(waiting):
            self._fuse(waiting, now_ms)
        kalman.finalize(k, done)
        # the supervisor resets the filter when its state leaves these bounds
        wild = ((np.abs(k.S[done, 0:3]).max(axis=1) > s.max_pos[done])
                | (np.abs(k.S[done, 3:6]).max(axis=1) > s.max_vel[done]))
        for i in done[wild]:
            self.reset(int(i), (0.0, 0.0, 0.0), now)

    # --- the estimate -------------------------------------------------------------------------------
    def position(self, i: int, truth_pos: np.ndarray, ground_asl: float) -> np.ndarray:
        s = self.s
        if s.kind[i] == KALMAN:
            return np.array(truth_pos, dtype=float) if s.exact[i] else self.k.S[i, 0:3].copy()
        return np.array([0.0, 0.0, truth_pos[2] + ground_asl])

    def velocity(self, i: int, truth_vel: np.ndarray) -> np.ndarray:
        s = self.s
        if s.kind[i] == KALMAN:
            return np.array(truth_vel, dtype=float) if s.exact[i] else self.k.R[i] @ self.k.S[i, 3:6]
        return np.array([0.0, 0.0, truth_vel[2]])

    def quaternion(self, i: int) -> Optional[np.ndarray]:
        """The filter's attitude (x, y, z, w) of row ``i``; None where no filter runs."""
        s = self.s
        return kalman.quaternion_xyzw(self.k, i) if s.kind[i] == KALMAN and not s.exact[i] else None

    def row_estimate(self, i: int, truth_pos: List[float], truth_vel: List[float],
                     ground_asl: float) -> Tuple[List[float], List[float]]:
        """``position`` and ``velocity`` of row ``i`` as Python floats."""
        s = self.s
        if s.kind[i] == KALMAN:
            if s.exact[i]:
                return list(truth_pos), list(truth_vel)
            return self.k.S[i, 0:3].tolist(), (self.k.R[i] @ self.k.S[i, 3:6]).tolist()
        return [0.0, 0.0, truth_pos[2] + ground_asl], [0.0, 0.0, truth_vel[2]]

    def positions(self, truth_pos: np.ndarray, ground_asl: float) -> np.ndarray:
        """Estimated positions (N,3) of all vehicles."""
        s = self.s
        kalman_rows = (s.kind == KALMAN)[:, None]
        baro = np.zeros_like(truth_pos)
        baro[:, 2] = truth_pos[:, 2] + ground_asl
        filtered = np.where(s.exact[:, None], truth_pos, self.k.S[:, 0:3])
        return np.where(kalman_rows, filtered, baro)

    def velocities(self, truth_vel: np.ndarray) -> np.ndarray:
        s = self.s
        kalman_rows = (s.kind == KALMAN)[:, None]
        vz_only = np.zeros_like(truth_vel)
        vz_only[:, 2] = truth_vel[:, 2]
        filtered = np.where(s.exact[:, None], truth_vel, kalman.world_velocity(self.k))
        return np.where(kalman_rows, filtered, vz_only)
