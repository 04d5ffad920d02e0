"""Rigid-body physics of Crazyflies, all vehicles at once (numpy), behind one ``step`` call.

Numbers are the Förster identification of the Crazyflie 2.0 (docs/simulation.md, "Vehicle physics"): thrust per motor
F(u) = c2·u² + c1·u + c0 for a 16-bit command u (0 for u = 0), a first-order motor lag, yaw
reaction torque κ·F, body drag −K·Σω·v_body and the X layout of that section (M1 front-right, M2
back-right, M3 back-left, M4 front-left; M1/M3 react −κF about +z, M2/M4 +κF).

Frames: world x forward, y left, z up; body the same on the vehicle. Quaternions are (x, y, z, w)
and rotate body vectors into the world; angular velocity is in the body frame (rad/s).
Another integrator or vehicle model can replace ``RigidBodyBackend``: the world only calls
``step(states, actions, dt)`` and reads ``position``, ``velocity``, ``quaternion``, ``omega``, ``thrust``,
``specific_force`` and ``on_ground`` from the states.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from crazyflie_driver.sim.vehicle_rows import Rows, Vector, bilinear_form, quadratic_form

GRAVITY = 9.81
MAX_COMMAND = 65535
SCALAR_ROWS = 3              # up to this many vehicles a substep runs in Python floats, row by row
PHYSICS_TICK_S = 0.001


@dataclass
class VehicleParams:
    """One vehicle's physical constants (defaults: bare Crazyflie 2.0, Förster)."""

    mass: float = 0.027                                   # kg; ~0.030-0.034 with markers/decks
    arm: float = 0.046                                    # m, centre to motor (X layout)
    inertia: Tuple[float, float, float] = (16.571710e-6, 16.655602e-6, 29.261652e-6)   # kg m²
    thrust_coeffs: Tuple[float, float, float] = (2.130295e-11, 1.032633e-6, 5.484560e-4)  # c2, c1, c0
    rotor_speed_coeffs: Tuple[float, float] = (0.04076521, 380.8359)    # ω = a·u + b [rad/s]
    yaw_torque_coeff: float = 0.005964552                # m (κ)
    motor_tau: float = 0.06                               # s, first-order lag of each motor's thrust
    body_drag: Tuple[float, float, float] = (9.1785e-7, 9.1785e-7, 10.311e-7)   # kg/rad
    gravity: float = GRAVITY

    def __post_init__(self) -> None:
        if not (self.mass > 0 and math.isfinite(self.mass)):
            raise ValueError("vehicle mass must be a positive number of kg, got %r" % (self.mass,))
        if not self.motor_tau > 0:
            raise ValueError("motor_tau must be > 0 s, got %r" % (self.motor_tau,))
        if len(self.inertia) != 3 or min(self.inertia) <= 0:
            raise ValueError("inertia must be three positive numbers (kg m²), got %r" % (self.inertia,))

    def thrust(self, command: float) -> float:
        """Steady thrust of one motor [N] for a 16-bit command."""
        u = min(max(float(command), 0.0), MAX_COMMAND)
        if u <= 0.0:
            return 0.0
        c2, c1, c0 = self.thrust_coeffs
        return c2 * u * u + c1 * u + c0

    def command_for_thrust(self, thrust: float) -> float:
        """Inverse of ``thrust``: the command giving ``thrust`` newtons per motor."""
        c2, c1, c0 = self.thrust_coeffs
        disc = c1 * c1 - 4.0 * c2 * (c0 - thrust)
        return (-c1 + math.sqrt(max(disc, 0.0))) / (2.0 * c2)

    def hover_command(self) -> float:
        """Command on all four motors that holds the vehicle's weight."""
        return self.command_for_thrust(self.mass * self.gravity / 4.0)


