"""Port 4 of the simulated firmware: the memory table of a Crazyflie 2.1 and its reads and writes.

Memory ids are handed out as the current firmware does: one-wire memories (one per plugged deck)
first, then the registered memories in their order (the EEPROM, then the trajectory memory when the
firmware has the high-level commander). Ch 0 ``[1]`` -> ``[1, n]``, ``[2, id]`` -> ``[2, id, type,
size u32, serial 8 B]`` (unknown id: ``[2, id]``, which ends cflib's enumeration); ch 1 read ``[id,
addr u32, len]`` -> ``[id, addr u32, 0, data]`` or ``[id, addr u32, EIO]``; ch 2 write ``[id, addr
u32, data]`` -> ``[id, addr u32, status]``. Facts in docs/protocol.md ("Memories").
"""
from __future__ import annotations

import struct
import zlib
from typing import Callable, List, NamedTuple, Optional, Sequence

from crazyflie_driver.crtp import config_block as cb

EIO = 5
MEMORY_TYPE_ONE_WIRE = 0x01
ONE_WIRE_SIZE = 112                     # bytes of a deck's one-wire memory (DS28E05)
ONE_WIRE_FAMILY = 0x2D                  # family code of the DS28E05, first byte of its 64-bit ROM id
NO_SERIAL = bytes(8)

Handler = Callable[[int, int, bytes], None]
Send = Callable[[int, bytes], bool]


class Deck(NamedTuple):
    """A Bitcraze deck as its one-wire memory names it (vendor 0xBC)."""

    name: str
    pid: int
    revision: str = "A"
    vid: int = 0xBC


#: Decks a world can plug in, by the board name in their one-wire memory.
DECKS = {d.name: d for d in (
    Deck("bcLedRing", 0x01), Deck("bcDWM1000", 0x06), Deck("bcMultiranger", 0x0C),
    Deck("bcZRanger2", 0x0E), Deck("bcFlow2", 0x0F), Deck("bcLighthouse4", 0x10),
)}


def maxim_crc8(data: bytes) -> int:
    """The 1-wire CRC (x^8 + x^5 + x^4 + 1, reflected) that ends a 1-wire ROM id."""
    crc = 0
    for byte in bytearray(data):
        for _ in range(8):
            mix = (crc ^ byte) & 0x01
            crc >>= 1
            if mix:
                crc ^= 0x8C
            byte >>= 1
    return crc


def one_wire_image(deck: Deck) -> bytes:
    """The 112 bytes of a deck's one-wire memory: header ``[0xEB, used pins u32, vid, pid, crc]``,
    then ``[version 0, length, elements…, crc]`` with elements 1 (board name) and 2 (revision); each
    crc is the low byte of the CRC-32 of the bytes before it in its part; 0xFF (erased) after that."""
    header = struct.pack("<BIBB", 0xEB, 0, deck.vid, deck.pid)
    header += bytes([zlib.crc32(header) & 0xFF])
    elements = b""
    for ident, text in ((1, deck.name), (2, deck.revision)):
        raw = text.encode("latin-1")
        elements += bytes([ident, len(raw)]) + raw
    body = bytes([0x00, len(elements)]) + elements
    body += bytes([zlib.crc32(body) & 0xFF])
    return (header + body).ljust(ONE_WIRE_SIZE, b"\xff")


class Memory:
    """One memory of the table: its type, size, serial and bytes (bounds-checked reads and writes)."""

    def __init__(self, kind: int, data: bytearray, serial: bytes = NO_SERIAL, writable: bool = True) -> None:
        self.kind = kind
        self.data = data
        self.serial = bytes(serial)
        self.writable = writable

    @property
    def size(self) -> int:
        return len(self.data)

    def read(self, address: int, length: int) -> Optional[bytes]:
        if address + length > self.size:
            return None
        return bytes(self.data[address:address + length])

    def write(self, address: int, payload: bytes) -> bool:
        if not self.writable or address + len(payload) > self.size:
            return False
        self.data[address:address + len(payload)] = payload
        return True


def eeprom(block: cb.ConfigBlock) -> Memory:
    """A factory-fresh EEPROM: the configuration block, then erased bytes."""
    return Memory(cb.MEMORY_TYPE_EEPROM, bytearray(cb.encode(block).ljust(cb.EEPROM_SIZE, b"\xff")))


def deck_memory(deck: Deck, slot: int) -> Memory:
    """The one-wire memory of ``deck`` in ``slot`` (its 64-bit ROM id is the serial)."""
    rom = bytes([ONE_WIRE_FAMILY, slot + 1, deck.pid, 0, 0, 0, 0xBC])
    return Memory(MEMORY_TYPE_ONE_WIRE, bytearray(one_wire_image(deck)), rom + bytes([maxim_crc8(rom)]))


def memory_port(send: Send, memories: Sequence[Memory]) -> Handler:
    """Port 4 over ``memories`` (index = memory id); ``memories`` may change between packets."""
    table: List[Memory] = memories  # type: ignore[assignment]

    def handle(header: int, channel: int, data: bytes) -> None:
        if not data:
            return
        if channel == 0:
            if data[0] == 1:
                send(header, bytes([1, len(table)]))
            elif data[0] == 2 and len(data) >= 2:
                if data[1] < len(table):
                    m = table[data[1]]
                    send(header, bytes([2, data[1], m.kind]) + struct.pack("<I", m.size) + m.serial)
                else:
                    send(header, bytes(data[:2]))          # short reply: no such memory
        elif channel == 1 and len(data) >= 6:
            ident, address, length = data[0], struct.unpack_from("<I", data, 1)[0], data[5]
            got = table[ident].read(address, length) if ident < len(table) else None
            send(header, bytes(data[:5]) + (bytes([0]) + got if got is not None else bytes([EIO])))
        elif channel == 2 and len(data) >= 5:
            ident, address = data[0], struct.unpack_from("<I", data, 1)[0]
            ok = ident < len(table) and table[ident].write(address, bytes(data[5:]))
            send(header, bytes(data[:5]) + bytes([0 if ok else EIO]))
    return handle
