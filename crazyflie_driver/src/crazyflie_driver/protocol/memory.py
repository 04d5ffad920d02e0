"""Port 4 (memory subsystem): enumerate the Crazyflie's memories, read and write them.

Channel 0 asks how many memories there are and what each one is (type, size); channel 1 reads
and channel 2 writes at most ``CHUNK`` bytes per packet, each answered with a status byte.
Writes are idempotent (same bytes at the same address), so a lost reply is simply asked again.
"""
from __future__ import annotations

import struct
import zlib
from typing import Callable, Dict, List, NamedTuple, Optional

from crazyflie_driver.crtp import config_block
from crazyflie_driver.crtp.packet import PORT_MEM, CRTPPacket
from crazyflie_driver.errors import CommandRejected, NotSupported, ProtocolError

CH_INFO = 0
CH_READ = 1
CH_WRITE = 2
CMD_NUMBER = 1
CMD_DETAILS = 2

#: Memory types (the firmware's MemoryType_t): the EEPROM, a deck's one-wire memory, the
#: high-level commander's trajectory memory.
TYPE_EEPROM = config_block.MEMORY_TYPE_EEPROM
TYPE_ONE_WIRE = 0x01
TYPE_TRAJECTORY = 0x12
#: Names of the memory types a Crazyflie may list (for listings; unknown types print as numbers).
TYPE_NAMES: Dict[int, str] = {
    0x00: "EEPROM", 0x01: "1-wire", 0x10: "LED ring", 0x11: "Loco", 0x12: "trajectory", 0x13: "Loco 2",
    0x14: "Lighthouse", 0x15: "memory tester", 0x16: "uSD", 0x17: "LED timing", 0x18: "app",
    0x19: "deck memory", 0x1A: "Multi-ranger", 0x1B: "PAA3905", 0x20: "deck ctrl DFU", 0x21: "deck ctrl",
}
#: Bytes of a deck's one-wire memory read first: the 8-byte header, the elements' version and length.
ONE_WIRE_HEAD = 10
ONE_WIRE_MAGIC = 0xEB
#: Bytes of data per read/write packet (30-byte payload minus id and u32 address, rounded to 4).
CHUNK = 24
_DETAILS = struct.Struct("<BBBI8s")
_ADDRESS = struct.Struct("<BI")

Request = Callable[..., CRTPPacket]


class MemoryInfo(NamedTuple):
    """One memory as the Crazyflie describes it."""

    id: int
    type: int
    size: int          # bytes
    serial: bytes


def number_packet() -> CRTPPacket:
    return CRTPPacket(PORT_MEM, CH_INFO, bytes([CMD_NUMBER]))


def details_packet(mem_id: int) -> CRTPPacket:
    return CRTPPacket(PORT_MEM, CH_INFO, bytes([CMD_DETAILS, mem_id]))


def write_packet(mem_id: int, address: int, data: bytes) -> CRTPPacket:
    if not 0 < len(data) <= CHUNK:
        raise ValueError("a memory write carries 1..%d bytes, got %d" % (CHUNK, len(data)))
    return CRTPPacket(PORT_MEM, CH_WRITE, _ADDRESS.pack(mem_id, address) + bytes(data))


def read_packet(mem_id: int, address: int, length: int) -> CRTPPacket:
    if not 0 < length <= CHUNK:
        raise ValueError("a memory read asks for 1..%d bytes, got %d" % (CHUNK, length))
    return CRTPPacket(PORT_MEM, CH_READ, _ADDRESS.pack(mem_id, address) + bytes([length]))


class DeckInfo(NamedTuple):
    """A deck as its one-wire memory names it."""

    vid: int
    pid: int
    name: str
    revision: str


def type_name(kind: int) -> str:
    return TYPE_NAMES.get(kind, "type 0x%02X" % kind)


def parse_one_wire(data: bytes) -> DeckInfo:
    """The deck described by the first bytes of a one-wire memory: header ``[0xEB, used pins u32, vid,
    pid, crc]`` then ``[version, length, (id, len, text)…, crc]`` (element 1 board name, 2 revision);
    each crc is the low byte of the CRC-32 of its part. ProtocolError when a part does not check."""
    data = bytes(data)
    if len(data) < 10 or data[0] != ONE_WIRE_MAGIC or zlib.crc32(data[:7]) & 0xFF != data[7]:
        raise ProtocolError("one-wire memory has no valid deck header: %s" % data[:8].hex(" "))
    vid, pid = data[5], data[6]
    end = 10 + data[9]
    if len(data) < end + 1 or zlib.crc32(data[8:end]) & 0xFF != data[end]:
        raise ProtocolError("one-wire memory of deck 0x%02X:0x%02X has broken elements" % (vid, pid))
    texts: Dict[int, str] = {}
    at = 10
    while at + 2 <= end:
        ident, size = data[at], data[at + 1]
        texts[ident] = data[at + 2:at + 2 + size].decode("latin-1")
        at += 2 + size
    return DeckInfo(vid, pid, texts.get(1, ""), texts.get(2, ""))


def parse_details(data: bytes) -> MemoryInfo:
    """A details reply ``[2, id, type, size u32, serial 8 B]``."""
    if len(data) < _DETAILS.size or data[0] != CMD_DETAILS:
        raise ProtocolError("memory details reply has %d bytes (%s), expected %d" % (len(data), data.hex(' '),
                                                                                    _DETAILS.size))
    _, mem_id, kind, size, serial = _DETAILS.unpack_from(data)
    return MemoryInfo(mem_id, kind, size, serial)


