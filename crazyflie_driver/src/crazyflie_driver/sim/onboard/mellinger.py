"""The firmware's Mellinger controller (``stabilizer.controller`` 2), all vehicles at once.

Mellinger & Kumar, "Minimum snap trajectory generation and control for quadrotors", ICRA 2011, as the
current firmware implements it, in two stages that both run at 500 Hz:

* ``desired_axes`` (the position part, before the stabilizer's step): the desired force
  F = m·(a_ff + g·ẑ) + kp·e_p + kd·e_v + ki·∫e_p and the desired body axes (z along F, x towards the
  desired yaw), thrust command = ``massThrust`` × (F · current body z). Only when the setpoint's x
  mode is absolute (position, full state, high-level commander). With roll and pitch absolute and z
  disabled (manual setpoints) the desired axes are the setpoint's roll, pitch and yaw and the thrust
  is the setpoint's. Any other combination (velocity-world, hover, zDistance) holds level at the
  current yaw with a z-only force on the setpoint's z (a velocity-world setpoint carries z = 0, so the
  force points down and the motors stop). Whenever z is disabled the thrust is the setpoint's.
* ``moments`` (the attitude law, in the stabilizer's step, with the measured gyro): the attitude
  error e_R = vee(R_desᵀR − RᵀR_des) (no ½: the gains absorb it; pitch in the firmware's legacy
  sign), the rate error e_ω = ω_des − ω with the setpoint's body rates as feed-forward, a derivative
  of the roll/pitch rate error and an integral of e_R:
  M = −kR·e_R + kw·e_ω + ki_m·∫(−e_R) + kd_omega_rp·ė_ω (roll, pitch), in motor counts, each clamped to
  ±32000; the mixer takes (M_x, M_y, −M_z).

Facts and gains in docs/simulation.md ("Mellinger").
"""
from __future__ import annotations

from typing import Dict, Tuple

import numpy as np

