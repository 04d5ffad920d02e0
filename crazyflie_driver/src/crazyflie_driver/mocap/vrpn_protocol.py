"""VRPN wire format: cookie, message framing, system messages and tracker reports.

Pure functions and small value types, no sockets. Everything on the wire is big-endian; the
24-byte header and every payload are padded to a multiple of 8 bytes, while the header's
length field holds 24 + the *unpadded* payload length (what VRPN's code does, not what its
Format_Of_Protocol.txt says). Both directions use the same framing, so each encoder here has
its decoder, and the test server is built from the same functions the client uses.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Iterator, List, Sequence, Tuple

DEFAULT_PORT = 3883

# -- cookie ---------------------------------------------------------------------------------
COOKIE_SIZE = 24
COOKIE_PREFIX = b"vrpn: ver. 07."          # a peer's cookie must match up to the last '.'
CLIENT_VERSION = "07.35"                    # what we announce (any 07.xx is accepted by VRPN)
SERVER_VERSION = "07.38"                    # what the test server announces

# -- framing --------------------------------------------------------------------------------
HEADER_SIZE = 24
_HEADER = struct.Struct(">iiiiii")          # length, sec, usec, sender, type, sequence
MAX_MESSAGE_LENGTH = 1 << 20                # sanity bound: a larger length means a broken stream
MAX_NAME_LENGTH = 99                        # VRPN name buffers hold 100 bytes with the NUL

# -- system message types (negative type ids) -----------------------------------------------
SENDER_DESCRIPTION = -1
TYPE_DESCRIPTION = -2
UDP_DESCRIPTION = -3
LOG_DESCRIPTION = -4
DISCONNECT_MESSAGE = -5

# -- well-known names ------------------------------------------------------------------------
CONTROL_SENDER = "VRPN Control"             # the connection's own sender, not a tracker
TYPE_POS_QUAT = "vrpn_Tracker Pos_Quat"
TYPE_VELOCITY = "vrpn_Tracker Velocity"
TYPE_ACCELERATION = "vrpn_Tracker Acceleration"
TYPE_TEXT = "vrpn_Base text_message"
TYPE_PING = "vrpn_Base ping_message"
TYPE_PONG = "vrpn_Base pong_message"
CONNECTION_EVENT_TYPES = (
    "VRPN_Connection_Got_First_Connection",
    "VRPN_Connection_Got_Connection",
    "VRPN_Connection_Dropped_Connection",
    "VRPN_Connection_Dropped_Last_Connection",
)

POS_QUAT_SIZE = 64
VELOCITY_SIZE = 72
_POS_QUAT = struct.Struct(">ii3d4d")
_VELOCITY = struct.Struct(">ii3d4dd")
_TEXT_HEAD = struct.Struct(">II")
_INT32 = struct.Struct(">i")


class VrpnProtocolError(ValueError):
    """Bytes that do not follow the VRPN wire format (the message names what was wrong)."""


class VrpnFramingError(VrpnProtocolError):
    """The byte stream cannot be cut into messages any more: the connection must be reset."""


def padded(n: int) -> int:
    """``n`` rounded up to the next multiple of 8 (VRPN's alignment)."""
    return (n + 7) & ~7


# -- cookie ---------------------------------------------------------------------------------
def encode_cookie(version: str = CLIENT_VERSION, log_mode: int = 0) -> bytes:
    """The 24-byte magic: ``vrpn: ver. <version>``, two spaces, log-mode digit, NUL padding."""
    if not 0 <= log_mode <= 3:
        raise ValueError("VRPN log mode must be 0..3, got %r" % (log_mode,))
    text = ("vrpn: ver. %s  %d" % (version, log_mode)).encode("ascii")
    if len(text) > COOKIE_SIZE:
        raise ValueError("VRPN version string %r is too long for the cookie" % (version,))
    return text + b"\0" * (COOKIE_SIZE - len(text))


def decode_cookie(data: bytes) -> Tuple[str, int]:
    """(version, log mode) of a peer's cookie; raises VrpnProtocolError when it is not VRPN 07."""
    if len(data) != COOKIE_SIZE:
        raise VrpnProtocolError("VRPN cookie must be %d bytes, got %d" % (COOKIE_SIZE, len(data)))
    if not data.startswith(COOKIE_PREFIX):
        raise VrpnProtocolError("not a VRPN 07 peer: cookie starts with %r" % (data[:16],))
    version = data[len(b"vrpn: ver. "):16].decode("ascii", "replace")
    mode_byte = data[18:19]
    if not (b"0" <= mode_byte <= b"3"):
        raise VrpnProtocolError("VRPN cookie has log mode %r, expected '0'..'3'" % (mode_byte,))
    return version, int(mode_byte)


# -- messages -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Message:
    """One VRPN message as framed on the wire (ids are the *sending* side's local ids)."""

    type_id: int
    sender_id: int
    payload: bytes
    sec: int = 0
    usec: int = 0
    sequence: int = 0

    @property
    def time(self) -> float:
        """Header timestamp in seconds (sender's clock)."""
        return self.sec + self.usec * 1e-6


def encode_message(type_id: int, sender_id: int, payload: bytes = b"", sec: int = 0,
                   usec: int = 0, sequence: int = 0) -> bytes:
    """Header + payload + zero padding, exactly as VRPN marshals a message."""
    n = len(payload)
    head = _HEADER.pack(HEADER_SIZE + n, sec, usec, sender_id, type_id, sequence)
    return head + payload + b"\0" * (padded(n) - n)


def encode(msg: Message) -> bytes:
    return encode_message(msg.type_id, msg.sender_id, msg.payload, msg.sec, msg.usec, msg.sequence)


def wire_size(length_field: int) -> int:
    """Bytes a message occupies on the wire, given its header's length field."""
    return HEADER_SIZE + padded(length_field - HEADER_SIZE)


def decode_header(data: bytes, offset: int = 0) -> Tuple[int, int, int, int, int, int]:
    """(length, sec, usec, sender, type, sequence); raises VrpnFramingError on an impossible length."""
    length, sec, usec, sender, type_id, seq = _HEADER.unpack_from(data, offset)
    if length < HEADER_SIZE or length > MAX_MESSAGE_LENGTH:
        raise VrpnFramingError("VRPN message length field %d is outside %d..%d"
                               % (length, HEADER_SIZE, MAX_MESSAGE_LENGTH))
    return length, sec, usec, sender, type_id, seq


class MessageReader:
    """Cuts whole messages out of a TCP byte stream that arrives in arbitrary pieces."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> List[Message]:
        """Append ``data``; return every message now complete. VrpnFramingError: stream broken."""
        buf = self._buf
        buf += data
        out: List[Message] = []
        pos = 0
        end = len(buf)
        while end - pos >= HEADER_SIZE:
            length, sec, usec, sender, type_id, seq = decode_header(buf, pos)
            size = HEADER_SIZE + padded(length - HEADER_SIZE)
            if end - pos < size:
                break
            start = pos + HEADER_SIZE
            out.append(Message(type_id, sender, bytes(buf[start:start + length - HEADER_SIZE]),
                               sec, usec, seq))
            pos += size
        if pos:
            del buf[:pos]
        return out

    @property
    def pending(self) -> int:
        """Bytes held that do not form a whole message yet."""
        return len(self._buf)

    def clear(self) -> None:
        self._buf.clear()


def split_datagram(data: bytes) -> Iterator[Message]:
    """Messages packed back-to-back in one UDP datagram (whole messages only)."""
    pos = 0
    while pos < len(data):
        if len(data) - pos < HEADER_SIZE:
            raise VrpnFramingError("VRPN datagram ends inside a header (%d stray bytes)" % (len(data) - pos))
        length, sec, usec, sender, type_id, seq = decode_header(data, pos)
        size = wire_size(length)
        if pos + size > len(data):
            raise VrpnFramingError("VRPN datagram ends inside a message of %d bytes" % size)
        yield Message(type_id, sender, bytes(data[pos + HEADER_SIZE:pos + length]), sec, usec, seq)
        pos += size


# -- system messages --------------------------------------------------------------------------
def encode_name_payload(name: str) -> bytes:
    """Payload of a sender/type description: int32 length including the NUL, the name, a NUL."""
    raw = name.encode("utf-8")
    if not raw or len(raw) > MAX_NAME_LENGTH or b"\0" in raw:
        raise ValueError("VRPN name must be 1..%d bytes without NUL, got %r" % (MAX_NAME_LENGTH, name))
    return _INT32.pack(len(raw) + 1) + raw + b"\0"


def decode_name_payload(payload: bytes) -> str:
    """The name carried by a sender/type description; raises VrpnProtocolError when malformed."""
    if len(payload) < 5:
        raise VrpnProtocolError("VRPN description payload too short (%d bytes)" % len(payload))
    (n,) = _INT32.unpack_from(payload, 0)
    if n < 1 or n > MAX_NAME_LENGTH + 1 or 4 + n > len(payload):
        raise VrpnProtocolError("VRPN description name length %d does not fit a payload of %d bytes"
                                % (n, len(payload)))
    raw = payload[4:4 + n].split(b"\0", 1)[0]
    if not raw:
        raise VrpnProtocolError("VRPN description carries an empty name")
    return raw.decode("utf-8", "replace")


def encode_sender_description(sender_id: int, name: str, sec: int = 0, usec: int = 0,
                              sequence: int = 0) -> bytes:
    return encode_message(SENDER_DESCRIPTION, sender_id, encode_name_payload(name), sec, usec, sequence)


def encode_type_description(type_id: int, name: str, sec: int = 0, usec: int = 0,
                            sequence: int = 0) -> bytes:
    return encode_message(TYPE_DESCRIPTION, type_id, encode_name_payload(name), sec, usec, sequence)


def encode_udp_description(udp_port: int, ip: str, sec: int = 0, usec: int = 0, sequence: int = 0) -> bytes:
    """-3 message: the sender field is the UDP port, the payload the ASCII IP and a NUL."""
    return encode_message(UDP_DESCRIPTION, udp_port, ip.encode("ascii") + b"\0", sec, usec, sequence)


def decode_udp_description(msg: Message) -> Tuple[str, int]:
    """(ip, port) of a -3 message."""
    ip = msg.payload.split(b"\0", 1)[0].decode("ascii", "replace")
    if not ip:
        raise VrpnProtocolError("VRPN UDP description without an address")
    return ip, msg.sender_id


# -- tracker reports ---------------------------------------------------------------------------
Vec3 = Tuple[float, float, float]
Quat = Tuple[float, float, float, float]   # (x, y, z, w)


@dataclass(frozen=True)
class PosQuat:
    """``vrpn_Tracker Pos_Quat``: sensor pose in the tracker's room frame (metres, quaternion xyzw)."""

    sensor: int
    position: Vec3
    orientation: Quat


@dataclass(frozen=True)
class Velocity:
    """``vrpn_Tracker Velocity``: linear velocity (m/s) and the rotation ``vel_quat`` over ``dt`` s."""

    sensor: int
    linear: Vec3
    rotation: Quat
    dt: float


def vec3(values: Sequence[float]) -> Vec3:
    """Three floats from any sequence of three numbers (ValueError for another length)."""
    x, y, z = values
    return float(x), float(y), float(z)


def quat(values: Sequence[float]) -> Quat:
    """Four floats (x, y, z, w) from any sequence of four numbers (ValueError for another length)."""
    x, y, z, w = values
    return float(x), float(y), float(z), float(w)


def encode_pos_quat(report: PosQuat) -> bytes:
    """64-byte payload: sensor, sensor again as padding, pos xyz, quat xyzw (float64)."""
    return _POS_QUAT.pack(report.sensor, report.sensor, *report.position, *report.orientation)


def decode_pos_quat(payload: bytes) -> PosQuat:
    if len(payload) != POS_QUAT_SIZE:
        raise VrpnProtocolError("vrpn_Tracker Pos_Quat payload must be %d bytes, got %d"
                                % (POS_QUAT_SIZE, len(payload)))
    v = _POS_QUAT.unpack(payload)
    return PosQuat(v[0], (v[2], v[3], v[4]), (v[5], v[6], v[7], v[8]))


def encode_velocity(report: Velocity) -> bytes:
    """72-byte payload: sensor, padding, vel xyz, vel_quat xyzw, vel_quat_dt (float64)."""
    return _VELOCITY.pack(report.sensor, report.sensor, *report.linear, *report.rotation, report.dt)


def decode_velocity(payload: bytes) -> Velocity:
    if len(payload) != VELOCITY_SIZE:
        raise VrpnProtocolError("vrpn_Tracker Velocity payload must be %d bytes, got %d"
                                % (VELOCITY_SIZE, len(payload)))
    v = _VELOCITY.unpack(payload)
    return Velocity(v[0], (v[2], v[3], v[4]), (v[5], v[6], v[7], v[8]), v[9])


# -- text messages -----------------------------------------------------------------------------
TEXT_NORMAL, TEXT_WARNING, TEXT_ERROR = 0, 1, 2


def encode_text(text: str, severity: int = TEXT_NORMAL, level: int = 0) -> bytes:
    """Payload of ``vrpn_Base text_message``: uint32 severity, uint32 level, NUL-terminated text."""
    raw = text.encode("utf-8")[:1024]
    return _TEXT_HEAD.pack(severity, level) + raw + b"\0"


def decode_text(payload: bytes) -> Tuple[int, int, str]:
    """(severity, level, text) of a text message."""
    if len(payload) < _TEXT_HEAD.size:
        raise VrpnProtocolError("vrpn_Base text_message payload too short (%d bytes)" % len(payload))
    severity, level = _TEXT_HEAD.unpack_from(payload, 0)
    text = payload[_TEXT_HEAD.size:].split(b"\0", 1)[0].decode("utf-8", "replace")
    return severity, level, text


def split_time(t: float) -> Tuple[int, int]:
    """(seconds, microseconds) of a Unix time, as the header carries it."""
    sec = int(t // 1)
    usec = int(round((t - sec) * 1e6))
    if usec >= 1000000:
        sec, usec = sec + 1, usec - 1000000
    return sec, usec
