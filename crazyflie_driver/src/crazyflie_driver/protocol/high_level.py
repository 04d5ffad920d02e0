"""Port 8 (high-level commander): takeoff, land, go_to, trajectories, group masks.

Builders pick the newest form of a command the Crazyflie's protocol version has (TAKEOFF_2 /
LAND_2 from 5, GO_TO_2 from 8, START_TRAJECTORY_2 from 10) and the original one otherwise.
Angles are radians (the firmware's unit). ``HighLevelCommander`` sends them to one Crazyflie and
checks the firmware's reply; the same packets go out by broadcast for a swarm.
"""
from __future__ import annotations

import errno
import struct
from typing import Callable, Dict, NamedTuple, Optional, Sequence

from crazyflie_driver.crtp.packet import PORT_HIGH_LEVEL, CRTPPacket
from crazyflie_driver.errors import CommandRejected, CommandValueError, NotSupported, TrajectoryError
from crazyflie_driver.protocol.checks import finite, group_mask, non_negative, positive
from crazyflie_driver.protocol.memory import TYPE_TRAJECTORY, MemoryClient
from crazyflie_driver.protocol.trajectory import PIECE_BYTES, Piece, check_id, pack_compressed, pack_poly4d

CMD_SET_GROUP_MASK = 0
CMD_TAKEOFF = 1
CMD_LAND = 2
CMD_STOP = 3
CMD_GO_TO = 4
CMD_START_TRAJECTORY = 5
CMD_DEFINE_TRAJECTORY = 6
CMD_TAKEOFF_2 = 7
CMD_LAND_2 = 8
CMD_GO_TO_2 = 12
CMD_START_TRAJECTORY_2 = 13

LOCATION_MEMORY = 1
FORMAT_POLY4D = 0
FORMAT_COMPRESSED = 1

#: Protocol versions from which a command exists (2018.10, 2022.03, 2024.10, 2025.09). TAKEOFF_2
#: came with firmware 2020.02, inside protocol 4, so it is used only from the next version on.
HIGH_LEVEL_FROM = 4
TAKEOFF_2_FROM = 5
GO_TO_2_FROM = 8
START_TRAJECTORY_2_FROM = 10

#: The firmware answers ``[cmd, byte 1, byte 2, result]``; takeoff outside IDLE answers 1.
_REPLY_LENGTH = 4
_RESULTS = {
    errno.ENOEXEC: "the Crazyflie does not accept it (unknown command, undefined trajectory or an option its "
                   "format does not allow)",
    errno.EBUSY: "the supervisor blocks the high-level commander (locked after an emergency stop or a crash? "
                 "restart the Crazyflie)",
}


def _require(protocol_version: int, since: int, what: str) -> None:
    if protocol_version < since:
        raise NotSupported("%s needs protocol version %d or later; this Crazyflie speaks %d: update its firmware"
                           % (what, since, protocol_version))


def _packet(fmt: str, *values) -> CRTPPacket:
    return CRTPPacket(PORT_HIGH_LEVEL, 0, struct.pack(fmt, *values))


def set_group_mask_packet(mask: int) -> CRTPPacket:
    """Make the Crazyflie a member of the groups whose bits are set (0: of none)."""
    return _packet("<BB", CMD_SET_GROUP_MASK, group_mask(mask))


def in_groups(member_mask: int, request_mask: int) -> bool:
    """Whether a Crazyflie in groups ``member_mask`` takes a command sent to ``request_mask`` (the
    firmware's rule: 0 reaches every Crazyflie, otherwise a shared bit)."""
    return request_mask == 0 or bool(member_mask & request_mask)


def nobody_addressed(request_mask: int, groups: str, what: str = "") -> CommandValueError:
    """The refusal of a command whose group mask reaches no Crazyflie (``groups``: theirs, for the
    message). The firmware would answer such a command OK and do nothing, so it is not sent."""
    return CommandValueError("%sno Crazyflie is in group mask %d (%s): nothing would fly or land; 0 addresses every "
                             "Crazyflie, and set_group_mask of each Crazyflie sets its groups"
                             % (what + " refused, nothing sent: " if what else "", request_mask, groups))


