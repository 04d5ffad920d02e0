"""Port 2 of the simulated firmware: the parameter TOC, reads, writes and the misc channel.

Reply formats follow docs/protocol.md, "Port 2 (parameters)", byte for byte: current firmware speaks TOC V2 (16-bit
ids) with a status byte in reads; the 2016.02 firmware speaks TOC V1 (8-bit ids), reads ``[id, value]`` and
reports unknown ids as ``[0xFF, id, ENOENT]``. A write to a read-only parameter gets no reply.
"""
from __future__ import annotations

import logging
import struct
from typing import Callable, Dict, List, Mapping, Optional, Sequence

from crazyflie_driver.sim.crtp import tables as T

ENOENT = 2
EACCES = 13
EINVAL = 22

CH_TOC, CH_READ, CH_WRITE, CH_MISC = 0, 1, 2, 3
TOC_ITEM_V1, TOC_INFO_V1, TOC_ITEM_V2, TOC_INFO_V2 = 0, 1, 2, 3
MISC_SET_BY_NAME = 0
MISC_GET_EXTENDED_TYPE = 2
MISC_PERSISTENT_STORE = 3
MISC_PERSISTENT_GET_STATE = 4
MISC_PERSISTENT_CLEAR = 5
MISC_GET_DEFAULT = 6
MISC_GET_EXTENDED_TYPE_V2 = 7
MISC_GET_DEFAULT_V2 = 8
#: The protocol version from which the firmware answers MISC_GET_EXTENDED_TYPE_V2 and MISC_GET_DEFAULT_V2.
MISC_V2_FROM_PROTOCOL = 11

Send = Callable[[int, bytes], bool]   # as ports.Send: whether the packet went out
_log = logging.getLogger(__name__)


def _persistent(e: Optional[T.ParamVar]) -> bool:
    """Whether ``e`` is a parameter that can be stored (None: no such id)."""
    return e is not None and e.persistent


MiscAnswer = Callable[[int, Optional[T.ParamVar]], bytes]


