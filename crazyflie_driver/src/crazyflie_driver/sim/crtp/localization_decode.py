"""Port-6 (localization) packets decoded as the current firmware decodes them (pure functions).

External position (ch 0), external pose (ch 1 type 8), packed positions (ch 2) and packed poses
(ch 1 type 9), whose items carry the radio address's low byte of the Crazyflie they are for.
Facts in docs/protocol.md ("Localization").
"""
from __future__ import annotations

import struct
from typing import List, NamedTuple, Optional, Tuple

from crazyflie_driver.crtp.quaternion import decompress_quaternion as decompress_quat

CH_POSITION, CH_GENERIC, CH_POSITION_PACKED = 0, 1, 2
EMERGENCY_STOP, EMERGENCY_STOP_WATCHDOG, EXT_POSE, EXT_POSE_PACKED = 3, 4, 8, 9
POSITION_FMT = struct.Struct("<fff")
POSE_FMT = struct.Struct("<fffffff")
PACKED_POSITION_ITEM = struct.Struct("<Bhhh")          # id, x, y, z in mm
PACKED_POSE_ITEM = struct.Struct("<BhhhI")             # id, x, y, z in mm, compressed quaternion
MAX_PACKED_POSITIONS = 4
MAX_PACKED_POSES = 2


class Measurement(NamedTuple):
    """One external position (m), with its quaternion (x, y, z, w) when it is a pose."""

    position: Tuple[float, float, float]
    quaternion: Optional[Tuple[float, float, float, float]] = None


def decode_position(data: bytes) -> Optional[Measurement]:
    """Channel 0: three floats. A short packet (the firmware would read stale bytes) gives None."""
    if len(data) < POSITION_FMT.size:
        return None
    return Measurement(POSITION_FMT.unpack_from(data))


def decode_pose(data: bytes) -> Optional[Measurement]:
    """Channel 1 type 8 data (after the type byte): position and quaternion as floats."""
    if len(data) < POSE_FMT.size:
        return None
    v = POSE_FMT.unpack_from(data)
    return Measurement(v[:3], v[3:])


def decode_packed_positions(data: bytes, my_id: int) -> Tuple[Optional[Measurement], List[int]]:
    """Channel 2: up to 4 items; (the item for ``my_id`` or None, ids of the other items)."""
    mine, others = None, []
    n = min(len(data) // PACKED_POSITION_ITEM.size, MAX_PACKED_POSITIONS)
    for k in range(n):
        ident, x, y, z = PACKED_POSITION_ITEM.unpack_from(data, k * PACKED_POSITION_ITEM.size)
        if ident == my_id:
            mine = Measurement((x / 1000.0, y / 1000.0, z / 1000.0))
        else:
            others.append(ident)
    return mine, others


def decode_packed_poses(data: bytes, my_id: int) -> Tuple[Optional[Measurement], List[int]]:
    """Channel 1 type 9 data (after the type byte): up to 2 items with compressed quaternions."""
    mine, others = None, []
    n = min(len(data) // PACKED_POSE_ITEM.size, MAX_PACKED_POSES)
    for k in range(n):
        ident, x, y, z, quat = PACKED_POSE_ITEM.unpack_from(data, k * PACKED_POSE_ITEM.size)
        if ident == my_id:
            mine = Measurement((x / 1000.0, y / 1000.0, z / 1000.0), decompress_quat(quat))
        else:
            others.append(ident)
    return mine, others