GRAVITY = 9.81
DT = 1.0 / 500.0                    # s, the controller's rate
MELLINGER_EVERY = 2                 # ticks
MOMENT_LIMIT = 32000.0              # counts
# current firmware defaults: the position part
DEFAULTS: Dict[str, float] = {
    "ctrlMel.kp_xy": 0.4, "ctrlMel.kd_xy": 0.2, "ctrlMel.ki_xy": 0.05, "ctrlMel.i_range_xy": 2.0,
    "ctrlMel.kp_z": 1.25, "ctrlMel.kd_z": 0.4, "ctrlMel.ki_z": 0.05, "ctrlMel.i_range_z": 0.4,
    "ctrlMel.mass": 0.029, "ctrlMel.massThrust": 132000.0,
}
GAIN_ORDER = tuple(DEFAULTS)        # column order of the per-vehicle gain array
# ... and the attitude law
ATTITUDE_DEFAULTS: Dict[str, float] = {
    "ctrlMel.kR_xy": 70000.0, "ctrlMel.kw_xy": 20000.0, "ctrlMel.ki_m_xy": 0.0, "ctrlMel.i_range_m_xy": 1.0,
    "ctrlMel.kR_z": 60000.0, "ctrlMel.kw_z": 12000.0, "ctrlMel.ki_m_z": 500.0, "ctrlMel.i_range_m_z": 1500.0,
    "ctrlMel.kd_omega_rp": 200.0,
}
ATTITUDE_GAIN_ORDER = tuple(ATTITUDE_DEFAULTS)


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.sqrt(np.einsum("ij,ij->i", v, v))
    return v / norm[:, None]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a × b of (n,3) arrays (np.cross costs several times more on small arrays)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _axes_towards(z_des: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
    """(n,3,3) columns x, y, z of the body frame with z along ``z_des`` and x in the plane of the yaw."""
    x_c = np.zeros_like(z_des)
    x_c[:, 0], x_c[:, 1] = np.cos(yaw_rad), np.sin(yaw_rad)
    y_des = _unit(_cross(z_des, x_c))
    axes = np.empty((len(z_des), 3, 3))
    axes[:, :, 0], axes[:, :, 1], axes[:, :, 2] = _cross(y_des, z_des), y_des, z_des
    return axes


def _rpy_axes(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(n,3,3) rotation matrices of standard roll, pitch, yaw (rad), z-y-x."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    r = np.empty((len(roll), 3, 3))
    r[:, 0, 0], r[:, 0, 1], r[:, 0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    r[:, 1, 0], r[:, 1, 1], r[:, 1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    r[:, 2, 0], r[:, 2, 1], r[:, 2, 2] = -sp, cp * sr, cp * cr
    return r


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """(n,3,3) body-to-world rotations of unit quaternions (n,4: x, y, z, w)."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0], r[:, 0, 1], r[:, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r[:, 1, 0], r[:, 1, 1], r[:, 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r[:, 2, 0], r[:, 2, 1], r[:, 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return r


def desired_axes(gains: np.ndarray, integ: np.ndarray, pos: np.ndarray, vel: np.ndarray, sp_pos: np.ndarray,
                 sp_vel: np.ndarray, sp_acc: np.ndarray, sp_att_deg: np.ndarray, sp_thrust: np.ndarray,
                 x_abs: np.ndarray, manual: np.ndarray, z_off: np.ndarray, yaw_des_rad: np.ndarray,
                 yaw_now_rad: np.ndarray, body_z: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The position part for n rows: (desired axes (n,3,3), thrust command (counts), new integrals).

    ``gains`` (n,10) in ``GAIN_ORDER``; ``integ`` (n,3) the position-error integrals; ``x_abs``,
    ``manual`` (roll and pitch absolute, z disabled), ``z_off`` (n,) bool; ``sp_att_deg`` roll and
    pitch in the legacy sign; ``body_z`` (n,3) the current body z axis in the world frame.
    """
    kp_xy, kd_xy, ki_xy, ir_xy, kp_z, kd_z, ki_z, ir_z, mass, mass_thrust = gains.T
    e_p = sp_pos - pos
    e_v = sp_vel - vel
    integ = integ + e_p * DT
    integ[:, :2] = np.minimum(np.maximum(integ[:, :2], -ir_xy[:, None]), ir_xy[:, None])
    integ[:, 2] = np.minimum(np.maximum(integ[:, 2], -ir_z), ir_z)
    z_force = kp_z * e_p[:, 2] + kd_z * e_v[:, 2] + ki_z * integ[:, 2]
    force = np.zeros_like(e_p)
    xy = mass[:, None] * sp_acc[:, :2] + kp_xy[:, None] * e_p[:, :2] + kd_xy[:, None] * e_v[:, :2] \
        + ki_xy[:, None] * integ[:, :2]
    force[:, :2] = np.where(x_abs[:, None], xy, 0.0)
    force[:, 2] = mass * (np.where(x_abs, sp_acc[:, 2], 0.0) + GRAVITY) + z_force
    with np.errstate(invalid="ignore", divide="ignore"):
        axes = _axes_towards(_unit(force), np.where(x_abs, yaw_des_rad, yaw_now_rad))
    if manual.any():
        command = _rpy_axes(np.radians(sp_att_deg[:, 0]), -np.radians(sp_att_deg[:, 1]), yaw_des_rad)
        axes = np.where((manual & ~x_abs)[:, None, None], command, axes)
    thrust = mass_thrust * np.einsum("ij,ij->i", force, body_z)
    thrust = np.where(z_off, sp_thrust, np.minimum(np.maximum(thrust, 0.0), 65535.0))
    return axes, thrust, integ


def moments(gains: np.ndarray, integ_m: np.ndarray, prev: np.ndarray, quaternion: np.ndarray, axes: np.ndarray,
            rate_sp_deg: np.ndarray, gyro_deg: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The attitude law for n rows: (roll, pitch, yaw commands (n,3) as the mixer takes them, new moment
    integrals, new derivative memory).

    ``gains`` (n,9) in ``ATTITUDE_GAIN_ORDER``; ``prev`` (n,4): the last roll and pitch rates and
    their setpoints (rad/s, legacy pitch); ``axes`` (n,3,3) the desired body axes (columns);
    ``rate_sp_deg`` (n,3) the setpoint's body rates (deg/s); ``gyro_deg`` (n,3) the measured body
    rates (deg/s, standard signs)."""
    kr_xy, kw_xy, ki_xy, ir_xy, kr_z, kw_z, ki_z, ir_z, kd_rp = gains.T
    r = rotation_matrices(quaternion)
    err = np.einsum("nji,njk->nik", axes, r) - np.einsum("nji,njk->nik", r, axes)     # R_desᵀR − RᵀR_des
    e_r = np.stack([err[:, 2, 1], err[:, 0, 2], err[:, 1, 0]], axis=1)
    e_r[:, 1] = -e_r[:, 1]                                      # the firmware's legacy pitch sign
    omega = np.radians(gyro_deg) * _LEGACY
    omega_sp = np.radians(rate_sp_deg)
    e_w = omega_sp * _LEGACY - omega
    d_roll = ((omega_sp[:, 0] - prev[:, 2]) - (omega[:, 0] - prev[:, 0])) / DT
    d_pitch = (-(omega_sp[:, 1] - prev[:, 3]) - (omega[:, 1] - prev[:, 1])) / DT
    prev = np.stack([omega[:, 0], omega[:, 1], omega_sp[:, 0], omega_sp[:, 1]], axis=1)
    integ_m = integ_m - e_r * DT
    integ_m[:, :2] = np.minimum(np.maximum(integ_m[:, :2], -ir_xy[:, None]), ir_xy[:, None])
    integ_m[:, 2] = np.minimum(np.maximum(integ_m[:, 2], -ir_z), ir_z)
    m = np.empty_like(e_r)
    m[:, 0] = -kr_xy * e_r[:, 0] + kw_xy * e_w[:, 0] + ki_xy * integ_m[:, 0] + kd_rp * d_roll
    m[:, 1] = -kr_xy * e_r[:, 1] + kw_xy * e_w[:, 1] + ki_xy * integ_m[:, 1] + kd_rp * d_pitch
    m[:, 2] = -(-kr_z * e_r[:, 2] + kw_z * e_w[:, 2] + ki_z * integ_m[:, 2])
    return np.minimum(np.maximum(m, -MOMENT_LIMIT), MOMENT_LIMIT), integ_m, prev


_LEGACY = np.array([1.0, -1.0, 1.0])        # the firmware's pitch rate is the negated gyro y