class ParamService:
    """Parameter values of one Crazyflie and the protocol that reads and writes them."""

    def __init__(self, generation: str, protocol_version: int, table: Sequence[T.ParamVar],
                 overrides: Mapping[str, float], write_hook: Callable[[str, float], None],
                 send: Send) -> None:
        self.generation = generation
        self.v2 = generation == T.GEN_CURRENT
        self.protocol_version = protocol_version
        self.entries: List[T.ParamVar] = T.select(table, generation)
        T.check_names(self.entries)
        self.crc = T.toc_crc(self.entries, lambda e: e.type_byte(generation))
        if not self.v2:
            self.crc ^= 0x20160200  # the 2016 firmware hashed raw structs: an unrelated value
        self._ids: Dict[str, int] = {e.full_name: i for i, e in enumerate(self.entries)}
        self._overrides = dict(overrides)
        self._write_hook = write_hook
        self._send = send
        self.values: List[T.Number] = []
        self.stored: Dict[int, T.Number] = {}   # persistent storage (ids with a stored value)
        self._misc_by_id = self._misc_table()
        self.reset_values()

    # --- values ---------------------------------------------------------------------------
    def default_of(self, ident: int) -> T.Number:
        e = self.entries[ident]
        value = self._overrides.get(e.full_name, e.default)
        return T.clamp(value, T.CTYPES[e.ctype])

    def reset_values(self) -> None:
        """Boot values: table defaults, overridden by the vehicle's, then stored persistent values."""
        self.values = [self.default_of(i) for i in range(len(self.entries))]
        for ident, value in self.stored.items():
            self.values[ident] = value

    def ident(self, full_name: str) -> Optional[int]:
        return self._ids.get(full_name)

    def value(self, full_name: str) -> T.Number:
        ident = self._ids.get(full_name)
        if ident is None:
            raise KeyError(full_name)
        return self.values[ident]

    def _set(self, ident: int, raw: bytes) -> None:
        e = self.entries[ident]
        value = T.unpack(raw, T.CTYPES[e.ctype])
        self.values[ident] = value
        try:
            self._write_hook(e.full_name, float(value))
        except Exception:  # a physics hook must never take the radio down
            _log.exception("write_param(%s) failed in the vehicle", e.full_name)

    # --- protocol ---------------------------------------------------------------------------
    def handle(self, header: int, channel: int, data: bytes) -> None:
        if channel == CH_TOC:
            self._toc(header, data)
        elif channel == CH_READ:
            self._read(header, data)
        elif channel == CH_WRITE:
            self._write(header, data)
        else:
            self._misc(header, data)

    def _id_width(self) -> int:
        return 2 if self.v2 else 1

    def _parse_id(self, data: bytes) -> Optional[int]:
        if self.v2:
            return struct.unpack_from("<H", data)[0] if len(data) >= 2 else None
        return data[0] if data else None

    def _toc(self, header: int, data: bytes) -> None:
        if not data:
            return
        cmd = data[0]
        n = len(self.entries)
        if self.v2 and cmd == TOC_INFO_V2:
            self._send(header, struct.pack("<BHI", TOC_INFO_V2, n, self.crc))
        elif self.v2 and cmd == TOC_ITEM_V2:
            if len(data) < 3:
                return
            ident = struct.unpack_from("<H", data, 1)[0]
            if ident >= n:
                self._send(header, bytes([TOC_ITEM_V2]))
                return
            e = self.entries[ident]
            self._send(header, struct.pack("<BHB", TOC_ITEM_V2, ident, e.type_byte(self.generation))
                       + T.toc_item_name(e))
        elif not self.v2 and cmd == TOC_INFO_V1:
            self._send(header, struct.pack("<BBI", TOC_INFO_V1, min(n, 255), self.crc))
        elif not self.v2 and cmd == TOC_ITEM_V1:
            if len(data) < 2:
                return
            ident = data[1]
            if ident >= n:
                self._send(header, bytes([TOC_ITEM_V1]))
                return
            e = self.entries[ident]
            self._send(header, bytes([TOC_ITEM_V1, ident, e.type_byte(self.generation)])
                       + T.toc_item_name(e))
        # current firmware (2026.04+) no longer answers the V1 commands; FW16 knows no V2

    def _unknown(self, header: int, ident: int) -> None:
        if self.v2:
            self._send(header, struct.pack("<HB", ident, ENOENT))
        else:
            self._send(header, bytes([0xFF, ident, ENOENT]))

    def _known_id(self, header: int, data: bytes) -> Optional[int]:
        """The id a read or write names; None (after answering ENOENT for an unknown id) when there is none."""
        ident = self._parse_id(data)
        if ident is not None and ident >= len(self.entries):
            self._unknown(header, ident)
            return None
        return ident

    def _read(self, header: int, data: bytes) -> None:
        ident = self._known_id(header, data)
        if ident is None:
            return
        e = self.entries[ident]
        value = T.pack(self.values[ident], T.CTYPES[e.ctype])
        if self.v2:
            self._send(header, struct.pack("<HB", ident, 0) + value)
        else:
            self._send(header, bytes([ident]) + value)

    def _write(self, header: int, data: bytes) -> None:
        ident = self._known_id(header, data)
        if ident is None:
            return
        e = self.entries[ident]
        if e.readonly:
            return  # the firmware stays silent
        raw = data[self._id_width():]
        if len(raw) < T.CTYPES[e.ctype].size:
            return  # short value: dropped rather than writing stack garbage as the firmware would
        self._set(ident, raw)
        self._send(header, bytes(data[:self._id_width() + T.CTYPES[e.ctype].size]))

    def _misc(self, header: int, data: bytes) -> None:
        if not data:
            return
        cmd = data[0]
        if cmd == MISC_SET_BY_NAME:
            self._set_by_name(header, data)
            return
        if not self.v2 or len(data) < 3:
            return  # the 2016 firmware knew only SET_BY_NAME
        answer = self._misc_by_id.get(cmd)
        if answer is None:
            return
        ident = struct.unpack_from("<H", data, 1)[0]
        e = self.entries[ident] if ident < len(self.entries) else None
        self._send(header, data[:3] + answer(ident, e))

    def _misc_table(self) -> Dict[int, MiscAnswer]:
        """The misc commands that name a parameter by id, each answering ``[cmd, id u16]`` + its bytes;
        the V2 forms only from MISC_V2_FROM_PROTOCOL (silence before)."""
        answers: Dict[int, MiscAnswer] = {
            MISC_GET_EXTENDED_TYPE: self._extended_type, MISC_GET_DEFAULT: self._default,
            MISC_PERSISTENT_STORE: self._persistent_store, MISC_PERSISTENT_CLEAR: self._persistent_clear,
            MISC_PERSISTENT_GET_STATE: self._persistent_state}
        if self.protocol_version >= MISC_V2_FROM_PROTOCOL:
            answers.update({MISC_GET_EXTENDED_TYPE_V2: self._extended_type_v2, MISC_GET_DEFAULT_V2: self._default_v2})
        return answers

    def _extended_type(self, ident: int, e: Optional[T.ParamVar]) -> bytes:
        return bytes([T.EXTENDED_PERSISTENT]) if _persistent(e) else bytes([ENOENT])

    def _extended_type_v2(self, ident: int, e: Optional[T.ParamVar]) -> bytes:
        """As GET_EXTENDED_TYPE with a status byte before the type."""
        return bytes([0, T.EXTENDED_PERSISTENT]) if _persistent(e) else bytes([ENOENT])

    def _default(self, ident: int, e: Optional[T.ParamVar]) -> bytes:
        if e is None or e.readonly:
            return bytes([ENOENT])
        return T.pack(self.default_of(ident), T.CTYPES[e.ctype])

    def _default_v2(self, ident: int, e: Optional[T.ParamVar]) -> bytes:
        """As GET_DEFAULT with a status byte before the value."""
        if e is None or e.readonly:
            return bytes([ENOENT])
        return b"\x00" + T.pack(self.default_of(ident), T.CTYPES[e.ctype])

    def _persistent_store(self, ident: int, e: Optional[T.ParamVar]) -> bytes:
        if not _persistent(e):
            return bytes([ENOENT])
        self.stored[ident] = self.values[ident]
        return bytes([0])

    def _persistent_clear(self, ident: int, e: Optional[T.ParamVar]) -> bytes:
        if not _persistent(e):
            return bytes([ENOENT])
        self.stored.pop(ident, None)
        return bytes([0])

    def _persistent_state(self, ident: int, e: Optional[T.ParamVar]) -> bytes:
        """Whether a value is stored, the default, then the stored value when there is one."""
        if e is None or not e.persistent:
            return bytes([ENOENT])
        ct = T.CTYPES[e.ctype]
        default = T.pack(self.default_of(ident), ct)
        if ident in self.stored:
            return b"\x01" + default + T.pack(self.stored[ident], ct)
        return b"\x00" + default

    def _set_by_name(self, header: int, data: bytes) -> None:
        body = bytes(data[1:])
        first = body.find(b"\x00")
        second = body.find(b"\x00", first + 1) if first >= 0 else -1
        if second < 0:
            return  # fewer than two NULs: ignored by the firmware
        names = body[:second + 1]
        reply = bytes([MISC_SET_BY_NAME]) + names
        try:
            full = "%s.%s" % (body[:first].decode("ascii"), body[first + 1:second].decode("ascii"))
        except UnicodeDecodeError:
            self._send(header, reply + bytes([ENOENT]))
            return
        ident = self._ids.get(full)
        if ident is None:
            self._send(header, reply + bytes([ENOENT]))
            return
        e = self.entries[ident]
        if e.readonly:
            self._send(header, reply + bytes([EACCES]))
            return
        rest = body[second + 1:]
        mask = ~(T.PARAM_CORE | T.PARAM_RO | T.PARAM_EXTENDED) & 0xFF
        if not rest or (rest[0] & mask) != (e.type_byte(self.generation) & mask) \
                or len(rest) - 1 < T.CTYPES[e.ctype].size:
            self._send(header, reply + bytes([EINVAL]))
            return
        self._set(ident, rest[1:])
        self._send(header, reply + bytes([0]))
