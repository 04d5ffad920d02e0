"""Ports 15 (link source) and 13 (platform): which protocol the firmware speaks.

Firmware since protocol version 1 answers a 15:1 request with the magic
"Bitcraze Crazyflie"; only then is 13:1 asked for the version. Without the
magic the version is -1 and everything uses the oldest (V1) formats.
"""
from __future__ import annotations

import struct

from crazyflie_driver.crtp.packet import PORT_LINK, PORT_PLATFORM, CRTPPacket

SOURCE_MAGIC = b"Bitcraze Crazyflie"
CH_LINK_SOURCE = 1
CH_PLATFORM_VERSION = 1
CMD_PROTOCOL_VERSION = 0
CMD_FIRMWARE_VERSION = 1
CMD_DEVICE_TYPE = 2

#: First protocol version with V2 TOCs (16-bit ids) and V2 parameter formats.
TOC_V2_FROM = 4


def toc_version(protocol_version: int) -> int:
    """TOC / parameter format generation for a protocol version: 1 below 4, 2 from 4."""
    return 2 if protocol_version >= TOC_V2_FROM else 1


class Platform:
    """Version queries; one request in flight."""

    def __init__(self, link, timeout: float = 1.0) -> None:
        self.link = link
        self.timeout = timeout

    def detect_protocol_version(self) -> int:
        """Ask 15:1 for the magic, then 13:1 for the protocol version; -1 without magic."""
        reply = self.link.request(
            CRTPPacket(PORT_LINK, CH_LINK_SOURCE, b"\x00"),
            match=lambda p: p.port == PORT_LINK and p.channel == CH_LINK_SOURCE,
            timeout=self.timeout, what="link source query (15:1)")
        if reply.data[:len(SOURCE_MAGIC)] != SOURCE_MAGIC:
            return -1
        reply = self._version_request(CMD_PROTOCOL_VERSION, "protocol version query (13:1)")
        if len(reply.data) >= 5:
            return struct.unpack_from("<i", reply.data, 1)[0]
        if len(reply.data) >= 2:
            return reply.data[1]
        return -1

    def firmware_version(self) -> str:
        """The firmware's release tag, e.g. "2026.04" (protocol version 2 and later)."""
        reply = self._version_request(CMD_FIRMWARE_VERSION, "firmware version query (13:1)")
        return reply.data[1:].split(b"\x00")[0].decode("ascii", "replace")

    def device_type(self) -> str:
        """The device type name, e.g. "Crazyflie 2.1" (firmware 2019.09 and later)."""
        reply = self._version_request(CMD_DEVICE_TYPE, "device type query (13:1)")
        return reply.data[1:].split(b"\x00")[0].decode("ascii", "replace")

    def _version_request(self, cmd: int, what: str) -> CRTPPacket:
        return self.link.request(
            CRTPPacket(PORT_PLATFORM, CH_PLATFORM_VERSION, bytes([cmd])),
            match=lambda p: (p.port == PORT_PLATFORM and p.channel == CH_PLATFORM_VERSION
                             and p.data[:1] == bytes([cmd])),
            timeout=self.timeout, what=what)