class BodyStates(Rows):
    """State of every vehicle body plus its physical constants (one row per vehicle)."""

    FIELDS = {
        "position": ((3,), float),
        "velocity": ((3,), float),           # world frame, m/s
        "quaternion": ((4,), float),         # x, y, z, w (body -> world)
        "omega": ((3,), float),              # body frame, rad/s
        "thrust": ((4,), float),             # lagged thrust of each motor, N
        "specific_force": ((3,), float),     # body frame, m/s² (what an ideal accelerometer reads)
        "acceleration": ((3,), float),       # world frame, m/s²
        "on_ground": ((), bool),
        # constants
        "mass": ((), float),
        "inertia": ((3,), float),
        "torque_scale": ((3,), float),       # arm projected on x or y (twice), then κ
        "thrust_coeffs": ((3,), float),
        "rotor_speed_coeffs": ((2,), float),
        "yaw_torque_coeff": ((), float),
        "motor_tau": ((), float),
        "body_drag": ((3,), float),
        "gravity": ((), float),
        # derived constants the integrator multiplies by
        "inv_mass": ((1,), float),
        "inv_inertia": ((3,), float),
        "gravity_vector": ((3,), float),     # (0, 0, g)
    }

    # The columns (one row per vehicle; shapes and dtypes in FIELDS), declared for the type checker.
    position: np.ndarray
    velocity: np.ndarray
    quaternion: np.ndarray
    omega: np.ndarray
    thrust: np.ndarray
    specific_force: np.ndarray
    acceleration: np.ndarray
    on_ground: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    torque_scale: np.ndarray
    thrust_coeffs: np.ndarray
    rotor_speed_coeffs: np.ndarray
    yaw_torque_coeff: np.ndarray
    motor_tau: np.ndarray
    body_drag: np.ndarray
    gravity: np.ndarray
    inv_mass: np.ndarray
    inv_inertia: np.ndarray
    gravity_vector: np.ndarray

    def add(self, params: VehicleParams, position: Vector = (0.0, 0.0, 0.0), yaw: float = 0.0) -> int:
        pos = np.asarray(position, dtype=float).reshape(3)
        g = params.gravity
        return self.append_row(
            position=pos, quaternion=(0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)),
            specific_force=(0.0, 0.0, g) if pos[2] <= 0.0 else (0.0, 0.0, 0.0),
            on_ground=bool(pos[2] <= 0.0), mass=params.mass, inertia=params.inertia,
            torque_scale=(params.arm / math.sqrt(2.0), params.arm / math.sqrt(2.0), params.yaw_torque_coeff),
            thrust_coeffs=params.thrust_coeffs,
            rotor_speed_coeffs=params.rotor_speed_coeffs, yaw_torque_coeff=params.yaw_torque_coeff,
            motor_tau=params.motor_tau, body_drag=params.body_drag, gravity=g,
            inv_mass=1.0 / params.mass, inv_inertia=1.0 / np.asarray(params.inertia, dtype=float),
            gravity_vector=(0.0, 0.0, g))


# ------------------------------------------------------------------------------------------------
# quaternion helpers (x, y, z, w), vectorised over the first axis

def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(N,4) unit quaternions -> (N,3,3) rotation matrices body -> world."""
    v = q[:, :3]
    w = q[:, 3]
    r = 2.0 * v[:, :, None] * v[:, None, :]                     # 2 v vᵀ
    d = w * w - (v * v).sum(axis=1)
    r[:, 0, 0] += d
    r[:, 1, 1] += d
    r[:, 2, 2] += d
    wv = 2.0 * w[:, None] * v                                     # 2 w [v]×
    r[:, 0, 1] -= wv[:, 2]
    r[:, 1, 0] += wv[:, 2]
    r[:, 0, 2] += wv[:, 1]
    r[:, 2, 0] -= wv[:, 1]
    r[:, 1, 2] -= wv[:, 0]
    r[:, 2, 1] += wv[:, 0]
    return r


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b of (N,4) xyzw quaternions."""
    ax, ay, az, aw = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    bx, by, bz, bw = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=1)


def quat_from_rotvec(v: np.ndarray) -> np.ndarray:
    """(N,3) rotation vectors -> (N,4) quaternions."""
    angle = np.sqrt((v * v).sum(axis=1))
    half = 0.5 * angle
    # sin(half)/angle, with its limit 1/2 at zero
    k = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    return np.concatenate([v * k[:, None], np.cos(half)[:, None]], axis=1)


