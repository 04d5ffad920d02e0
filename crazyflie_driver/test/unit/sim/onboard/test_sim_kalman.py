"""The simulated firmware's Kalman filter against the published algorithm.

``Reference`` is a direct single-vehicle transcription of the filter as Mueller, Hamer & D'Andrea
(ICRA 2015) and Mueller, Hehn & D'Andrea (JGCN 2016) give it and the Crazyflie firmware runs it
(kalman_core.c, mm_position.c, mm_pose.c): element by element, with plain Python loops. The
vectorised filter runs three vehicles with different inputs at once and must follow it; closed-form
cases pin the update gain, the covariance convergence and the attitude fold-back.
"""
from __future__ import annotations

import math
from typing import List

import numpy as np
import pytest

from crazyflie_driver.sim.onboard import kalman

G = 9.81


def qmul(a, b):
    """Hamilton product of w, x, y, z quaternions."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return [aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw]


def qexp(v, eps=0.0):
    """The quaternion of the rotation vector ``v`` (the firmware adds ``eps`` to the angle)."""
    a = math.sqrt(sum(c * c for c in v)) + eps
    if a < 1e-12:
        return [1.0, 0.0, 0.0, 0.0]
    return [math.cos(a / 2)] + [math.sin(a / 2) * c / a for c in v]


def normalised(q):
    """The firmware's normalisation: by the norm + 1e-6."""
    n = math.sqrt(sum(c * c for c in q)) + 1e-6
    return [c / n for c in q]


def qrot(q):
    w, x, y, z = q
    return [[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]]


