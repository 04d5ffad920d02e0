"""Port 8: the high-level commander's packets decoded as the current firmware decodes them.

Every packet gets a reply on its own header, ``[command, request byte 1, request byte 2, result]``.
The planning itself happens in the world (``call(command, **args) -> result``); trajectory
definitions and their data live in the ``TrajectoryMemory``. A packet shorter than its command's
layout is read as if zero-padded (the firmware reads whatever the buffer holds). Facts in
docs/protocol.md ("High-level commander"); compressed trajectories and the spiral in
docs/simulation.md.
"""
from __future__ import annotations

import logging
import struct
from typing import Callable, Dict, Tuple

from crazyflie_driver.sim.crtp.trajectory_memory import MAX_TRAJECTORIES, Descriptor, TrajectoryMemory

_log = logging.getLogger(__name__)

ENOEXEC = 8
Handler = Callable[[int, int, bytes], None]
Send = Callable[[int, bytes], bool]
Call = Callable[..., int]

SET_GROUP_MASK, TAKEOFF, LAND, STOP, GO_TO, START_TRAJECTORY, DEFINE_TRAJECTORY = 0, 1, 2, 3, 4, 5, 6
TAKEOFF_2, LAND_2, TAKEOFF_WITH_VELOCITY, LAND_WITH_VELOCITY, SPIRAL, GO_TO_2, START_TRAJECTORY_2 = \
    7, 8, 9, 10, 11, 12, 13

LAYOUTS: Dict[int, struct.Struct] = {
    SET_GROUP_MASK: struct.Struct("<B"), TAKEOFF: struct.Struct("<Bff"), LAND: struct.Struct("<Bff"),
    STOP: struct.Struct("<B"), GO_TO: struct.Struct("<BBfffff"), START_TRAJECTORY: struct.Struct("<BBBBf"),
    DEFINE_TRAJECTORY: struct.Struct("<BBBIB"), TAKEOFF_2: struct.Struct("<Bff?f"), LAND_2: struct.Struct("<Bff?f"),
    TAKEOFF_WITH_VELOCITY: struct.Struct("<Bf?f?f"), LAND_WITH_VELOCITY: struct.Struct("<Bf?f?f"),
    GO_TO_2: struct.Struct("<BBBfffff"), START_TRAJECTORY_2: struct.Struct("<BBBBBf"),
    SPIRAL: struct.Struct("<BBBfffff"),
}


def _fields(cmd: int, data: bytes) -> Tuple:
    layout = LAYOUTS[cmd]
    return layout.unpack(bytes(data[:layout.size]).ljust(layout.size, b"\x00"))


def high_level_port(send: Send, call: Call, memory: TrajectoryMemory) -> Handler:
    def start(mask: int, traj_id: int, timescale: float, reversed_: bool, relative: bool, relative_yaw: bool) -> int:
        pieces = memory.pieces(traj_id)
        if pieces is None:
            compressed = memory.compressed(traj_id)
            if compressed is None:
                return ENOEXEC
            # the firmware plays a compressed trajectory only forwards at its own speed, shifted in
            # position only (no relative yaw)
            if timescale != 1.0 or reversed_:
                return call("start_trajectory", mask=mask, pieces=[])
            pieces, past_end = compressed
            if past_end:
                _log.warning("compressed trajectory %d runs past the end of the trajectory memory: the simulated "
                             "Crazyflie reads zeros there (the real one reads whatever RAM follows)", traj_id)
            relative_yaw = False
        return call("start_trajectory", mask=mask, pieces=pieces, timescale=timescale, reversed=reversed_,
                    relative=relative, relative_yaw=relative_yaw)

    def execute(cmd: int, data: bytes) -> int:
        if cmd not in LAYOUTS:
            return ENOEXEC
        f = _fields(cmd, data)
        if cmd == SET_GROUP_MASK:
            return call("set_group_mask", mask=f[0])
        if cmd in (TAKEOFF, LAND):
            return call("takeoff" if cmd == TAKEOFF else "land", mask=f[0], height=f[1], yaw=0.0, duration=f[2])
        if cmd in (TAKEOFF_2, LAND_2):
            return call("takeoff" if cmd == TAKEOFF_2 else "land", mask=f[0], height=f[1], yaw=f[2],
                        use_current_yaw=f[3], duration=f[4])
        if cmd in (TAKEOFF_WITH_VELOCITY, LAND_WITH_VELOCITY):
            return call("takeoff" if cmd == TAKEOFF_WITH_VELOCITY else "land", mask=f[0], height=f[1],
                        relative=f[2], yaw=f[3], use_current_yaw=f[4], velocity=f[5])
        if cmd == STOP:
            return call("stop", mask=f[0])
        if cmd == GO_TO:
            return call("go_to", mask=f[0], relative=f[1], linear=False, goal=f[2:5], yaw=f[5], duration=f[6])
        if cmd == GO_TO_2:
            return call("go_to", mask=f[0], relative=f[1], linear=f[2], goal=f[3:6], yaw=f[6], duration=f[7])
        if cmd == SPIRAL:
            return call("spiral", mask=f[0], sideways=bool(f[1]), clockwise=bool(f[2]), angle=f[3], r0=f[4],
                        rf=f[5], ascent=f[6], duration=f[7])
        if cmd == START_TRAJECTORY:
            return start(f[0], f[3], f[4], bool(f[2]), bool(f[1]), False)
        if cmd == START_TRAJECTORY_2:
            return start(f[0], f[4], f[5], bool(f[3]), bool(f[1]), bool(f[1] and f[2]))
        if cmd == DEFINE_TRAJECTORY:
            traj_id, location, kind, offset, n_pieces = f
            if traj_id >= MAX_TRAJECTORIES:
                return ENOEXEC
            memory.descriptors[traj_id] = Descriptor(location, kind, offset, n_pieces)
            return 0
        return ENOEXEC

    def handle(header: int, channel: int, data: bytes) -> None:
        if not data:
            return
        result = execute(data[0], bytes(data[1:]))
        echo = bytes(data[:3]).ljust(3, b"\x00")
        send(header, echo + bytes([result & 0xFF]))
    return handle
