"""Binary framing between ``RemoteMedium`` clients and the world server.

A frame is ``[code u8, length u16 LE, body]``. Requests: OP_TRANSMIT (a radio packet; the hot path,
a fixed 10-byte head plus the packet) and OP_CONTROL (JSON ``{"op": ..., "args": {...}}``). Replies
carry STATUS_OK or STATUS_ERROR as code. Kept tiny so one loopback round trip stays cheap. A radio
reply also carries the world's speed (world seconds per wall second) at the time it was served, so a
fake dongle in another process can time its transfers in world time (``dongle_timing.WorldPacedClock``).
"""
from __future__ import annotations

import socket
import struct
from typing import Callable, Tuple, TypeVar

Reply = TypeVar("Reply")

OP_TRANSMIT = 1
OP_CONTROL = 2
STATUS_OK = 0
STATUS_ERROR = 1

_HEAD = struct.Struct("<BH")
_TX = struct.Struct("<BBBBB5s")       # dongle, channel, datarate, ack_enabled, arc, address
_REPLY = struct.Struct("<BBff")       # flags (acked, power detector, unplugged), retries, latency_s, world speed
MAX_BODY = 0xFFFF


def encode_transmit(dongle: int, channel: int, datarate: int, address: bytes, data: bytes,
                    ack_enabled: bool, arc: int) -> bytes:
    return _TX.pack(dongle & 0xFF, channel & 0xFF, datarate & 0xFF, 1 if ack_enabled else 0, arc & 0xFF,
                    bytes(address)[:5]) + bytes(data)


def decode_transmit(body: bytes):
    if len(body) < _TX.size:
        raise ValueError("transmit request of %d bytes is shorter than its %d-byte head" % (len(body), _TX.size))
    dongle, channel, datarate, ack, arc, address = _TX.unpack_from(body)
    return dongle, channel, datarate, address, body[_TX.size:], bool(ack), arc


def encode_air_reply(reply, speed: float = 1.0) -> bytes:
    """``reply`` (an ``AirReply``) and the world's ``speed`` [world s / wall s] when it was served."""
    flags = (1 if reply.acked else 0) | (2 if reply.power_detector else 0) | (4 if reply.unplugged else 0)
    return _REPLY.pack(flags, reply.retries & 0xFF, reply.latency_s, speed) + bytes(reply.payload)


def decode_air_reply(body: bytes, cls: Callable[..., Reply]) -> Tuple[Reply, float]:
    """The ``cls`` (``AirReply``) of a reply body and the world's speed it carried."""
    flags, retries, latency, speed = _REPLY.unpack_from(body)
    return (cls(acked=bool(flags & 1), payload=bytes(body[_REPLY.size:]), retries=retries,
                power_detector=bool(flags & 2), unplugged=bool(flags & 4), latency_s=float(latency)), float(speed))


class Connection:
    """One framed stream socket; ``receive`` reads whole frames through a small buffer."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self._buf = bytearray()

    def send(self, code: int, body: bytes) -> None:
        if len(body) > MAX_BODY:
            raise ValueError("frame body of %d bytes exceeds %d" % (len(body), MAX_BODY))
        self.sock.sendall(_HEAD.pack(code, len(body)) + body)

    def receive(self) -> Tuple[int, bytes]:
        """Next frame; raises EOFError when the peer closed the connection."""
        buf = self._buf
        while True:
            if len(buf) >= _HEAD.size:
                code, length = _HEAD.unpack_from(buf)
                end = _HEAD.size + length
                if len(buf) >= end:
                    body = bytes(buf[_HEAD.size:end])
                    del buf[:end]
                    return code, body
            chunk = self.sock.recv(65536)
            if not chunk:
                raise EOFError("connection closed by peer")
            buf += chunk

    def close(self) -> None:
        try:
            self.sock.close()
        except OSError:
            pass
