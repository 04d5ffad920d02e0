"""OptiTrack Y-up world -> ROS Z-up world, as a proper rotation of position and orientation.

OptiTrack Motive streams in a right-handed frame with Y vertical (X along the calibration
square's x axis, Z horizontal). ROS (REP 103) and the Crazyflie firmware use a right-handed frame
with Z up. The two are related by a +90 degree rotation about X:

    R = Rx(+90 deg) = [[1, 0, 0],        x =  X
                       [0, 0, -1],       y = -Z
                       [0, 1, 0]]        z =  Y            det(R) = +1

A plain swap of Y and Z (without the minus sign) has determinant -1: a mirror that yields a
left-handed frame, which is the usual mistake.

Orientation: the rigid body's own axes were defined in the Y-up frame too (Motive fixes them to
the world axes when the body is created), so the body frame is converted as well:
``q' = qR * q * qR^-1`` with ``qR`` the quaternion of R. That conjugation rotates the quaternion's
vector part by R and keeps w: ``(qx, qy, qz, qw) -> (qx, -qz, qy, qw)``. A body created level,
nose along Motive's +X, then reads identity in the Z-up frame, nose along +x.
"""
from __future__ import annotations

import math
from typing import Sequence, Tuple

Vec3 = Tuple[float, float, float]
Quat = Tuple[float, float, float, float]

#: Rotation matrix taking Y-up coordinates to Z-up coordinates (rows: x, y, z of the result).
Y_UP_TO_Z_UP = ((1.0, 0.0, 0.0),
                (0.0, 0.0, -1.0),
                (0.0, 1.0, 0.0))

#: The same rotation as a quaternion (x, y, z, w): +90 degrees about X.
Y_UP_TO_Z_UP_QUAT: Quat = (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4))


def y_up_to_z_up_vector(v: Sequence[float]) -> Vec3:
    """A position, velocity or angular velocity from the Y-up frame in the Z-up frame."""
    return (v[0], -v[2], v[1])


def z_up_to_y_up_vector(v: Sequence[float]) -> Vec3:
    """Inverse of :func:`y_up_to_z_up_vector` (used by the fake mocap to stream Y-up)."""
    return (v[0], v[2], -v[1])


def y_up_to_z_up_quaternion(q: Sequence[float]) -> Quat:
    """An orientation (x, y, z, w) of a body defined in the Y-up frame, in the Z-up frame."""
    return (q[0], -q[2], q[1], q[3])


def z_up_to_y_up_quaternion(q: Sequence[float]) -> Quat:
    """Inverse of :func:`y_up_to_z_up_quaternion`."""
    return (q[0], q[2], -q[1], q[3])


def y_up_to_z_up_pose(position: Sequence[float], orientation: Sequence[float]) -> Tuple[Vec3, Quat]:
    return y_up_to_z_up_vector(position), y_up_to_z_up_quaternion(orientation)


def quaternion_multiply(a: Sequence[float], b: Sequence[float]) -> Quat:
    """Hamilton product a * b of quaternions in (x, y, z, w) order."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def quaternion_to_matrix(q: Sequence[float]) -> Tuple[Vec3, Vec3, Vec3]:
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
            (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
            (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)))


def quaternion_to_rotation_vector(q: Sequence[float]) -> Vec3:
    """Axis * angle (rad) of a quaternion (x, y, z, w), the shortest way round."""
    x, y, z, w = q
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return (2 * x, 2 * y, 2 * z)        # small-angle limit
    angle = 2.0 * math.atan2(s, w)
    k = angle / s
    return (x * k, y * k, z * k)


def yaw_of(q: Sequence[float]) -> float:
    """Yaw (rad, about +z, counter-clockwise seen from above) of a Z-up orientation."""
    x, y, z, w = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def determinant(m: Sequence[Sequence[float]]) -> float:
    return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
