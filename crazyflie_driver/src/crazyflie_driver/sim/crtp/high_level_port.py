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
from typing import Any, Callable, Dict, NamedTuple, Tuple

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


# --- the fields of each command as the world's keyword arguments (pure) -------------------------
Args = Dict[str, Any]


def _mask_args(f: Tuple) -> Args:
    return {"mask": f[0]}


def _height_args(f: Tuple) -> Args:
    """TAKEOFF / LAND: group mask, height, duration; yaw 0."""
    return {"mask": f[0], "height": f[1], "yaw": 0.0, "duration": f[2]}


def _height_yaw_args(f: Tuple) -> Args:
    """TAKEOFF_2 / LAND_2: group mask, height, yaw, use current yaw, duration."""
    return {"mask": f[0], "height": f[1], "yaw": f[2], "use_current_yaw": f[3], "duration": f[4]}


def _height_velocity_args(f: Tuple) -> Args:
    """TAKEOFF_WITH_VELOCITY / LAND_WITH_VELOCITY: group mask, height, relative, yaw, use current yaw,
    velocity."""
    return {"mask": f[0], "height": f[1], "relative": f[2], "yaw": f[3], "use_current_yaw": f[4],
            "velocity": f[5]}


def _go_to_args(f: Tuple) -> Args:
    """GO_TO: group mask, relative, x, y, z, yaw, duration; never linear."""
    return {"mask": f[0], "relative": f[1], "linear": False, "goal": f[2:5], "yaw": f[5], "duration": f[6]}


def _go_to_2_args(f: Tuple) -> Args:
    """GO_TO_2: GO_TO with a linear flag after relative."""
    return {"mask": f[0], "relative": f[1], "linear": f[2], "goal": f[3:6], "yaw": f[6], "duration": f[7]}


def _spiral_args(f: Tuple) -> Args:
    return {"mask": f[0], "sideways": bool(f[1]), "clockwise": bool(f[2]), "angle": f[3], "r0": f[4],
            "rf": f[5], "ascent": f[6], "duration": f[7]}


#: The commands the world plays directly: command -> (the world's operation, its arguments).
_CALLS: Dict[int, Tuple[str, Callable[[Tuple], Args]]] = {
    SET_GROUP_MASK: ("set_group_mask", _mask_args),
    TAKEOFF: ("takeoff", _height_args), LAND: ("land", _height_args),
    TAKEOFF_2: ("takeoff", _height_yaw_args), LAND_2: ("land", _height_yaw_args),
    TAKEOFF_WITH_VELOCITY: ("takeoff", _height_velocity_args), LAND_WITH_VELOCITY: ("land", _height_velocity_args),
    STOP: ("stop", _mask_args),
    GO_TO: ("go_to", _go_to_args), GO_TO_2: ("go_to", _go_to_2_args),
    SPIRAL: ("spiral", _spiral_args),
}


class _Start(NamedTuple):
    """A start-trajectory request, either version."""

    mask: int
    traj_id: int
    timescale: float
    reversed_: bool
    relative: bool
    relative_yaw: bool


def _start_args(f: Tuple) -> _Start:
    """START_TRAJECTORY: group mask, relative, reversed, id, time scale; no relative yaw."""
    return _Start(f[0], f[3], f[4], bool(f[2]), bool(f[1]), False)


def _start_2_args(f: Tuple) -> _Start:
    """START_TRAJECTORY_2: group mask, relative, relative yaw (only with relative), reversed, id,
    time scale."""
    return _Start(f[0], f[4], f[5], bool(f[3]), bool(f[1]), bool(f[1] and f[2]))


_STARTS: Dict[int, Callable[[Tuple], _Start]] = {START_TRAJECTORY: _start_args, START_TRAJECTORY_2: _start_2_args}


# --- the port ------------------------------------------------------------------------------------
def high_level_port(send: Send, call: Call, memory: TrajectoryMemory) -> Handler:
    return _HighLevelPort(send, call, memory).handle


class _HighLevelPort:
    """Decodes one command per packet, has the world play it (or defines a trajectory in memory)
    and replies with the result."""

    def __init__(self, send: Send, call: Call, memory: TrajectoryMemory) -> None:
        self._send = send
        self._call = call
        self._memory = memory

    def handle(self, header: int, channel: int, data: bytes) -> None:
        if not data:
            return
        result = self.execute(data[0], bytes(data[1:]))
        echo = bytes(data[:3]).ljust(3, b"\x00")
        self._send(header, echo + bytes([result & 0xFF]))

    def execute(self, cmd: int, data: bytes) -> int:
        """The result code of command ``cmd`` with its fields ``data`` (0, or an errno)."""
        if cmd not in LAYOUTS:
            return ENOEXEC
        f = _fields(cmd, data)
        if cmd in _CALLS:
            op, args_of = _CALLS[cmd]
            return self._call(op, **args_of(f))
        if cmd in _STARTS:
            return self._start(_STARTS[cmd](f))
        if cmd == DEFINE_TRAJECTORY:
            return self._define(f)
        return ENOEXEC

    def _define(self, f: Tuple) -> int:
        traj_id, location, kind, offset, n_pieces = f
        if traj_id >= MAX_TRAJECTORIES:
            return ENOEXEC
        self._memory.descriptors[traj_id] = Descriptor(location, kind, offset, n_pieces)
        return 0

    def _start(self, s: _Start) -> int:
        pieces = self._memory.pieces(s.traj_id)
        if pieces is None:
            return self._start_compressed(s)
        return self._call("start_trajectory", mask=s.mask, pieces=pieces, timescale=s.timescale,
                          reversed=s.reversed_, relative=s.relative, relative_yaw=s.relative_yaw)

    def _start_compressed(self, s: _Start) -> int:
        """The firmware plays a compressed trajectory only forwards at its own speed, shifted in
        position only (no relative yaw); ENOEXEC when ``traj_id`` is defined neither way."""
        compressed = self._memory.compressed(s.traj_id)
        if compressed is None:
            return ENOEXEC
        if s.timescale != 1.0 or s.reversed_:
            return self._call("start_trajectory", mask=s.mask, pieces=[])
        pieces, past_end = compressed
        if past_end:
            _log.warning("compressed trajectory %d runs past the end of the trajectory memory: the simulated "
                         "Crazyflie reads zeros there (the real one reads whatever RAM follows)", s.traj_id)
        return self._call("start_trajectory", mask=s.mask, pieces=pieces, timescale=s.timescale, reversed=False,
                          relative=s.relative, relative_yaw=False)