def chunks(address: int, data: bytes):
    """(address, bytes) pieces of at most CHUNK bytes covering ``data`` written at ``address``."""
    for i in range(0, len(data), CHUNK):
        yield address + i, bytes(data[i:i + CHUNK])


class MemoryClient:
    """Memory access over ``request(packet, match, timeout=, what=)`` (the link's request)."""

    def __init__(self, request: Request, timeout: float = 1.0, label: str = "") -> None:
        self._request = request
        self.timeout = timeout
        self.label = label
        self._memories: Optional[List[MemoryInfo]] = None

    def memories(self, refresh: bool = False) -> List[MemoryInfo]:
        """Every memory of the Crazyflie (asked once, then cached)."""
        if self._memories is None or refresh:
            reply = self._request(number_packet(), match=lambda p: _is_info(p, CMD_NUMBER),
                                  timeout=self.timeout, what="memory count (4:0)")
            if len(reply.data) < 2:
                raise ProtocolError("%s: memory count reply too short: %s" % (self.label, reply.data.hex(' ')))
            found = []
            for mem_id in range(reply.data[1]):
                details = self._request(details_packet(mem_id),
                                        match=lambda p, i=mem_id: (_is_info(p, CMD_DETAILS)
                                                                   and p.data[1:2] == bytes([i])),
                                        timeout=self.timeout, what="details of memory %d (4:0)" % mem_id)
                found.append(parse_details(details.data))
            self._memories = found
        return list(self._memories)

    def find(self, kind: int) -> Optional[MemoryInfo]:
        """The first memory of type ``kind``, or None."""
        for info in self.memories():
            if info.type == kind:
                return info
        return None

    def _eeprom(self) -> MemoryInfo:
        info = self.find(TYPE_EEPROM)
        if info is None:
            raise NotSupported("%s lists no EEPROM memory (type 0x00): this Crazyflie keeps no "
                               "configuration block" % self.label)
        return info

    def read_config(self) -> config_block.ConfigBlock:
        """The EEPROM's configuration block; ConfigBlockError when it is not valid (the firmware then
        runs on the defaults)."""
        info = self._eeprom()
        head = self.read(info.id, 0, config_block.SIZE_V0)
        if len(head) > 4 and head[4] >= 1:
            head += self.read(info.id, config_block.SIZE_V0, config_block.SIZE - config_block.SIZE_V0)
        return config_block.decode(head)

    def write_config(self, block: config_block.ConfigBlock) -> None:
        """Write ``block`` as a version 1 block (the firmware takes it at its next boot); read back
        and compared, so a write the EEPROM lost is reported, not assumed."""
        info = self._eeprom()
        image = config_block.encode(block)
        self.write(info.id, 0, image)
        back = self.read(info.id, 0, len(image))
        if back != image:
            raise CommandRejected("%s: the EEPROM reads back %s after writing %s: write the configuration again"
                                  % (self.label, back.hex(" "), image.hex(" ")))

    def decks(self) -> List[DeckInfo]:
        """The decks plugged in, one per one-wire memory."""
        out = []
        for info in self.memories():
            if info.type == TYPE_ONE_WIRE:
                head = self.read(info.id, 0, ONE_WIRE_HEAD)
                rest = min(head[9] + 1, info.size - ONE_WIRE_HEAD) if head[0] == ONE_WIRE_MAGIC else 0
                out.append(parse_one_wire(head + (self.read(info.id, ONE_WIRE_HEAD, rest) if rest > 0 else b"")))
        return out

    def write(self, mem_id: int, address: int, data: bytes) -> None:
        """Write ``data`` at ``address``, chunk by chunk; CommandRejected when a chunk is refused."""
        for addr, chunk in chunks(address, data):
            self._answered(write_packet(mem_id, addr, chunk), CH_WRITE, mem_id, addr, "write",
                           "%d bytes" % len(chunk))

    def read(self, mem_id: int, address: int, length: int) -> bytes:
        """``length`` bytes from ``address``; CommandRejected when the Crazyflie reports an error."""
        out = b""
        while len(out) < length:
            addr = address + len(out)
            n = min(CHUNK, length - len(out))
            reply = self._answered(read_packet(mem_id, addr, n), CH_READ, mem_id, addr, "read",
                                   "a read of %d bytes" % n)
            out += reply.data[6:6 + n]
        return out

    def _answered(self, packet: CRTPPacket, channel: int, mem_id: int, addr: int, action: str,
                  refused: str) -> CRTPPacket:
        """The Crazyflie's answer to a read or write of memory ``mem_id`` at ``addr`` (the one that
        names both); CommandRejected, naming ``refused``, when its status byte is not 0."""
        head = _ADDRESS.pack(mem_id, addr)
        reply = self._request(packet, match=lambda p: p.port == PORT_MEM and p.channel == channel
                              and p.data[:5] == head and len(p.data) >= 6,
                              timeout=self.timeout, what="memory %d %s at %d (4:%d)" % (mem_id, action, addr, channel))
        if reply.data[5] != 0:
            raise CommandRejected("%s: memory %d refused %s at address %d (status %d)"
                                  % (self.label, mem_id, refused, addr, reply.data[5]))
        return reply


def _is_info(packet: CRTPPacket, cmd: int) -> bool:
    return packet.port == PORT_MEM and packet.channel == CH_INFO and packet.data[:1] == bytes([cmd])
