"""The trajectory memory of the current firmware (port 4) and the trajectory descriptors of port 8.

One memory of type 0x12 (its id is its place in the table of memory_port.py), 4096 bytes, read
and written 1:1; a trajectory is a descriptor (location, type, offset, number of pieces) pointing
into it. poly4d pieces are 33 little-endian
floats: eight coefficients each of x, y, z and yaw (ascending powers), then the duration. The
compressed format (a start point, then Bezier segments until one of duration 0) is decoded into the
same pieces, as the firmware decodes it, traps included (docs/simulation.md, "Compressed
trajectories"). Facts in docs/protocol.md ("Trajectory memory").
"""
from __future__ import annotations

import math
import struct
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple

import numpy as np

MEMORY_TYPE_TRAJECTORY = 0x12
MEMORY_SIZE = 4096                  # bytes
MAX_TRAJECTORIES = 31
LOCATION_MEMORY = 1
TYPE_POLY4D, TYPE_COMPRESSED = 0, 1
POLY4D_PIECE = struct.Struct("<33f")
COMPRESSED_START = struct.Struct("<4h")       # x, y, z in mm, yaw in tenths of a degree
COMPRESSED_HEADER = struct.Struct("<BH")      # 2 bits per axis (x, y, z, yaw): Bezier kind; duration ms
CONTROL_POINTS = (0, 1, 3, 7)                 # stored points of each kind (the first is the previous end)
DISTANCE_SCALE = 1000.0                       # stored mm per m
# The firmware divides a stored yaw by 0.1 and uses the result as radians (not a tenth of a degree).
YAW_SCALE = 0.1


class Descriptor(NamedTuple):
    location: int
    kind: int
    offset: int
    n_pieces: int


Pieces = List[Tuple[float, np.ndarray]]


def bezier_to_polynomial(points: Sequence[float], duration: float) -> np.ndarray:
    """Coefficients (8, ascending powers of t in s) of the Bezier curve with control ``points`` over
    ``duration``; a constant for one point or a duration of 0."""
    out = np.zeros(8)
    n = len(points) - 1
    if n == 0 or not duration > 0:
        out[0] = points[0]
        return out
    for k in range(n + 1):
        a_k = math.comb(n, k) * sum((-1) ** (k - i) * math.comb(k, i) * points[i] for i in range(k + 1))
        out[k] = a_k / duration ** k
    return out


def _polynomial_end(coeffs: np.ndarray, duration: float) -> float:
    return float(coeffs @ (duration ** np.arange(8)))


def decode_compressed(data: bytes, offset: int) -> Tuple[Pieces, bool]:
    """The pieces of a compressed trajectory at ``offset``, and whether it ran past the memory's end.

    The firmware walks segments until one has duration 0 and reads whatever lies beyond its 4096
    bytes; here the bytes past the end read as zeros, which ends the trajectory there. The pieces
    end with the hold segment the firmware evaluates after the last one (duration 0).
    """
    def read(at: int, size: int) -> bytes:
        chunk = bytes(data[at:at + size]) if 0 <= at < len(data) else b""
        return chunk.ljust(size, b"\x00")

    past_end = offset + COMPRESSED_START.size > len(data)
    x, y, z, yaw = COMPRESSED_START.unpack(read(offset, COMPRESSED_START.size))
    previous = [x / DISTANCE_SCALE, y / DISTANCE_SCALE, z / DISTANCE_SCALE, yaw / YAW_SCALE]
    at = offset + COMPRESSED_START.size
    pieces: Pieces = []
    while True:
        past_end |= at + COMPRESSED_HEADER.size > len(data)
        kinds, duration_ms = COMPRESSED_HEADER.unpack(read(at, COMPRESSED_HEADER.size))
        at += COMPRESSED_HEADER.size
        if duration_ms == 0:
            hold = np.zeros((4, 8))
            hold[:, 0] = previous
            pieces.append((0.0, hold))
            return pieces, past_end
        duration = duration_ms / 1000.0
        coeffs = np.zeros((4, 8))
        for axis in range(4):
            count = CONTROL_POINTS[(kinds >> (2 * axis)) & 0x03]
            past_end |= at + 2 * count > len(data)
            stored = struct.unpack("<%dh" % count, read(at, 2 * count))
            at += 2 * count
            scale = YAW_SCALE if axis == 3 else DISTANCE_SCALE
            coeffs[axis] = bezier_to_polynomial([previous[axis]] + [v / scale for v in stored], duration)
            previous[axis] = _polynomial_end(coeffs[axis], duration)
        pieces.append((duration, coeffs))


class TrajectoryMemory:
    """The memory bytes and the 31 trajectory descriptors of one Crazyflie (a memory of the table
    in memory_port.py: kind, size, serial, read, write)."""

    kind = MEMORY_TYPE_TRAJECTORY
    size = MEMORY_SIZE
    serial = bytes(8)
    writable = True

    def __init__(self) -> None:
        self.data = bytearray(MEMORY_SIZE)
        self.descriptors: Dict[int, Descriptor] = {}

    def write(self, address: int, payload: bytes) -> bool:
        if address + len(payload) > MEMORY_SIZE:
            return False
        self.data[address:address + len(payload)] = payload
        return True

    def read(self, address: int, length: int) -> Optional[bytes]:
        if address + length > MEMORY_SIZE:
            return None
        return bytes(self.data[address:address + length])

    def pieces(self, trajectory_id: int) -> Optional[Pieces]:
        """(duration, coefficients (4, 8)) of every poly4d piece of a defined trajectory; None when it
        is not defined in memory, not poly4d, or its pieces run past the end of the memory."""
        d = self.descriptors.get(trajectory_id)
        if d is None or d.location != LOCATION_MEMORY or d.kind != TYPE_POLY4D or d.n_pieces == 0:
            return None
        if d.offset + d.n_pieces * POLY4D_PIECE.size > MEMORY_SIZE:
            return None
        out = []
        for k in range(d.n_pieces):
            values = POLY4D_PIECE.unpack_from(self.data, d.offset + k * POLY4D_PIECE.size)
            out.append((values[32], np.array(values[:32], dtype=float).reshape(4, 8)))
        return out

    def compressed(self, trajectory_id: int) -> Optional[Tuple[Pieces, bool]]:
        """``decode_compressed`` of a defined compressed trajectory (its n_pieces is not used, as in
        the firmware); None when the trajectory is not a compressed one in memory."""
        d = self.descriptors.get(trajectory_id)
        if d is None or d.location != LOCATION_MEMORY or d.kind != TYPE_COMPRESSED:
            return None
        return decode_compressed(self.data, d.offset)


    def decoded(self, trajectory_id: int) -> Optional[Pieces]:
        """The pieces of a defined trajectory in memory, poly4d or compressed; None when there are none."""
        pieces = self.pieces(trajectory_id)
        if pieces is None:
            compressed = self.compressed(trajectory_id)
            pieces = compressed[0] if compressed is not None else None
        return pieces
