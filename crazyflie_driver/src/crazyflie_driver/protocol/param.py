"""Port 2 (parameters): TOC, reads and writes in both protocol generations.

V1 (protocol version < 4): read ``[id]`` -> ``[id, value]``, write ``[id, value]``
-> echo, unknown id -> ``[0xFF, id, 2]``. V2: 16-bit ids, read ``[id u16]`` ->
``[id u16, status, value]``, write echoed, unknown id -> ``[id u16, 2]``. A
read-only parameter gets no reply to a write, so it is refused before sending.
"""
from __future__ import annotations

import logging
import math
import struct
from typing import Any, Callable, Dict, List, Optional, Union

from crazyflie_driver.crtp.ctypes import ctype, type_size
from crazyflie_driver.crtp.packet import MAX_PAYLOAD, PORT_PARAM, CRTPPacket
from crazyflie_driver.errors import ParamValueError, ProtocolError, ReadOnlyParam
from crazyflie_driver.protocol.toc import TocEntry, TocPortClient, check_toc_name, request_all

_LOG = logging.getLogger(__name__)

CH_TOC = 0
CH_READ = 1
CH_WRITE = 2
CH_MISC = 3
MISC_SET_BY_NAME = 0
MISC_VALUE_UPDATED = 1
ENOENT = 2

Value = Union[int, float]


def param_value(full_name: str, ctype_name: str, value: Any) -> Value:
    """``value`` (number, bool or text) as parameter ``full_name`` of C type ``ctype_name`` holds it.

    The one conversion every parameter write goes through. Integer types take whole numbers in
    their range, ``true``/``false`` (bool or text, any case) as 1/0, and numeric text (``"0x10"``);
    floating types take finite numbers within the type's range and numeric text. NaN, infinity,
    fractions for integers and booleans for floating types are refused: ParamValueError naming the
    parameter, its type and the range.
    """
    ct = ctype(ctype_name)
    label = "parameter %s (%s)" % (full_name, ct.name)
    if ct.is_float:
        number = _as_float(label, value)
        if not math.isfinite(number):
            raise ParamValueError("%s: %r is not a finite number" % (label, value))
        if not ct.holds(number):
            raise ParamValueError("%s: %r is out of range %g..%g" % (label, value, ct.low, ct.high))
        return number
    number = _as_integer(label, value)
    if not ct.holds(number):
        raise ParamValueError("%s: %r is out of range %d..%d" % (label, value, ct.low, ct.high))
    return number


def _as_float(label: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ParamValueError("%s: %r is not a number" % (label, value))
    try:
        return float(value)
    except (TypeError, ValueError, OverflowError):
        raise ParamValueError("%s: %r is not a number" % (label, value)) from None


def _as_integer(label: str, value: Any) -> int:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, int):
        return value
    if isinstance(value, str):
        text = value.strip()
        if text.lower() in ("true", "false"):
            return int(text.lower() == "true")
        try:
            return int(text, 0)
        except ValueError:
            pass
    if not isinstance(value, (float, str)):
        raise ParamValueError("%s: %r is not an integer" % (label, value))
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParamValueError("%s: %r is not an integer" % (label, value)) from None
    if not math.isfinite(number) or number != int(number):
        raise ParamValueError("%s: %r is not an integer" % (label, value))
    return int(number)


def set_by_name_packet(full_name: str, ctype_name: str, value: Any) -> CRTPPacket:
    """SET_BY_NAME (misc channel, command 0): ``[0, group, 0, name, 0, type, value]``, a write that names the
    parameter instead of its TOC id, so one broadcast sets it on every Crazyflie that has it (as swarm servers
    send ``/update_params``). ``value`` converted as ``param_value`` does; ParamValueError when the name and
    value do not fit in one packet. The firmware answers it (the answer waits in its transmit queue)."""
    check_toc_name(full_name, "parameter")
    ct = ctype(ctype_name)
    group, name = full_name.split(".")
    payload = (bytes([MISC_SET_BY_NAME]) + group.encode("ascii") + b"\x00" + name.encode("ascii") + b"\x00"
               + bytes([ct.param_code]) + ct.pack(param_value(full_name, ctype_name, value)))
    if len(payload) > MAX_PAYLOAD:
        raise ParamValueError("parameter %s: a write by name takes %d bytes, more than a packet's %d"
                              % (full_name, len(payload), MAX_PAYLOAD))
    return CRTPPacket(PORT_PARAM, CH_MISC, payload)


def pack_value(entry: TocEntry, value: Value) -> bytes:
    return ctype(entry.ctype).pack(value)


def unpack_value(entry: TocEntry, data: bytes) -> Value:
    return ctype(entry.ctype).unpack(data)