def euler_from_quat(q: np.ndarray) -> np.ndarray:
    """(N,4) -> (N,3) roll, pitch, yaw [rad], standard Z-Y-X (pitch positive nose down)."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=1)


def quat_from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """One quaternion (4,) from standard Z-Y-X angles [rad]."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy])


# ------------------------------------------------------------------------------------------------

def motor_thrust(states: BodyStates, commands: np.ndarray) -> np.ndarray:
    """Steady thrust (N,4) [N] of each motor for 16-bit commands (N,4); 0 for a stopped motor."""
    u = np.minimum(np.maximum(commands, 0.0), MAX_COMMAND)
    c = states.thrust_coeffs
    f = (c[:, 0:1] * u + c[:, 1:2]) * u + c[:, 2:3]
    return np.where(u > 0.0, f, 0.0)


@dataclass
class Drive:
    """What a set of motor commands does while it is held: computed once per change of the commands."""

    commands: np.ndarray          # (N,4) the commands this drive was made from
    target: np.ndarray            # (N,4) steady thrust of each motor [N]
    blend: np.ndarray             # (N,1) motor lag over one substep: 1 - exp(-h / tau)
    drag: np.ndarray              # (N,3) body drag per unit body velocity: -K · Σ rotor speed [kg/s]
    motors_off: bool = False      # no motor of any vehicle turns


