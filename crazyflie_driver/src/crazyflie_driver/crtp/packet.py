"""CRTP packets: the header byte and the port numbers, shared by host and simulator.

Header byte: bits 7..4 port, bits 3..2 link bits (safelink sequence numbers,
ignored by everyone above the link layer), bits 1..0 channel.
"""
from __future__ import annotations

from dataclasses import dataclass

MAX_PAYLOAD = 30

PORT_CONSOLE = 0
PORT_PARAM = 2
PORT_COMMANDER = 3
PORT_MEM = 4
PORT_LOG = 5
PORT_LOCALIZATION = 6
PORT_GENERIC_SETPOINT = 7
PORT_HIGH_LEVEL = 8
PORT_SUPERVISOR = 9
PORT_PLATFORM = 13
PORT_LINK = 15

NULL_PACKET = b"\xff"


def make_header(port: int, channel: int) -> int:
    """Header byte for (port, channel) with both link bits set, as cflib sends it."""
    return ((port & 0x0F) << 4) | 0x0C | (channel & 0x03)


def is_null_header(header: int) -> bool:
    """Port 15 channel 3, whatever the link bits: a null / empty-ack packet."""
    return (header & 0xF3) == 0xF3


# ports whose packets steer the motors: setpoints, high-level commands, stops and emergency stops
MOTOR_COMMAND_PORTS = frozenset((PORT_COMMANDER, PORT_GENERIC_SETPOINT, PORT_HIGH_LEVEL, PORT_SUPERVISOR))
LOCALIZATION_GENERIC_CHANNEL = 1       # carries the emergency stop on firmware without the supervisor port


# every header byte of such a packet, whatever its link bits (one set lookup per packet on the air)
_MOTOR_COMMAND_HEADERS = frozenset(h for h in range(256) if h >> 4 in MOTOR_COMMAND_PORTS or (
    h >> 4 == PORT_LOCALIZATION and h & 0x03 == LOCALIZATION_GENERIC_CHANNEL))


def is_motor_command(raw: bytes) -> bool:
    """Whether a raw packet (header byte first) steers the motors (see MOTOR_COMMAND_PORTS); such
    packets may go before polls on a shared dongle."""
    return raw[0] in _MOTOR_COMMAND_HEADERS if raw else False


@dataclass(frozen=True)
class CRTPPacket:
    """One CRTP packet; ``data`` is the payload after the header byte."""

    port: int
    channel: int
    data: bytes = b""

    @property
    def header(self) -> int:
        return make_header(self.port, self.channel)

    def to_bytes(self) -> bytes:
        return bytes([self.header]) + bytes(self.data)

    @classmethod
    def from_bytes(cls, raw: bytes) -> CRTPPacket:
        if not raw:
            raise ValueError("empty CRTP packet")
        h = raw[0]
        return cls((h >> 4) & 0x0F, h & 0x03, bytes(raw[1:]))

    def __repr__(self) -> str:
        return f"CRTPPacket({self.port}:{self.channel} {self.data.hex(' ')})"