class Reference:
    """One vehicle's filter, transcribed from the equations (lists, loops, no vectorisation)."""

    def __init__(self, x, y, z, yaw, noise=kalman.NOISE_DEFAULTS):
        self.S = [x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        self.q0 = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        self.q = list(self.q0)
        self.R = qrot(self.q)
        std = [100.0, 100.0, 1.0, 0.01, 0.01, 0.01, 0.01, 0.01, 0.01]
        self.P = [[std[i] ** 2 if i == j else 0.0 for j in range(9)] for i in range(9)]
        self.noise = noise

    def _bound(self):
        P = self.P
        for i in range(9):
            for j in range(i, 9):
                p = 0.5 * P[i][j] + 0.5 * P[j][i]
                if math.isnan(p) or p > 100.0:
                    p = 100.0
                elif i == j and p < 1e-6:
                    p = 1e-6
                P[i][j] = P[j][i] = p

    def _apat(self, A):
        P = self.P
        AP = [[sum(A[i][k] * P[k][j] for k in range(9)) for j in range(9)] for i in range(9)]
        self.P = [[sum(AP[i][k] * A[j][k] for k in range(9)) for j in range(9)] for i in range(9)]

    @staticmethod
    def _att_block(A, d0, d1, d2):
        A[6][6], A[6][7], A[6][8] = 1 - d1 * d1 / 2 - d2 * d2 / 2, d2 + d0 * d1 / 2, -d1 + d0 * d2 / 2
        A[7][6], A[7][7], A[7][8] = -d2 + d0 * d1 / 2, 1 - d0 * d0 / 2 - d2 * d2 / 2, d0 + d1 * d2 / 2
        A[8][6], A[8][7], A[8][8] = d1 + d0 * d2 / 2, -d0 + d1 * d2 / 2, 1 - d0 * d0 / 2 - d1 * d1 / 2

    def predict(self, acc, gyro, dt, flying):
        S, R = self.S, self.R
        A = [[1.0 if i == j else 0.0 for j in range(9)] for i in range(9)]
        for r in range(3):
            for c in range(3):
                A[r][3 + c] = R[r][c] * dt
            A[r][6] = (S[4] * R[r][2] - S[5] * R[r][1]) * dt
            A[r][7] = (-S[3] * R[r][2] + S[5] * R[r][0]) * dt
            A[r][8] = (S[3] * R[r][1] - S[4] * R[r][0]) * dt
        wx, wy, wz = gyro
        A[4][3], A[5][3], A[3][4], A[5][4], A[3][5], A[4][5] = -wz * dt, wy * dt, wz * dt, -wx * dt, -wy * dt, wx * dt
        A[4][6], A[5][6] = -G * R[2][2] * dt, G * R[2][1] * dt
        A[3][7], A[5][7] = G * R[2][2] * dt, -G * R[2][0] * dt
        A[3][8], A[4][8] = -G * R[2][1] * dt, G * R[2][0] * dt
        self._att_block(A, wx * dt / 2, wy * dt / 2, wz * dt / 2)
        self._apat(A)
        ax, ay, az = (0.0, 0.0, acc[2]) if flying else acc
        d = [S[3] * dt + ax * dt * dt / 2, S[4] * dt + ay * dt * dt / 2, S[5] * dt + az * dt * dt / 2]
        for r in range(3):
            S[r] += R[r][0] * d[0] + R[r][1] * d[1] + R[r][2] * d[2]
        S[2] -= G * dt * dt / 2
        px, py, pz = S[3], S[4], S[5]
        S[3] += dt * (ax + wz * py - wy * pz - G * R[2][0])
        S[4] += dt * (ay - wz * px + wx * pz - G * R[2][1])
        S[5] += dt * (az + wy * px - wx * py - G * R[2][2])
        q = qmul(self.q, qexp([wx * dt, wy * dt, wz * dt], 1e-6))
        if not flying:
            q = [0.999 * a + 0.001 * b for a, b in zip(q, self.q0)]
        self.q = normalised(q)

    def process_noise(self, loops):
        acc_xy, acc_z, vel, pos, att, g_rp, g_yaw = self.noise
        dt = 1e-3
        for _ in range(loops):
            add = [(acc_xy * dt * dt + vel * dt + pos) ** 2] * 2 + [(acc_z * dt * dt + vel * dt + pos) ** 2] \
                + [(acc_xy * dt + vel) ** 2] * 2 + [(acc_z * dt + vel) ** 2] \
                + [(g_rp * dt + att) ** 2] * 2 + [(g_yaw * dt + att) ** 2]
            for i in range(9):
                self.P[i][i] += add[i]
            self._bound()

    def scalar_update(self, idx, error, std):
        P, R = self.P, std * std
        PHt = [P[i][idx] for i in range(9)]
        K = [PHt[i] / (PHt[idx] + R) for i in range(9)]
        for i in range(9):
            self.S[i] += K[i] * error
        M = [[(1.0 if i == j else 0.0) - (K[i] if j == idx else 0.0) for j in range(9)] for i in range(9)]
        self._apat(M)
        for i in range(9):
            for j in range(9):
                self.P[i][j] += K[i] * R * K[j]
        self._bound()

    def position(self, pos, std):
        for i in range(3):
            self.scalar_update(i, pos[i] - self.S[i], std)

    def pose(self, pos, quat_xyzw, std_pos, std_quat):
        self.position(pos, std_pos)
        m = [quat_xyzw[3]] + list(quat_xyzw[:3])
        inv = [self.q[0], -self.q[1], -self.q[2], -self.q[3]]
        res = qmul(inv, m)
        err = [2.0 * c / res[0] for c in res[1:]]
        for i in range(3):
            self.scalar_update(6 + i, err[i], std_quat)

    def finalize(self):
        v = self.S[6:9]
        if any(abs(c) > 0.1e-3 for c in v) and all(abs(c) < 10 for c in v):
            self.q = normalised(qmul(self.q, qexp(v, 1e-6)))
            A = [[1.0 if i == j else 0.0 for j in range(9)] for i in range(9)]
            self._att_block(A, v[0] / 2, v[1] / 2, v[2] / 2)
            self._apat(A)
        self.R = qrot(self.q)
        self.S[6:9] = [0.0, 0.0, 0.0]
        self._bound()


def attitude_of(acc_world):
    """Level-yaw attitude (w x y z) whose body z is along the thrust direction."""
    z = acc_world / np.linalg.norm(acc_world)
    axis = np.cross([0.0, 0.0, 1.0], z)
    s = np.linalg.norm(axis)
    angle = math.atan2(s, z[2])
    return qexp(list(axis / s * angle)) if s > 1e-12 else [1.0, 0.0, 0.0, 0.0]


def trajectory(kind: str, seconds: float, phase: float):
    """Per ms: true position, quaternion (w x y z), body specific force, body rate of a vehicle
    hovering or flying a 0.5 m circle at 1 rad/s (tilted so that its thrust makes the acceleration)."""
    out = []
    prev_q = None
    steps = int(seconds * 1000)
    for k in range(steps + 1):
        t = k / 1000.0
        if kind == "hover":
            p, a = np.array([0.1, -0.2, 0.5]), np.zeros(3)
        else:
            w, r = 1.0, 0.5
            p = np.array([r * math.cos(w * t + phase), r * math.sin(w * t + phase), 0.5])
            a = -w * w * (p - np.array([0.0, 0.0, 0.5]))
        f_world = a + np.array([0.0, 0.0, G])
        q = attitude_of(f_world)
        Rm = np.array(qrot(q))
        f_body = Rm.T @ f_world
        if prev_q is None:
            omega = np.zeros(3)
        else:
            dq = qmul([prev_q[0], -prev_q[1], -prev_q[2], -prev_q[3]], q)
            omega = 2.0 * np.array(dq[1:]) * 1000.0
        prev_q = q
        out.append((p, q, f_body, omega))
    return out


def run(kind: str, rate_hz: float, seconds: float = 4.0, n: int = 3, seed: int = 3, pose: bool = False):
    """The vectorised filter (n vehicles) and the reference (one per vehicle) on the same inputs
    (IMU means with noise and biases, noisy positions): their estimates and the true positions."""
    rng = np.random.default_rng(seed)
    trajs = [trajectory(kind, seconds, 0.7 * v) for v in range(n)]
    k = kalman.KalmanStates()
    refs: List[Reference] = []
    for v in range(n):
        k.append_row()
        k.noise[v] = kalman.NOISE_DEFAULTS
        p0 = trajs[v][0][0]
        kalman.initialise(k, v, np.array([p0[0], p0[1], p0[2], 0.0]), 0.0)
        refs.append(Reference(p0[0], p0[1], p0[2], 0.0))
    rows = np.arange(n)
    bias_g, bias_a = rng.normal(0, 0.001, (n, 3)), rng.normal(0, 0.05, (n, 3))
    every = int(round(1000 / rate_hz))
    errs_v, errs_r = [], []
    for ms in range(10, int(seconds * 1000) + 1, 10):
        window = [trajs[v][ms - 9:ms + 1] for v in range(n)]
        acc = np.array([np.mean([s[2] for s in w], axis=0) for w in window]) + bias_a + rng.normal(0, 0.3, (n, 3))
        gyro = np.array([np.mean([s[3] for s in w], axis=0) for w in window]) + bias_g + rng.normal(0, 0.005, (n, 3))
        flying = np.ones(n, bool)
        kalman.predict(k, rows, acc, gyro, 0.01, flying)
        kalman.add_process_noise(k, rows, float(ms))
        for v in range(n):
            refs[v].predict(acc[v].tolist(), gyro[v].tolist(), 0.01, True)
            refs[v].process_noise(10)
        if ms % every == 0:
            truth = np.array([trajs[v][ms][0] for v in range(n)])
            meas = truth + rng.normal(0, 0.0005, (n, 3))
            std = np.full(n, 0.01)
            kalman.update_position(k, rows, meas, std)
            quats = np.array([[*trajs[v][ms][1][1:], trajs[v][ms][1][0]] for v in range(n)])
            if pose:
                kalman.update_attitude(k, rows, quats, np.full(n, 4.5e-3))
            for v in range(n):
                if pose:
                    refs[v].pose(meas[v].tolist(), quats[v].tolist(), 0.01, 4.5e-3)
                else:
                    refs[v].position(meas[v].tolist(), 0.01)
        kalman.finalize(k, rows)
        for v in range(n):
            refs[v].finalize()
        truth = np.array([trajs[v][ms][0] for v in range(n)])
        if ms >= 1000:
            errs_v.append(np.linalg.norm(k.S[:, :3] - truth, axis=1))
            errs_r.append(np.linalg.norm(np.array([r.S[:3] for r in refs]) - truth, axis=1))
    return k, refs, np.array(errs_v), np.array(errs_r)


@pytest.mark.parametrize("kind", ["hover", "circle"])
@pytest.mark.parametrize("rate_hz", [100.0, 10.0, 2.0])
def test_fleet_filter_follows_the_published_algorithm(kind, rate_hz):
    k, refs, errs_v, errs_r = run(kind, rate_hz, seconds=3.0 if rate_hz > 2 else 4.0)
    for v, ref in enumerate(refs):
        assert np.allclose(k.S[v], ref.S, atol=1e-9), (v, k.S[v], ref.S)
        assert np.allclose(k.P[v], np.array(ref.P), rtol=1e-7, atol=1e-12)
        assert np.allclose(k.q[v], ref.q, atol=1e-10)
    mean_v, mean_r = errs_v.mean(), errs_r.mean()
    assert abs(mean_v - mean_r) <= 0.3 * mean_r, (mean_v, mean_r)
    # the estimate is worth having: centimetres at most, coarser with rarer fixes
    assert mean_r < {100.0: 0.01, 10.0: 0.05, 2.0: 0.2}[rate_hz], mean_r


def test_pose_updates_follow_the_published_algorithm():
    k, refs, _, _ = run("circle", 100.0, seconds=1.5, pose=True)
    for v, ref in enumerate(refs):
        assert np.allclose(k.S[v], ref.S, atol=1e-9)
        assert np.allclose(k.P[v], np.array(ref.P), rtol=1e-7, atol=1e-12)
        assert np.allclose(k.q[v], ref.q, atol=1e-10)


def fresh(n=1):
    k = kalman.KalmanStates()
    for v in range(n):
        k.append_row()
        k.noise[v] = kalman.NOISE_DEFAULTS
        kalman.initialise(k, v, np.zeros(4), 0.0)
    return k


def test_a_position_step_moves_the_estimate_by_the_kalman_gain():
    k = fresh()
    k.P[0] = np.diag([0.04, 0.04, 0.04, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4])
    std = 0.1
    kalman.update_position(k, np.array([0]), np.array([[1.0, 0.0, 0.0]]), np.array([std]))
    gain = 0.04 / (0.04 + std * std)                     # P / (P + σ²) for an uncorrelated state
    assert k.S[0, 0] == pytest.approx(gain * 1.0, rel=1e-12)
    assert k.P[0, 0, 0] == pytest.approx((1 - gain) * 0.04, rel=1e-12)
    assert k.S[0, 1] == 0.0 and k.S[0, 2] == 0.0


def test_a_stationary_vehicle_s_covariance_converges_below_the_measurement_noise():
    k = fresh()
    rows = np.array([0])
    std = 0.01
    history = []
    for ms in range(10, 5001, 10):
        kalman.predict(k, rows, np.array([[0.0, 0.0, G]]), np.zeros((1, 3)), 0.01, np.array([False]))
        kalman.add_process_noise(k, rows, float(ms))
        kalman.update_position(k, rows, np.zeros((1, 3)), np.array([std]))
        kalman.finalize(k, rows)
        history.append(k.P[0, 0, 0])
    assert history[0] < std * std                          # the first fix takes the 100 m prior down
    assert history[-1] < 0.5 * std * std                   # averaging: below one measurement's variance
    assert abs(history[-1] - history[-101]) < 0.01 * history[-1]   # converged
    assert np.allclose(k.P[0], k.P[0].T) and np.all(np.diag(k.P[0]) >= kalman.MIN_COVARIANCE)


def test_the_attitude_error_is_folded_into_the_quaternion():
    k = fresh()
    v = np.array([0.02, -0.01, 0.005])
    k.S[0, 6:9] = v
    k.P[0] = np.diag([0.04, 0.04, 0.01, 1e-3, 1e-3, 1e-3, 4e-4, 3e-4, 2e-4])
    k.P[0, 6, 7] = k.P[0, 7, 6] = 1e-4
    P_before = k.P[0].copy()
    kalman.finalize(k, np.array([0]))
    expected = qexp(list(v))                               # from the identity attitude
    assert np.allclose(k.q[0], expected, atol=1e-6)
    assert np.allclose(k.R[0], qrot(k.q[0]), atol=1e-12)
    assert np.all(k.S[0, 6:9] == 0.0)
    A = np.eye(9)
    d = v / 2
    A[6:9, 6:9] = [[1 - d[1] ** 2 / 2 - d[2] ** 2 / 2, d[2] + d[0] * d[1] / 2, -d[1] + d[0] * d[2] / 2],
                   [-d[2] + d[0] * d[1] / 2, 1 - d[0] ** 2 / 2 - d[2] ** 2 / 2, d[0] + d[1] * d[2] / 2],
                   [d[1] + d[0] * d[2] / 2, -d[0] + d[1] * d[2] / 2, 1 - d[0] ** 2 / 2 - d[1] ** 2 / 2]]
    assert np.allclose(k.P[0], A @ P_before @ A.T, rtol=1e-12, atol=1e-18)
    # below the threshold nothing is folded, but the error is still cleared
    k.S[0, 6:9] = (0.5e-4, 0.0, 0.0)
    q = k.q[0].copy()
    kalman.finalize(k, np.array([0]))
    assert np.array_equal(k.q[0], q) and np.all(k.S[0, 6:9] == 0.0)


def test_an_orientation_fix_turns_the_attitude_towards_it():
    k = fresh()
    k.P[0, 6:9, 6:9] = np.diag([1e-2, 1e-2, 1e-2])
    yaw = 0.2
    measured = [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]
    kalman.update_attitude(k, np.array([0]), np.array([measured]), np.array([4.5e-3]))
    kalman.finalize(k, np.array([0]))
    est_yaw = 2 * math.atan2(k.q[0, 3], k.q[0, 0])
    # residual 2·tan(yaw/2) weighted by P/(P+σ²)
    assert est_yaw == pytest.approx(2 * math.tan(yaw / 2) * 1e-2 / (1e-2 + 4.5e-3 ** 2), rel=1e-3)
