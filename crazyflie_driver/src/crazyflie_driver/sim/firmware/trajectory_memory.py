"""The trajectory memory of the current firmware (port 4) and the trajectory descriptors of port 8.

One memory, id 0, type 0x12, 4096 bytes, read and written 1:1; a trajectory is a descriptor
(location, type, offset, number of pieces) pointing into it. poly4d pieces are 33 little-endian
floats: eight coefficients each of x, y, z and yaw (ascending powers), then the duration.
Facts in docs/protocol.md ("Trajectory memory").
"""
from __future__ import annotations

import struct
from typing import Callable, Dict, List, NamedTuple, Optional, Tuple

import numpy as np

MEMORY_ID = 0
MEMORY_TYPE_TRAJECTORY = 0x12
MEMORY_SIZE = 4096                  # bytes
MAX_TRAJECTORIES = 31
LOCATION_MEMORY = 1
TYPE_POLY4D, TYPE_COMPRESSED = 0, 1
POLY4D_PIECE = struct.Struct("<33f")
EIO = 5
INFO_SERIAL = bytes(8)

Handler = Callable[[int, int, bytes], None]
Send = Callable[[int, bytes], bool]


class Descriptor(NamedTuple):
    location: int
    kind: int
    offset: int
    n_pieces: int


class TrajectoryMemory:
    """The memory bytes and the 31 trajectory descriptors of one Crazyflie."""

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

    def pieces(self, trajectory_id: int) -> Optional[List[Tuple[float, np.ndarray]]]:
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


def trajectory_memory_port(send: Send, memory: TrajectoryMemory) -> Handler:
    """Port 4 with one memory: enumeration (ch 0), reads (ch 1) and writes (ch 2)."""
    def handle(header: int, channel: int, data: bytes) -> None:
        if not data:
            return
        if channel == 0:
            if data[0] == 1:
                send(header, bytes([1, 1]))
            elif data[0] == 2 and len(data) >= 2:
                if data[1] == MEMORY_ID:
                    send(header, bytes([2, MEMORY_ID, MEMORY_TYPE_TRAJECTORY]) + struct.pack("<I", MEMORY_SIZE)
                         + INFO_SERIAL)
                else:
                    send(header, bytes(data[:2]))          # short reply: no such memory
        elif channel == 1 and len(data) >= 6:
            ident, address, length = data[0], struct.unpack_from("<I", data, 1)[0], data[5]
            got = memory.read(address, length) if ident == MEMORY_ID else None
            send(header, bytes(data[:5]) + (bytes([0]) + got if got is not None else bytes([EIO])))
        elif channel == 2 and len(data) >= 5:
            ident, address = data[0], struct.unpack_from("<I", data, 1)[0]
            ok = ident == MEMORY_ID and memory.write(address, bytes(data[5:]))
            send(header, bytes(data[:5]) + bytes([0 if ok else EIO]))
    return handle