class RigidBodyBackend:
    """Newton-Euler integration in fixed substeps (1 ms unless told) with motor lag, rotor drag and a floor at z = 0.

    Floor: a vehicle touching the floor whose vertical thrust does not exceed its weight rests:
    position on the floor, no velocity (friction), no rotation, attitude levelled to its yaw
    (it stands on its legs). It takes off once the thrust's vertical component exceeds the weight.

    Cost: a substep is a fixed number of numpy calls whatever the number of vehicles (quaternion
    products, rotations and cross products are single matrix products over all vehicles).
    """

    def __init__(self, tick: float = PHYSICS_TICK_S) -> None:
        if not tick > 0:
            raise ValueError("physics tick must be > 0 s")
        self.tick = float(tick)
        self._blend_key: Optional[tuple] = None
        self._blend_value = np.zeros((0, 1))
        self._columns_key: Optional[tuple] = None
        self._columns_value: Tuple[np.ndarray, ...] = ()

    def drive(self, states: BodyStates, actions: np.ndarray, dt: float) -> Drive:
        """The per-substep constants of holding motor commands ``actions`` (N,4, 0..65535) for ``dt`` s."""
        actions = np.asarray(actions, dtype=float)
        if actions.shape != (states.position.shape[0], 4):
            raise ValueError("actions must have shape (%d, 4), got %s" % (len(states), actions.shape))
        h = dt / max(1, int(round(dt / self.tick)))
        u = np.minimum(np.maximum(actions, 0.0), MAX_COMMAND)
        spinning = u > 0.0
        c2, c1, c0, a1, a0 = self._columns(states)
        target = (c2 * u + c1) * u + c0
        target *= spinning
        rotor_speed = a1 * u + a0
        rotor_speed *= spinning
        return Drive(actions, target, self._blend(states, h), rotor_speed @ _MINUS_ONES4 * states.body_drag,
                     not np.count_nonzero(spinning))

    def _columns(self, states: BodyStates) -> Tuple[np.ndarray, ...]:
        """(N,1) columns of the thrust and rotor-speed coefficients; kept while those arrays stay the same."""
        c, a = states.thrust_coeffs, states.rotor_speed_coeffs
        key = self._columns_key
        if key is None or key[0] is not c or key[1] is not a:
            self._columns_key = (c, a)
            self._columns_value = (c[:, 0:1], c[:, 1:2], c[:, 2:3], a[:, 0:1], a[:, 1:2])
        return self._columns_value

    def _blend(self, states: BodyStates, h: float) -> np.ndarray:
        """(N,1) motor lag over a substep of h seconds; kept while the vehicles' time constants stay the same."""
        key = (h, states.motor_tau)
        if self._blend_key is None or self._blend_key[0] != h or self._blend_key[1] is not states.motor_tau:
            self._blend_key = key
            self._blend_value = (1.0 - np.exp(-h / states.motor_tau))[:, None]
        return self._blend_value

    def step(self, states: BodyStates, actions: np.ndarray, dt: float, drive: Optional[Drive] = None) -> None:
        """Advance every vehicle by ``dt`` seconds with motor commands ``actions`` (N,4, 0..65535).

        ``drive``: the result of ``drive(states, actions, dt)`` when the caller keeps it across steps.
        """
        if len(states) == 0:
            return
        if drive is None:
            drive = self.drive(states, actions, dt)
        n = max(1, int(round(dt / self.tick)))
        h = dt / n
        rows = states.position.shape[0]
        for _ in range(n):
            if rows > SCALAR_ROWS or not self._substep_rows(states, drive, h):
                self._substep(states, drive, h)

    def _substep_rows(self, s: BodyStates, d: Drive, h: float) -> bool:
        """``_substep`` for a few vehicles in Python floats, row by row (numpy's per-call cost dominates
        there). Only for vehicles in the air: False, with nothing changed, when a vehicle rests on or
        reaches the floor (``_substep`` then does the step, floor contact included)."""
        new = []
        for i in range(s.position.shape[0]):
            row = _substep_row(h, s.thrust[i].tolist(), d.target[i].tolist(), float(d.blend[i, 0]),
                               d.drag[i].tolist(), s.position[i].tolist(), s.velocity[i].tolist(),
                               s.quaternion[i].tolist(), s.omega[i].tolist(), s.inertia[i].tolist(),
                               s.torque_scale[i].tolist(), float(s.inv_mass[i, 0]), s.inv_inertia[i].tolist(),
                               float(s.gravity[i]))
            if row is None or s.on_ground[i]:
                return False
            new.append(row)
        for i, (thrust, position, velocity, omega, quaternion, acceleration, specific_force) in enumerate(new):
            s.thrust[i], s.position[i], s.velocity[i], s.omega[i] = thrust, position, velocity, omega
            s.quaternion[i], s.acceleration[i], s.specific_force[i] = quaternion, acceleration, specific_force
        return True

    def _substep(self, s: BodyStates, d: Drive, h: float) -> None:
        f = s.thrust
        lag = d.target - f
        lag *= d.blend
        f += lag
        if d.motors_off and np.count_nonzero(s.on_ground) == len(s.on_ground) and s.position[:, 2].max() <= 0.0 \
                and not np.count_nonzero(s.velocity) and not np.count_nonzero(s.omega):
            return      # every vehicle rests on the floor, still, with its motors off: nothing moves
        ft = f @ _FORCE_PATTERN                          # (N,4): torque about x, y, z (unscaled), total thrust
        total = ft[:, 3]
        r = (s.quaternion[:, :, None] * s.quaternion[:, None, :]).reshape(-1, 16) @ _QUAT_TO_MATRIX
        r = r.reshape(-1, 3, 3)
        v_old = s.velocity
        # body-frame force: rotor drag on the body velocity plus the thrust along body z
        force_body = (v_old[:, None, :] @ r)[:, 0, :]    # R^T v
        force_body *= d.drag
        force_body[:, 2] += total
        acc = (r @ force_body[:, :, None])[:, :, 0]
        acc *= s.inv_mass
        acc[:, 2] -= s.gravity
        w = s.omega
        gyroscopic = (w[:, :, None] * (s.inertia * w)[:, None, :]).reshape(-1, 9) @ _CROSS     # w × (I w)
        torque = ft[:, :3] * s.torque_scale
        torque -= gyroscopic
        torque *= s.inv_inertia
        torque *= h
        w_new = w + torque

        v_new = v_old + acc * h
        p_new = v_old + v_new
        p_new *= 0.5 * h
        p_new += s.position
        q_new = _quat_multiply_flat(s.quaternion, _small_rotation(w_new * h))
        q_new /= np.sqrt((q_new * q_new) @ _ONES41)

        # floor contact
        resting = np.zeros(len(p_new), dtype=bool)
        if p_new[:, 2].min() <= 0.0:
            touching = p_new[:, 2] <= 0.0
            lifting = r[:, 2, 2] * total > s.mass * s.gravity
            resting = touching & ~lifting
            np.maximum(p_new[:, 2], 0.0, out=p_new[:, 2])                 # on the floor, not under it
            v_new[:, 2] = np.where(touching, np.maximum(v_new[:, 2], 0.0), v_new[:, 2])
            if np.count_nonzero(resting):
                v_new[resting] = 0.0
                w_new[resting] = 0.0
                q = q_new[resting]
                yaw = np.arctan2(2 * (q[:, 3] * q[:, 2] + q[:, 0] * q[:, 1]), 1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2))
                level = np.zeros_like(q)
                level[:, 2] = np.sin(yaw / 2)
                level[:, 3] = np.cos(yaw / 2)
                q_new[resting] = level
                r[resting] = quat_to_matrix(level)
            acc[touching] = (v_new[touching] - v_old[touching]) / h
        s.position, s.velocity, s.omega, s.quaternion = p_new, v_new, w_new, q_new
        s.acceleration = acc
        s.on_ground = resting
        sf_world = acc + s.gravity_vector
        s.specific_force = (sf_world[:, None, :] @ r)[:, 0, :]     # R^T (a + g)


