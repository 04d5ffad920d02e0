"""The firmware's error-state extended Kalman filter, for every vehicle at once (numpy rows).

Follows the filter of Mueller, Hamer & D'Andrea (ICRA 2015) with the covariance correction of
Mueller, Hehn & D'Andrea (JGCN 2016), as the Crazyflie firmware runs it (docs/simulation.md,
"Onboard estimator"): a 9-element state (position in the world frame, velocity in the body frame,
attitude error) beside the attitude quaternion, which the attitude error is folded into after
every update. The IMU drives the prediction (100 Hz, on the mean of the samples since the last
one); external positions and poses update it with one scalar update per component (Joseph
form, then the covariance made symmetric and bounded).

Every function here takes the rows it works on (an index array), so that the caller chooses which
vehicles predict, update or finalize; nothing loops over vehicles in Python.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from crazyflie_driver.sim.vehicle_rows import Rows

GRAVITY = 9.81                     # m/s², the firmware's GRAVITY_MAGNITUDE
STATE_DIM = 9
X, PX, D0 = 0, 3, 6                # first index of position, body velocity and attitude error
MAX_COVARIANCE = 100.0             # covariance entries above are clamped (and NaN replaced) to this
MIN_COVARIANCE = 1e-6              # diagonal entries below are raised to this
EPS = 1e-6                         # added to norms, as the firmware
LOOP_S = 1e-3                      # s, the filter task's loop (process noise is added per loop)
FOLD_MIN, FOLD_MAX = 0.1e-3, 10.0  # rad, attitude errors folded into the quaternion lie in between

# kalmanCoreParams_t defaults (firmware, quadrotor build)
STD_INITIAL_POSITION_XY = 100.0    # m
STD_INITIAL_POSITION_Z = 1.0       # m
STD_INITIAL_VELOCITY = 0.01        # m/s
STD_INITIAL_ATTITUDE_RP = 0.01     # rad
STD_INITIAL_ATTITUDE_YAW = 0.01    # rad
ATTITUDE_REVERSION = 0.001         # per prediction on the ground, towards the initial attitude
# process noise columns: pNAcc_xy (m/s²), pNAcc_z (m/s²), pNVel (m/s), pNPos (m), pNAtt (rad),
# mNGyro_rollpitch (rad/s), mNGyro_yaw (rad/s)
NOISE_DEFAULTS = (0.5, 1.0, 0.0, 0.0, 0.0, 0.1, 0.1)


class KalmanStates(Rows):
    FIELDS = {
        "S": ((STATE_DIM,), float),             # x, y, z (m, world); px, py, pz (m/s, body); d0, d1, d2 (rad)
        "q": ((4,), float),                     # attitude, w x y z, body -> world
        "q_initial": ((4,), float),             # attitude after a reset (kalman.initialYaw)
        "R": ((3, 3), float),                   # rotation matrix of q as of the last finalize
        "P": ((STATE_DIM, STATE_DIM), float),   # covariance of S
        "noise": ((7,), float),                 # NOISE_DEFAULTS' columns
        "noise_ms": ((), float),                # world ms up to which process noise was added
    }

    # The columns (one row per vehicle; shapes and dtypes in FIELDS), declared for the type checker.
    S: np.ndarray
    q: np.ndarray
    q_initial: np.ndarray
    R: np.ndarray
    P: np.ndarray
    noise: np.ndarray
    noise_ms: np.ndarray


def initialise(k: KalmanStates, i: int, initial: np.ndarray, now_ms: float) -> None:
    """Row ``i`` as kalmanCoreInit leaves it: at ``initial`` (x, y, z m, yaw rad), at rest, level."""
    k.S[i] = 0.0
    k.S[i, :3] = initial[:3]
    yaw = float(initial[3])
    k.q_initial[i] = (math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0))
    k.q[i] = k.q_initial[i]
    k.R[i] = np.eye(3)
    k.P[i] = np.diag(np.square([STD_INITIAL_POSITION_XY, STD_INITIAL_POSITION_XY, STD_INITIAL_POSITION_Z]
                               + [STD_INITIAL_VELOCITY] * 3
                               + [STD_INITIAL_ATTITUDE_RP, STD_INITIAL_ATTITUDE_RP, STD_INITIAL_ATTITUDE_YAW]))
    k.noise_ms[i] = now_ms


def bound(P: np.ndarray) -> np.ndarray:
    """Covariances (n,9,9) made symmetric, NaN and entries over the ceiling set to it, the diagonal
    kept above the floor (the firmware does this after every step)."""
    P = 0.5 * (P + P.transpose(0, 2, 1))
    P[np.isnan(P) | (P > MAX_COVARIANCE)] = MAX_COVARIANCE
    diag = P[:, np.arange(STATE_DIM), np.arange(STATE_DIM)]
    P[:, np.arange(STATE_DIM), np.arange(STATE_DIM)] = np.maximum(diag, MIN_COVARIANCE)
    return P


def _rotation_block(d: np.ndarray) -> np.ndarray:
    """(n,3,3): the second-order approximation of exp(-[[d]]) that rotates the attitude covariance
    (Mueller, Hehn & D'Andrea 2016), ``d`` (n,3) half the rotation vector."""
    d0, d1, d2 = d[:, 0], d[:, 1], d[:, 2]
    out = np.empty((len(d), 3, 3))
    out[:, 0, 0] = 1.0 - d1 * d1 / 2.0 - d2 * d2 / 2.0
    out[:, 0, 1] = d2 + d0 * d1 / 2.0
    out[:, 0, 2] = -d1 + d0 * d2 / 2.0
    out[:, 1, 0] = -d2 + d0 * d1 / 2.0
    out[:, 1, 1] = 1.0 - d0 * d0 / 2.0 - d2 * d2 / 2.0
    out[:, 1, 2] = d0 + d1 * d2 / 2.0
    out[:, 2, 0] = d1 + d0 * d2 / 2.0
    out[:, 2, 1] = -d0 + d1 * d2 / 2.0
    out[:, 2, 2] = 1.0 - d0 * d0 / 2.0 - d1 * d1 / 2.0
    return out


def _rotate_by(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """q ⊗ exp(v) for quaternions (n,4) w x y z and body rotation vectors (n,3), not normalised."""
    angle = np.sqrt(np.einsum("ij,ij->i", v, v)) + EPS
    ca, sa = np.cos(angle / 2.0), np.sin(angle / 2.0) / angle
    dq0, dq1, dq2, dq3 = ca, sa * v[:, 0], sa * v[:, 1], sa * v[:, 2]
    q0, q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([dq0 * q0 - dq1 * q1 - dq2 * q2 - dq3 * q3,
                     dq1 * q0 + dq0 * q1 + dq3 * q2 - dq2 * q3,
                     dq2 * q0 - dq3 * q1 + dq0 * q2 + dq1 * q3,
                     dq3 * q0 + dq2 * q1 - dq1 * q2 + dq0 * q3], axis=1)


def _normalised(q: np.ndarray) -> np.ndarray:
    return q / (np.sqrt(np.einsum("ij,ij->i", q, q)) + EPS)[:, None]


def rotation(q: np.ndarray) -> np.ndarray:
    """(n,3,3) body -> world rotation matrices of quaternions (n,4) w x y z."""
    q0, q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    r[:, 0, 1] = 2 * q1 * q2 - 2 * q0 * q3
    r[:, 0, 2] = 2 * q1 * q3 + 2 * q0 * q2
    r[:, 1, 0] = 2 * q1 * q2 + 2 * q0 * q3
    r[:, 1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    r[:, 1, 2] = 2 * q2 * q3 - 2 * q0 * q1
    r[:, 2, 0] = 2 * q1 * q3 - 2 * q0 * q2
    r[:, 2, 1] = 2 * q2 * q3 + 2 * q0 * q1
    r[:, 2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    return r


def predict(k: KalmanStates, rows: np.ndarray, acc: np.ndarray, gyro: np.ndarray, dt: float,
            flying: np.ndarray) -> None:
    """The prediction over ``dt`` (s) of ``rows`` from the mean accelerometer (n,3, m/s², body) and
    gyro (n,3, rad/s) readings. Flying rows take thrust along body z only; on the ground the
    accelerometer's full vector counts and the attitude creeps back to the initial one."""
    n = len(rows)
    S, R, P = k.S[rows], k.R[rows], k.P[rows]
    px, py, pz = S[:, 3], S[:, 4], S[:, 5]
    wx, wy, wz = gyro[:, 0], gyro[:, 1], gyro[:, 2]
    A = np.zeros((n, STATE_DIM, STATE_DIM))
    idx = np.arange(STATE_DIM)
    A[:, idx, idx] = 1.0
    A[:, 0:3, 3:6] = R * dt
    # position w.r.t. the attitude error: R [[p]]^T columns
    A[:, 0:3, 6] = (py[:, None] * R[:, :, 2] - pz[:, None] * R[:, :, 1]) * dt
    A[:, 0:3, 7] = (-px[:, None] * R[:, :, 2] + pz[:, None] * R[:, :, 0]) * dt
    A[:, 0:3, 8] = (px[:, None] * R[:, :, 1] - py[:, None] * R[:, :, 0]) * dt
    # body velocity w.r.t. itself (the rotating frame; drag is zero on the quadrotor)
    A[:, 4, 3] = -wz * dt
    A[:, 5, 3] = wy * dt
    A[:, 3, 4] = wz * dt
    A[:, 5, 4] = -wx * dt
    A[:, 3, 5] = -wy * dt
    A[:, 4, 5] = wx * dt
    # body velocity w.r.t. the attitude error (gravity)
    g = GRAVITY * dt
    A[:, 4, 6] = -g * R[:, 2, 2]
    A[:, 5, 6] = g * R[:, 2, 1]
    A[:, 3, 7] = g * R[:, 2, 2]
    A[:, 5, 7] = -g * R[:, 2, 0]
    A[:, 3, 8] = -g * R[:, 2, 1]
    A[:, 4, 8] = g * R[:, 2, 0]
    A[:, 6:9, 6:9] = _rotation_block(gyro * (dt / 2.0))
    k.P[rows] = A @ P @ A.transpose(0, 2, 1)

    # the state: thrust along body z when flying, the full specific force on the ground
    body_acc = np.where(flying[:, None], acc * np.array([0.0, 0.0, 1.0]), acc)
    dp = S[:, 3:6] * dt + body_acc * (dt * dt / 2.0)
    pos = S[:, 0:3] + np.einsum("nij,nj->ni", R, dp)
    pos[:, 2] -= GRAVITY * dt * dt / 2.0
    vel = S[:, 3:6]
    coriolis = np.stack([wz * py - wy * pz, -wz * px + wx * pz, wy * px - wx * py], axis=1)
    vel = vel + dt * (body_acc + coriolis - GRAVITY * R[:, 2, :])
    S[:, 0:3], S[:, 3:6] = pos, vel
    k.S[rows] = S

    q = _rotate_by(k.q[rows], gyro * dt)
    keep = np.where(flying, 1.0, 1.0 - ATTITUDE_REVERSION)[:, None]
    q = keep * q + (1.0 - keep) * k.q_initial[rows]
    k.q[rows] = _normalised(q)


def add_process_noise(k: KalmanStates, rows: np.ndarray, now_ms: float) -> None:
    """The process noise of every filter loop (1 ms) since the last call, on the diagonal."""
    loops = np.maximum(np.round(now_ms - k.noise_ms[rows]), 0.0) * (1e-3 / LOOP_S)
    if not np.any(loops > 0):
        return
    dt = LOOP_S
    nz = k.noise[rows]
    acc_xy, acc_z, vel, pos, att, gyro_rp, gyro_yaw = (nz[:, c] for c in range(7))
    inc = np.stack([(acc_xy * dt * dt + vel * dt + pos) ** 2, (acc_xy * dt * dt + vel * dt + pos) ** 2,
                    (acc_z * dt * dt + vel * dt + pos) ** 2,
                    (acc_xy * dt + vel) ** 2, (acc_xy * dt + vel) ** 2, (acc_z * dt + vel) ** 2,
                    (gyro_rp * dt + att) ** 2, (gyro_rp * dt + att) ** 2, (gyro_yaw * dt + att) ** 2], axis=1)
    P = k.P[rows]
    idx = np.arange(STATE_DIM)
    # loop by loop the firmware raises the diagonal to the floor after the first increment only
    # (the increments are >= 0), so n loops at once are exactly: floor(d + inc) + (n - 1)·inc
    n = loops[:, None]
    diag = np.maximum(P[:, idx, idx] + inc, MIN_COVARIANCE) + (n - 1.0) * inc
    P[:, idx, idx] = np.where(n > 0, diag, P[:, idx, idx])
    k.P[rows] = bound(P)
    k.noise_ms[rows] = np.maximum(k.noise_ms[rows], now_ms)


def scalar_update(k: KalmanStates, rows: np.ndarray, state: int, error: np.ndarray, std: np.ndarray) -> None:
    """kalmanCoreScalarUpdate with H = e_state for each row: ``error`` (n,) is measurement - H·S."""
    P = k.P[rows]
    var = std * std
    ph = P[:, :, state]                                            # P H'
    K = ph / (ph[:, state] + var)[:, None]
    k.S[rows] += K * error[:, None]
    # (I - K H) P (I - K H)' + K R K', with H picking one state
    MP = P - K[:, :, None] * P[:, state, None, :]
    P = MP - MP[:, :, state, None] * K[:, None, :] + var[:, None, None] * K[:, :, None] * K[:, None, :]
    k.P[rows] = bound(P)


def update_position(k: KalmanStates, rows: np.ndarray, position: np.ndarray, std: np.ndarray) -> None:
    """mm_position: x, y, z measured directly, one scalar update each."""
    for axis in range(3):
        scalar_update(k, rows, X + axis, position[:, axis] - k.S[rows, X + axis], std)


def update_attitude(k: KalmanStates, rows: np.ndarray, quat_xyzw: np.ndarray, std: np.ndarray) -> None:
    """mm_pose's orientation part: the body-frame residual q_estimate⁻¹ ⊗ q_measured (Hamilton
    products; the firmware's ``qqmul(q_measured, qinv(q_estimate))`` multiplies in this order) as a
    small angle (2·v/w), one scalar update per attitude-error component."""
    q = k.q[rows]
    ew, ev = q[:, 0], -q[:, 1:4]                                 # the estimate's inverse (unit quaternion)
    mv, mw = quat_xyzw[:, 0:3], quat_xyzw[:, 3]
    res_w = mw * ew - np.einsum("ij,ij->i", mv, ev)
    res_v = mw[:, None] * ev + ew[:, None] * mv + np.cross(ev, mv)
    err = 2.0 / res_w[:, None] * res_v
    for axis in range(3):
        scalar_update(k, rows, D0 + axis, err[:, axis], std)


def finalize(k: KalmanStates, rows: np.ndarray) -> None:
    """Fold the attitude error into the quaternion (rotating its covariance), zero it, refresh R and
    bound the covariance."""
    v = k.S[rows, D0:D0 + 3]
    a = np.abs(v)
    fold = np.any(a > FOLD_MIN, axis=1) & np.all(a < FOLD_MAX, axis=1)
    if np.any(fold):
        sub = rows[fold]
        vf = v[fold]
        k.q[sub] = _normalised(_rotate_by(k.q[sub], vf))
        A = np.broadcast_to(np.eye(STATE_DIM), (len(sub), STATE_DIM, STATE_DIM)).copy()
        A[:, 6:9, 6:9] = _rotation_block(vf / 2.0)
        k.P[sub] = A @ k.P[sub] @ A.transpose(0, 2, 1)
    k.R[rows] = rotation(k.q[rows])
    k.S[rows, D0:D0 + 3] = 0.0
    k.P[rows] = bound(k.P[rows])


def world_velocity(k: KalmanStates, rows: Optional[np.ndarray] = None) -> np.ndarray:
    """(n,3) the velocity estimate in the world frame (R · body velocity)."""
    R = k.R if rows is None else k.R[rows]
    S = k.S if rows is None else k.S[rows]
    return np.einsum("nij,nj->ni", R, S[:, 3:6])


def quaternion_xyzw(k: KalmanStates, i: int) -> np.ndarray:
    """Row ``i``'s attitude estimate as (x, y, z, w)."""
    w, x, y, z = k.q[i].tolist()
    return np.array([x, y, z, w])