def _vertical(cmd_old: int, cmd_new: int, height: float, duration: float, mask: int, yaw: Optional[float],
              protocol_version: int, what: str) -> CRTPPacket:
    _require(protocol_version, HIGH_LEVEL_FROM, what)
    mask = group_mask(mask)
    height = finite("height", height)
    duration = non_negative("duration", duration)
    if protocol_version < TAKEOFF_2_FROM:
        if yaw is not None:
            raise NotSupported("%s with a yaw needs protocol version %d or later (this Crazyflie speaks %d)"
                               % (what, TAKEOFF_2_FROM, protocol_version))
        return _packet("<BBff", cmd_old, mask, height, duration)
    use_current = yaw is None
    return _packet("<BBff?f", cmd_new, mask, height, 0.0 if use_current else finite("yaw", yaw), use_current, duration)


def takeoff_packet(height: float, duration: float, protocol_version: int, group_mask: int = 0,
                   yaw: Optional[float] = None) -> CRTPPacket:
    """Rise to ``height`` (m, absolute) in ``duration`` s; yaw (rad) None keeps the current heading."""
    return _vertical(CMD_TAKEOFF, CMD_TAKEOFF_2, height, duration, group_mask, yaw, protocol_version, "takeoff")


def land_packet(height: float, duration: float, protocol_version: int, group_mask: int = 0,
                yaw: Optional[float] = None) -> CRTPPacket:
    """Descend to ``height`` (m, absolute) in ``duration`` s, then motors off."""
    return _vertical(CMD_LAND, CMD_LAND_2, height, duration, group_mask, yaw, protocol_version, "land")


def stop_packet(group_mask_: int = 0) -> CRTPPacket:
    """Stop the plan and switch the motors off (the planner goes idle)."""
    return _packet("<BB", CMD_STOP, group_mask(group_mask_))


def go_to_packet(x: float, y: float, z: float, yaw: float, duration: float, protocol_version: int,
                 relative: bool = False, linear: bool = False, group_mask_: int = 0) -> CRTPPacket:
    """Fly to (x, y, z) m with yaw (rad) in ``duration`` s; ``relative`` adds to the current position."""
    _require(protocol_version, HIGH_LEVEL_FROM, "go_to")
    values = [finite(n, v) for n, v in (("goal x", x), ("goal y", y), ("goal z", z), ("yaw", yaw))]
    values.append(non_negative("duration", duration))
    mask = group_mask(group_mask_)
    if protocol_version < GO_TO_2_FROM:
        if linear:
            raise NotSupported("a linear go_to needs protocol version %d or later (this Crazyflie speaks %d)"
                               % (GO_TO_2_FROM, protocol_version))
        return _packet("<BBB5f", CMD_GO_TO, mask, bool(relative), *values)
    return _packet("<BBBB5f", CMD_GO_TO_2, mask, bool(relative), bool(linear), *values)


def start_trajectory_packet(trajectory_id: int, protocol_version: int, timescale: float = 1.0,
                            reversed_: bool = False, relative: bool = False, relative_yaw: bool = False,
                            group_mask_: int = 0) -> CRTPPacket:
    """Fly an uploaded trajectory; ``relative`` shifts it to start where the Crazyflie is,
    ``timescale`` > 1 flies it slower, ``relative_yaw`` (with ``relative``) turns it to the current yaw."""
    _require(protocol_version, HIGH_LEVEL_FROM, "start_trajectory")
    check_id(trajectory_id)
    scale = positive("timescale", timescale)
    mask = group_mask(group_mask_)
    if relative_yaw and not relative:
        raise TrajectoryError("relative_yaw only applies together with relative (position); set both")
    if protocol_version < START_TRAJECTORY_2_FROM:
        if relative_yaw:
            raise NotSupported("relative_yaw needs protocol version %d or later (this Crazyflie speaks %d)"
                               % (START_TRAJECTORY_2_FROM, protocol_version))
        return _packet("<BBBBBf", CMD_START_TRAJECTORY, mask, bool(relative), bool(reversed_), trajectory_id, scale)
    return _packet("<BBBBBBf", CMD_START_TRAJECTORY_2, mask, bool(relative), bool(relative_yaw), bool(reversed_),
                   trajectory_id, scale)