def _substep_row(h: float, f: List[float], target: List[float], blend: float, drag: List[float],
                 p: List[float], v: List[float], q: List[float], w: List[float], inertia: List[float],
                 torque_scale: List[float], inv_mass: float, inv_inertia: List[float], g: float):
    """One vehicle's ``_substep`` in floats (the same sums; the matrices written out), or None when the
    vehicle would reach the floor. Returns (thrust, position, velocity, omega, quaternion, acceleration,
    specific force)."""
    f = [fk + (tk - fk) * blend for fk, tk in zip(f, target)]
    f1, f2, f3, f4 = f
    tx, ty, tz, total = -f1 - f2 + f3 + f4, -f1 + f2 + f3 - f4, -f1 + f2 - f3 + f4, f1 + f2 + f3 + f4
    x, y, z, qw = q
    ww, xx, yy, zz = qw * qw, x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = 2.0 * x * y, 2.0 * x * z, 2.0 * y * z, 2.0 * qw * x, 2.0 * qw * y, 2.0 * qw * z
    r00, r01, r02 = ww + xx - yy - zz, xy - wz, xz + wy
    r10, r11, r12 = xy + wz, ww - xx + yy - zz, yz - wx
    r20, r21, r22 = xz - wy, yz + wx, ww - xx - yy + zz
    v0, v1, v2 = v
    b0 = (v0 * r00 + v1 * r10 + v2 * r20) * drag[0]                    # body frame: rotor drag, thrust
    b1 = (v0 * r01 + v1 * r11 + v2 * r21) * drag[1]
    b2 = (v0 * r02 + v1 * r12 + v2 * r22) * drag[2] + total
    a0 = (r00 * b0 + r01 * b1 + r02 * b2) * inv_mass
    a1 = (r10 * b0 + r11 * b1 + r12 * b2) * inv_mass
    a2 = (r20 * b0 + r21 * b1 + r22 * b2) * inv_mass - g
    w0, w1, w2 = w
    i0, i1, i2 = inertia[0] * w0, inertia[1] * w1, inertia[2] * w2
    n0 = (tx * torque_scale[0] - (w1 * i2 - w2 * i1)) * inv_inertia[0] * h
    n1 = (ty * torque_scale[1] - (w2 * i0 - w0 * i2)) * inv_inertia[1] * h
    n2 = (tz * torque_scale[2] - (w0 * i1 - w1 * i0)) * inv_inertia[2] * h
    w0, w1, w2 = w0 + n0, w1 + n1, w2 + n2
    nv0, nv1, nv2 = v0 + a0 * h, v1 + a1 * h, v2 + a2 * h
    half = 0.5 * h
    p2 = (v2 + nv2) * half + p[2]
    if p2 <= 0.0 or p2 != p2:
        return None
    position = [(v0 + nv0) * half + p[0], (v1 + nv1) * half + p[1], p2]
    rx, ry, rz = w0 * h, w1 * h, w2 * h                                 # rotation of the substep
    a_sq = rx * rx + ry * ry + rz * rz
    (s0, c0), (s1, c1), (s2, c2), (s3, c3) = _ROTATION_SERIES.tolist()
    sinc = ((a_sq * s0 + s1) * a_sq + s2) * a_sq + s3
    cosine = ((a_sq * c0 + c1) * a_sq + c2) * a_sq + c3
    bx, by, bz = rx * sinc, ry * sinc, rz * sinc
    qx = qw * bx + x * cosine + y * bz - z * by
    qy = qw * by - x * bz + y * cosine + z * bx
    qz = qw * bz + x * by - y * bx + z * cosine
    qn = qw * cosine - x * bx - y * by - z * bz
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qn * qn)
    sf0, sf1, sf2 = a0, a1, a2 + g                                       # R^T (a + g), with the old R
    return (f, position, [nv0, nv1, nv2], [w0, w1, w2], [qx / norm, qy / norm, qz / norm, qn / norm], [a0, a1, a2],
            [sf0 * r00 + sf1 * r10 + sf2 * r20, sf0 * r01 + sf1 * r11 + sf2 * r21, sf0 * r02 + sf1 * r12 + sf2 * r22])


