"""The position part of the firmware's Mellinger controller (``stabilizer.controller`` 2), all vehicles at once.

The desired force is F = m·(a_ff + g·ẑ) + kp·e_p + kd·e_v + ki·∫e_p, but only when the setpoint's x
mode is absolute (position, full state, high-level commander). Any other setpoint gets the
firmware's quirk: the x/y force comes from the setpoint's roll and pitch fields (zero for hover and
velocity-world setpoints, which therefore have no horizontal control at all) and z holds the
setpoint's z (0 for velocity-world setpoints, whose decoder leaves it unset), or 1 N when z is not
absolute. The thrust command is ``massThrust`` × (F · current body z). The attitude that points
the body z along F at the desired yaw is handed to the stabilizer's attitude controller: the
firmware's own moment law (kR, kw) is not simulated. Facts in docs/simulation.md ("Mellinger").
"""
from __future__ import annotations

import math
from typing import Dict, List, Sequence, Tuple

import numpy as np

from crazyflie_driver.sim.world.scalar import clamp, safe_cos, safe_sin

GRAVITY = 9.81
DT = 1.0 / 500.0                    # s, the controller's rate
MELLINGER_EVERY = 2                 # ticks
# current firmware defaults
DEFAULTS: Dict[str, float] = {
    "ctrlMel.kp_xy": 0.4, "ctrlMel.kd_xy": 0.2, "ctrlMel.ki_xy": 0.05, "ctrlMel.i_range_xy": 2.0,
    "ctrlMel.kp_z": 1.25, "ctrlMel.kd_z": 0.4, "ctrlMel.ki_z": 0.05, "ctrlMel.i_range_z": 0.4,
    "ctrlMel.mass": 0.029, "ctrlMel.massThrust": 132000.0,
}
GAIN_ORDER = tuple(DEFAULTS)        # column order of the per-vehicle gain array


def force_and_attitude(gains: np.ndarray, integ: np.ndarray, pos: np.ndarray, vel: np.ndarray,
                       sp_pos: np.ndarray, sp_vel: np.ndarray, sp_acc: np.ndarray, sp_att_deg: np.ndarray,
                       x_abs: np.ndarray, z_abs: np.ndarray, yaw_des_rad: np.ndarray,
                       body_z: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One 500 Hz step for the given rows: (roll deg, legacy pitch deg, thrust counts, new integrals).

    ``gains`` (n, 10) in ``GAIN_ORDER``; ``integ`` (n, 3) the position-error integrals; ``body_z``
    (n, 3) the current body z axis in the world frame.
    """
    kp_xy, kd_xy, ki_xy, ir_xy, kp_z, kd_z, ki_z, ir_z, mass, mass_thrust = gains.T
    e_p = sp_pos - pos
    e_v = sp_vel - vel
    integ = integ + e_p * DT
    integ[:, :2] = np.minimum(np.maximum(integ[:, :2], -ir_xy[:, None]), ir_xy[:, None])
    integ[:, 2] = np.minimum(np.maximum(integ[:, 2], -ir_z), ir_z)
    full = np.empty_like(e_p)
    full[:, 0] = mass * sp_acc[:, 0] + kp_xy * e_p[:, 0] + kd_xy * e_v[:, 0] + ki_xy * integ[:, 0]
    full[:, 1] = mass * sp_acc[:, 1] + kp_xy * e_p[:, 1] + kd_xy * e_v[:, 1] + ki_xy * integ[:, 1]
    full[:, 2] = mass * (sp_acc[:, 2] + GRAVITY) + kp_z * e_p[:, 2] + kd_z * e_v[:, 2] + ki_z * integ[:, 2]
    quirk = np.empty_like(e_p)
    quirk[:, 0] = -np.sin(np.radians(sp_att_deg[:, 1]))
    quirk[:, 1] = -np.sin(np.radians(sp_att_deg[:, 0]))
    quirk[:, 2] = np.where(z_abs, mass * GRAVITY + kp_z * e_p[:, 2] + kd_z * e_v[:, 2] + ki_z * integ[:, 2], 1.0)
    force = np.where(x_abs[:, None], full, quirk)
    thrust = np.minimum(np.maximum(mass_thrust * np.einsum("ij,ij->i", force, body_z), 0.0), 65535.0)
    norm = np.linalg.norm(force, axis=1)
    z_des = force / np.where(norm > 0, norm, 1.0)[:, None]
    c, s = np.cos(yaw_des_rad), np.sin(yaw_des_rad)
    bx = c * z_des[:, 0] + s * z_des[:, 1]          # desired body z in the yaw-aligned frame
    by = -s * z_des[:, 0] + c * z_des[:, 1]
    roll = -np.degrees(np.arcsin(np.minimum(np.maximum(by, -1.0), 1.0)))
    pitch_legacy = -np.degrees(np.arctan2(bx, z_des[:, 2]))
    return roll, pitch_legacy, thrust, integ


def force_and_attitude_row(gains: Sequence[float], integ: Sequence[float], pos: Sequence[float],
                           vel: Sequence[float], sp_pos: Sequence[float], sp_vel: Sequence[float],
                           sp_acc: Sequence[float], sp_att_deg: Sequence[float], x_abs: bool, z_abs: bool,
                           yaw_des_rad: float, body_z: Sequence[float]) -> Tuple[float, float, float, List[float]]:
    """``force_and_attitude`` for one vehicle in Python floats: the same operations in the same order
    (a few numpy calls on 3-vectors cost more than the whole step in floats)."""
    kp_xy, kd_xy, ki_xy, ir_xy, kp_z, kd_z, ki_z, ir_z, mass, mass_thrust = gains
    e0, e1, e2 = sp_pos[0] - pos[0], sp_pos[1] - pos[1], sp_pos[2] - pos[2]
    v0, v1, v2 = sp_vel[0] - vel[0], sp_vel[1] - vel[1], sp_vel[2] - vel[2]
    i0 = clamp(integ[0] + e0 * DT, -ir_xy, ir_xy)
    i1 = clamp(integ[1] + e1 * DT, -ir_xy, ir_xy)
    i2 = clamp(integ[2] + e2 * DT, -ir_z, ir_z)
    if x_abs:
        f0 = mass * sp_acc[0] + kp_xy * e0 + kd_xy * v0 + ki_xy * i0
        f1 = mass * sp_acc[1] + kp_xy * e1 + kd_xy * v1 + ki_xy * i1
        f2 = mass * (sp_acc[2] + GRAVITY) + kp_z * e2 + kd_z * v2 + ki_z * i2
    else:
        f0 = -safe_sin(math.radians(sp_att_deg[1]))
        f1 = -safe_sin(math.radians(sp_att_deg[0]))
        f2 = mass * GRAVITY + kp_z * e2 + kd_z * v2 + ki_z * i2 if z_abs else 1.0
    thrust = clamp(mass_thrust * (f0 * body_z[0] + f1 * body_z[1] + f2 * body_z[2]), 0.0, 65535.0)
    norm = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    scale = norm if norm > 0 else 1.0
    z0, z1, z2 = f0 / scale, f1 / scale, f2 / scale
    c, s = safe_cos(yaw_des_rad), safe_sin(yaw_des_rad)
    bx = c * z0 + s * z1
    by = -s * z0 + c * z1
    roll = -math.degrees(math.asin(clamp(by, -1.0, 1.0)))
    pitch_legacy = -math.degrees(math.atan2(bx, z2))
    return roll, pitch_legacy, thrust, [i0, i1, i2]