def define_trajectory_packet(trajectory_id: int, address: int, n_pieces: int, compressed: bool = False) -> CRTPPacket:
    """Declare that trajectory ``trajectory_id`` lies in the trajectory memory at byte ``address``."""
    check_id(trajectory_id)
    if not 0 <= address <= 0xFFFFFFFF or not 0 <= n_pieces <= 0xFF:
        raise TrajectoryError("trajectory address %r or piece count %r out of range" % (address, n_pieces))
    return _packet("<BBBBIB", CMD_DEFINE_TRAJECTORY, trajectory_id, LOCATION_MEMORY,
                   FORMAT_COMPRESSED if compressed else FORMAT_POLY4D, address, n_pieces)


def result_message(cmd: int, result: int) -> str:
    """What a non-zero result of the firmware means, for an error message."""
    if cmd in (CMD_TAKEOFF, CMD_TAKEOFF_2) and result == 1:
        return "takeoff is accepted only while the planner is idle (on the ground, not flying a plan)"
    return _RESULTS.get(result, "the planner refused it (error %d)" % result)


class TrajectoryInfo(NamedTuple):
    """What was uploaded under one identifier."""

    address: int       # byte address in the trajectory memory
    length: int        # bytes stored there
    n_pieces: int
    compressed: bool
    duration: float