def _small_rotation(v: np.ndarray) -> np.ndarray:
    """quat_from_rotvec for the rotation of one substep, without branches.

    sin(a/2)/a and cos(a/2) by their series to a⁶ (evaluated together): below 0.1 rad (50 rad/s over
    a 2 ms substep) the dropped terms are under 1e-13; the caller normalises the product.
    """
    a2 = (v * v) @ _ONES31
    series = a2 * _ROTATION_SERIES[0]
    series += _ROTATION_SERIES[1]
    series *= a2
    series += _ROTATION_SERIES[2]
    series *= a2
    series += _ROTATION_SERIES[3]
    out = np.empty((len(v), 4))
    np.multiply(v, series[:, 0:1], out=out[:, :3])
    out[:, 3] = series[:, 1]
    return out


def _quat_multiply_flat(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """quat_multiply as one matrix product (same values up to rounding)."""
    return (a[:, :, None] * b[:, None, :]).reshape(-1, 16) @ _QUAT_PRODUCT


# torque = (F @ pattern) * (arm_xy, arm_xy, κ): docs/simulation.md, "Vehicle physics"
_TORQUE_PATTERN = np.array([[-1.0, -1.0, -1.0],
                            [-1.0, 1.0, 1.0],
                            [1.0, 1.0, -1.0],
                            [1.0, -1.0, 1.0]])
_FORCE_PATTERN = np.concatenate([_TORQUE_PATTERN, np.ones((4, 1))], axis=1)      # last column: total thrust
_QUAT_TO_MATRIX = quadratic_form(lambda q: quat_to_matrix(q[None])[0].ravel(), 4)            # (16, 9)
_QUAT_PRODUCT = bilinear_form(lambda a, b: quat_multiply(a[None], b[None])[0], 4, 4)          # (16, 4)
_CROSS = bilinear_form(np.cross, 3, 3)
_MINUS_ONES4 = -np.ones((4, 1))
_ONES31 = np.ones((3, 1))
_ONES41 = np.ones((4, 1))
# Horner coefficients (highest power first) of sin(a/2)/a and cos(a/2) in a²
_ROTATION_SERIES = np.array([[-1.0 / 645120.0, -1.0 / 46080.0], [1.0 / 3840.0, 1.0 / 384.0],
                             [-1.0 / 48.0, -1.0 / 8.0], [0.5, 1.0]])