class ParamClient(TocPortClient):
    """Parameters of one Crazyflie: TOC, reads, writes. One request in flight at a time.

    ``fetch_toc`` in V2 also sends GET_INFO_V2, which firmware 2018.10-2021.06 needs before it
    answers V2 reads.
    """

    def __init__(self, link, cache=None, timeout: float = 1.0) -> None:
        super().__init__(link, PORT_PARAM, "param", cache, timeout)
        self.values: Dict[str, Value] = {}
        self._update_callbacks: List[Callable[[str, Value], None]] = []
        self._unsubscribe = link.subscribe(PORT_PARAM, CH_MISC, self._on_misc)

    def read_all(self) -> Dict[str, Value]:
        """Read every parameter, several requests in flight (toc.request_all); ``group.name`` -> value."""
        with self._lock:
            toc = self._ensure_toc()
            v2 = self.version >= 2
            entries = {self._id_bytes(e.ident): e for e in toc}

            def key_of(p: CRTPPacket) -> Optional[bytes]:
                if not v2 and len(p.data) == 3 and p.data[0] == 0xFF:
                    return bytes(p.data[1:2])       # the 2016 firmware's error reply
                key = bytes(p.data[:2 if v2 else 1])
                return key if key in entries else None

            answers = request_all(self.link, [(k, CRTPPacket(PORT_PARAM, CH_READ, k)) for k in entries],
                                  PORT_PARAM, CH_READ, key_of, self.timeout,
                                  lambda k: "parameter read of %s" % entries[k].full_name)
            return {e.full_name: self._value_of(e, answers[k]) for k, e in entries.items()}

    def get(self, name: str) -> Value:
        """Read one parameter from the Crazyflie now."""
        check_toc_name(name, "parameter")       # before a TOC download
        with self._lock:
            entry = self._ensure_toc().lookup(name, "parameter")
            return self._read(entry)

    def set(self, name: str, value) -> Value:
        """Convert ``value`` to the parameter's type and write it; returns the value written."""
        check_toc_name(name, "parameter")
        with self._lock:
            entry = self._ensure_toc().lookup(name, "parameter")
            if entry.readonly:
                raise ReadOnlyParam("parameter %s is read-only on the Crazyflie" % entry.full_name)
            converted = param_value(entry.full_name, entry.ctype, value)
            self._write(entry, converted)
            return converted

    def on_update(self, callback: Callable[[str, Value], None]) -> None:
        """callback(name, value) when the firmware reports a changed value on its own (2:3)."""
        self._update_callbacks.append(callback)

    def close(self) -> None:
        self._unsubscribe()

    # -- wire formats -------------------------------------------------------------------------

    def _id_bytes(self, ident: int) -> bytes:
        if self.version >= 2:
            return struct.pack("<H", ident)
        return bytes([ident])

    def _read(self, entry: TocEntry) -> Value:
        id_bytes = self._id_bytes(entry.ident)
        v2 = self.version >= 2

        def match(p: CRTPPacket) -> bool:
            if p.port != PORT_PARAM or p.channel != CH_READ:
                return False
            if p.data[:len(id_bytes)] == id_bytes:
                return True
            return not v2 and len(p.data) == 3 and p.data[0] == 0xFF and p.data[1] == entry.ident

        reply = self.link.request(CRTPPacket(PORT_PARAM, CH_READ, id_bytes), match=match,
                                  timeout=self.timeout,
                                  what="parameter read of %s" % entry.full_name)
        return self._value_of(entry, reply)

    def _value_of(self, entry: TocEntry, reply: CRTPPacket) -> Value:
        """The value a read reply carries (stored in ``values``); ProtocolError for an error reply."""
        size = type_size(entry.ctype)
        v2 = self.version >= 2
        data = reply.data
        if v2:
            if len(data) == 3 + size and data[2] == 0:
                raw = data[3:]
            elif len(data) >= 3:
                raise ProtocolError("%s: reading parameter %s failed: firmware error %d%s"
                                    % (self.link.uri, entry.full_name, data[2],
                                       " (no such id)" if data[2] == ENOENT else ""))
            else:
                raise ProtocolError("%s: short reply to parameter read of %s: %s"
                                    % (self.link.uri, entry.full_name, data.hex(" ")))
        else:
            if len(data) == 1 + size and data[0] == entry.ident:
                raw = data[1:]
            elif len(data) == 3 and data[0] == 0xFF:
                raise ProtocolError("%s: reading parameter %s failed: firmware error %d"
                                    % (self.link.uri, entry.full_name, data[2]))
            else:
                raise ProtocolError("%s: reply to parameter read of %s has %d value bytes, "
                                    "expected %d: %s" % (self.link.uri, entry.full_name,
                                                         len(data) - 1, size, data.hex(" ")))
        value = unpack_value(entry, raw)
        self.values[entry.full_name] = value
        return value

    def _write(self, entry: TocEntry, value: Value) -> None:
        id_bytes = self._id_bytes(entry.ident)
        request = id_bytes + pack_value(entry, value)
        v2 = self.version >= 2

        def match(p: CRTPPacket) -> bool:
            if p.port != PORT_PARAM or p.channel != CH_WRITE:
                return False
            if p.data[:len(id_bytes)] == id_bytes:
                return True
            return not v2 and len(p.data) == 3 and p.data[0] == 0xFF and p.data[1] == entry.ident

        reply = self.link.request(CRTPPacket(PORT_PARAM, CH_WRITE, request), match=match,
                                  timeout=self.timeout,
                                  what="parameter write of %s" % entry.full_name)
        if reply.data != request:
            code = reply.data[-1] if reply.data else -1
            raise ProtocolError("%s: writing parameter %s failed: firmware error %d"
                                % (self.link.uri, entry.full_name, code))
        self.values[entry.full_name] = value

    def _on_misc(self, packet: CRTPPacket) -> None:
        data = packet.data
        if len(data) < 3 or data[0] != MISC_VALUE_UPDATED or self.toc is None:
            return
        entry = self.toc.by_id(data[1] | (data[2] << 8))
        if entry is None or len(data) != 3 + type_size(entry.ctype):
            return
        value = unpack_value(entry, data[3:])
        self.values[entry.full_name] = value
        for callback in list(self._update_callbacks):
            try:
                callback(entry.full_name, value)
            except Exception:  # a user callback must not kill the link thread
                _LOG.exception("parameter update callback failed")