class HighLevelCommander:
    """High-level commands to one Crazyflie, each confirmed by the firmware's reply.

    ``send`` and ``request`` are the link's; a refused command raises CommandRejected with the reason.
    Without a reply within ``timeout`` LinkTimeout is raised. ``trajectories`` remembers what was
    uploaded, so starting an unknown one fails before anything is sent.
    """

    def __init__(self, send: Callable[[CRTPPacket], bool], request, memory: MemoryClient,
                 protocol_version: int = -1, timeout: float = 1.0, label: str = "") -> None:
        self._send = send
        self._request = request
        self._memory = memory
        self.protocol_version = protocol_version
        self.timeout = timeout
        self.label = label
        self.trajectories: Dict[int, TrajectoryInfo] = {}

    def command(self, packet: CRTPPacket, idempotent: bool = True) -> None:
        """Send one high-level packet and check the reply. A command that must not run twice (a
        relative go_to) is sent again only where safelink makes duplicates impossible."""
        cmd = packet.data[0]
        head = packet.data[1:3]     # the reply echoes two request bytes; a shorter request (stop, set
        # group mask: one byte after the command) is compared on the bytes it has
        reply = self._request(packet,
                              match=lambda p: (p.port == PORT_HIGH_LEVEL and len(p.data) >= _REPLY_LENGTH
                                               and p.data[0] == cmd and p.data[1:1 + len(head)] == head),
                              timeout=self.timeout, resend_interval=0.2 if idempotent else self.timeout + 1.0,
                              what="high-level command %d (8:0)" % cmd)
        result = reply.data[3]
        if result != 0:
            raise CommandRejected("%s: high-level command %d refused: %s"
                                  % (self.label, cmd, result_message(cmd, result)))

    def set_group_mask(self, mask: int) -> None:
        _require(self.protocol_version, HIGH_LEVEL_FROM, "set_group_mask")
        self.command(set_group_mask_packet(mask))

    def takeoff(self, height: float, duration: float, group_mask: int = 0, yaw: Optional[float] = None) -> None:
        self.command(takeoff_packet(height, duration, self.protocol_version, group_mask, yaw))

    def land(self, height: float, duration: float, group_mask: int = 0, yaw: Optional[float] = None) -> None:
        self.command(land_packet(height, duration, self.protocol_version, group_mask, yaw))

    def stop(self, group_mask: int = 0) -> None:
        _require(self.protocol_version, HIGH_LEVEL_FROM, "stop")
        self.command(stop_packet(group_mask))

    def go_to(self, x: float, y: float, z: float, yaw: float, duration: float, relative: bool = False,
              linear: bool = False, group_mask: int = 0) -> None:
        packet = go_to_packet(x, y, z, yaw, duration, self.protocol_version, relative, linear, group_mask)
        self.command(packet, idempotent=not relative)

    def start_trajectory(self, trajectory_id: int, timescale: float = 1.0, reversed_: bool = False,
                         relative: bool = False, relative_yaw: bool = False, group_mask: int = 0) -> None:
        self.command(self.start_trajectory_packet(trajectory_id, timescale, reversed_, relative, relative_yaw,
                                                  group_mask))

    def start_trajectory_packet(self, trajectory_id: int, timescale: float = 1.0, reversed_: bool = False,
                                relative: bool = False, relative_yaw: bool = False,
                                group_mask: int = 0) -> CRTPPacket:
        """The start packet, checked against what was uploaded (TrajectoryError for an unknown id)."""
        packet = start_trajectory_packet(trajectory_id, self.protocol_version, timescale, reversed_, relative,
                                         relative_yaw, group_mask)
        info = self.trajectories.get(trajectory_id)
        if info is None:
            raise TrajectoryError("%s: trajectory %d was not uploaded (uploaded: %s); call upload_trajectory first"
                                  % (self.label, trajectory_id, sorted(self.trajectories) or "none"))
        if info.compressed and (timescale != 1.0 or reversed_):
            raise TrajectoryError("trajectory %d is compressed: the firmware plays compressed trajectories only "
                                  "forwards at timescale 1" % trajectory_id)
        return packet

    def upload_trajectory(self, trajectory_id: int, pieces: Sequence[Piece], piece_offset: int = 0,
                          compressed: bool = False) -> TrajectoryInfo:
        """Write the pieces into the trajectory memory at ``piece_offset`` x 132 bytes, then define
        the trajectory. Everything is checked before the first byte is sent."""
        _require(self.protocol_version, HIGH_LEVEL_FROM, "upload_trajectory")
        check_id(trajectory_id)
        if isinstance(piece_offset, bool) or not isinstance(piece_offset, int) or piece_offset < 0:
            raise TrajectoryError("piece offset must be an integer >= 0, got %r" % (piece_offset,))
        data = pack_compressed(pieces) if compressed else pack_poly4d(pieces)
        address = piece_offset * PIECE_BYTES
        memory = self._memory.find(TYPE_TRAJECTORY)
        if memory is None:
            raise NotSupported("%s has no trajectory memory (memory type 0x%02X)" % (self.label, TYPE_TRAJECTORY))
        if address + len(data) > memory.size:
            raise TrajectoryError("trajectory %d needs %d bytes at byte %d, but the trajectory memory holds %d bytes "
                                  "(%d poly4d pieces in all): use fewer pieces, a smaller piece offset or compressed"
                                  % (trajectory_id, len(data), address, memory.size, memory.size // PIECE_BYTES))
        overlapping = [i for i, t in self.trajectories.items() if i != trajectory_id
                       and t.address < address + len(data) and address < t.address + t.length]
        self._memory.write(memory.id, address, data)
        for i in overlapping:
            del self.trajectories[i]   # overwritten: starting them would fly garbage
        self.command(define_trajectory_packet(trajectory_id, address, len(pieces), compressed))
        info = TrajectoryInfo(address, len(data), len(pieces), bool(compressed), sum(p.duration for p in pieces))
        self.trajectories[trajectory_id] = info
        return info
