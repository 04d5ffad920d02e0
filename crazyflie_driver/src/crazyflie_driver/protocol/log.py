"""Port 5 (log): TOC, log blocks and the decoding of their data packets.

A log block is a list of TOC variables the firmware samples every period and
sends as ``[block, timestamp u24 ms, values...]`` on 5:2. Control requests on
5:1 are answered ``[cmd, block, result]``; a non-zero result is a firmware
error code, turned into a sentence here.
"""
from __future__ import annotations

import logging
import struct
from typing import Callable, Dict, List, Sequence

from crazyflie_driver.crtp.ctypes import ctype, type_size
from crazyflie_driver.crtp.firmware_limits import (
    LOG_BLOCK_MAX_BYTES,
    LOG_MAX_BLOCKS,
    LOG_MAX_OPS,
    LOG_PERIOD_MAX_MS,
    LOG_PERIOD_MIN_MS,
    LOG_PERIOD_UNIT_MS,
    LOG_PERIOD_V2_MAX_MS,
)
from crazyflie_driver.crtp.packet import MAX_PAYLOAD, PORT_LOG, CRTPPacket
from crazyflie_driver.errors import LogConfigError, ProtocolError
from crazyflie_driver.protocol.toc import TocEntry, TocPortClient, check_toc_name

_LOG = logging.getLogger(__name__)

CH_TOC = 0
CH_CONTROL = 1
CH_DATA = 2

CMD_CREATE = 0
CMD_APPEND = 1
CMD_DELETE = 2
CMD_START = 3
CMD_STOP = 4
CMD_RESET = 5
CMD_CREATE_V2 = 6
CMD_APPEND_V2 = 7
CMD_START_V2 = 8

#: Protocol version from which START_V2 (period in ms as u16) exists (firmware 2024.10).
START_V2_FROM = 8

ENOENT, E2BIG, ENOEXEC, ENOMEM, EEXIST = 2, 7, 8, 12, 17
FIRMWARE_ERRORS = {
    ENOENT: "no such log block or variable (ENOENT)",
    E2BIG: "the values do not fit in one log packet (E2BIG)",
    ENOEXEC: "the firmware does not know this log command (ENOEXEC)",
    ENOMEM: "no free log block or log operation left on the Crazyflie (ENOMEM)",
    EEXIST: "the log block id is already in use (EEXIST)",
}

LogCallback = Callable[[int, List[float]], None]


def firmware_error(code: int) -> str:
    return FIRMWARE_ERRORS.get(code, "firmware error %d" % code)


class LogBlock:
    """A block created on the Crazyflie. Its callback runs in the link's polling thread."""

    def __init__(self, client: LogClient, ident: int, variables: List[TocEntry],
                 period_ms: int, callback: LogCallback) -> None:
        self.client = client
        self.ident = ident
        self.variables = variables
        self.period_ms = period_ms
        self.callback = callback
        self.started = False
        self.deleted = False
        self._types = [ctype(v.ctype) for v in variables]
        self._size = sum(type_size(v.ctype) for v in variables)

    @property
    def names(self) -> List[str]:
        return [v.full_name for v in self.variables]

    def start(self) -> None:
        self.client._start(self)

    def stop(self) -> None:
        self.client._stop(self)

    def delete(self) -> None:
        self.client._delete(self)

    def decode(self, data: bytes) -> tuple[int, List[float]]:
        """``[ts u24, values...]`` (block id stripped) -> (timestamp ms, values)."""
        if len(data) < 3 + self._size:
            raise ProtocolError("log block %d: %d value bytes, expected %d"
                                % (self.ident, len(data) - 3, self._size))
        timestamp = data[0] | (data[1] << 8) | (data[2] << 16)
        values = []
        offset = 3
        for ct in self._types:
            values.append(ct.unpack(data, offset))
            offset += ct.size
        return timestamp, values


class LogClient(TocPortClient):
    """Log TOC and blocks of one Crazyflie. Control requests go one at a time."""

    def __init__(self, link, cache=None, timeout: float = 1.0) -> None:
        super().__init__(link, PORT_LOG, "log", cache, timeout)
        self.max_blocks = LOG_MAX_BLOCKS
        self.max_ops = LOG_MAX_OPS
        self.blocks: Dict[int, LogBlock] = {}
        self._unsubscribe = link.subscribe(PORT_LOG, CH_DATA, self._on_data)

    def fetch_toc(self) -> List[TocEntry]:
        """Download the log TOC (or take it from the cache); it also tells how many blocks and
        variables (ops) fit."""
        with self._lock:
            info = self._download_toc()
            if info.max_blocks:
                self.max_blocks = min(info.max_blocks, LOG_MAX_BLOCKS)
            if info.max_ops:
                self.max_ops = min(info.max_ops, LOG_MAX_OPS)
            assert self.toc is not None
            return list(self.toc)

    @property
    def ops_used(self) -> int:
        """Log variables in the blocks created so far (the firmware counts them over all blocks)."""
        return sum(len(b.variables) for b in self.blocks.values())

    def reset(self) -> None:
        """Delete every block on the Crazyflie (also those a previous session left running)."""
        with self._lock:
            self._control(bytes([CMD_RESET]), "log reset")
            for block in self.blocks.values():
                block.deleted = True
                block.started = False
            self.blocks.clear()

    def create_block(self, variables: Sequence[str], period_ms: int,
                     callback: LogCallback) -> LogBlock:
        """Create and start a block of ``group.name`` variables sampled every ``period_ms``."""
        for name in variables:
            check_toc_name(name, "log variable")
        with self._lock:
            toc = self._ensure_toc()
            if not variables:
                raise LogConfigError("a log block needs at least one variable")
            entries = [toc.lookup(name, "log variable") for name in variables]
            size = sum(type_size(e.ctype) for e in entries)
            if size > LOG_BLOCK_MAX_BYTES:
                raise LogConfigError(
                    "log block %s needs %d bytes of values, at most %d fit in one log packet"
                    % (", ".join(variables), size, LOG_BLOCK_MAX_BYTES))
            period_ms = self._effective_period(period_ms)
            if len(self.blocks) >= self.max_blocks:
                raise LogConfigError("cannot create log block %s: all %d log blocks the firmware holds are in use "
                                     "(delete one first)" % (", ".join(variables), self.max_blocks))
            if self.ops_used + len(entries) > self.max_ops:
                raise LogConfigError(
                    "cannot create log block %s: it needs %d log variables and %d of the %d the firmware holds over "
                    "all blocks are in use by %d blocks (delete one, or log fewer variables)"
                    % (", ".join(variables), len(entries), self.ops_used, self.max_ops, len(self.blocks)))
            ident = next(i for i in range(1, 256) if i not in self.blocks)
            block = LogBlock(self, ident, entries, int(period_ms), callback)
            self._send_create(block)
            self.blocks[ident] = block
            try:
                self._start(block)
            except Exception:
                self._delete(block)
                raise
            return block

    def close(self) -> None:
        self._unsubscribe()

    # -- control requests -----------------------------------------------------------------------

    def _effective_period(self, period_ms) -> int:
        """The period the firmware will use. START counts in 10 ms units (truncated, as the
        original driver did); firmware with START_V2 takes any whole number of ms."""
        try:
            period = int(period_ms)
        except (TypeError, ValueError):
            raise LogConfigError("log period %r is not a number of milliseconds" % (period_ms,)) from None
        if self.protocol_version >= START_V2_FROM:
            if not 1 <= period <= LOG_PERIOD_V2_MAX_MS:
                raise LogConfigError("log period %r ms is out of range 1..%d ms"
                                     % (period_ms, LOG_PERIOD_V2_MAX_MS))
            return period
        if not LOG_PERIOD_MIN_MS <= period <= LOG_PERIOD_MAX_MS:
            raise LogConfigError("log period %r ms is out of range %d..%d ms (the firmware counts "
                                 "in 10 ms units)" % (period_ms, LOG_PERIOD_MIN_MS, LOG_PERIOD_MAX_MS))
        return period - period % LOG_PERIOD_UNIT_MS

    def _send_create(self, block: LogBlock) -> None:
        v2 = self.version >= 2
        item_size = 3 if v2 else 2
        per_packet = (MAX_PAYLOAD - 2) // item_size
        items = []
        for entry in block.variables:
            code = ctype(entry.ctype).log_code
            if code is None:
                raise LogConfigError("%s is a %s, which the log cannot carry: log another variable"
                                     % (entry.name, entry.ctype))
            type_byte = (code << 4) | code
            if v2:
                items.append(struct.pack("<BH", type_byte, entry.ident))
            else:
                items.append(bytes([type_byte, entry.ident]))
        for start in range(0, len(items), per_packet):
            first = start == 0
            if v2:
                cmd = CMD_CREATE_V2 if first else CMD_APPEND_V2
            else:
                cmd = CMD_CREATE if first else CMD_APPEND
            payload = bytes([cmd, block.ident]) + b"".join(items[start:start + per_packet])
            what = "log block %d %s" % (block.ident, "create" if first else "append")
            result = self._control(payload, what, check=False)
            if result == EEXIST and first:
                # The id is taken: a block left by an earlier session, or the first copy of a
                # resent create. Either way its content is not known: delete and create again.
                self._control(bytes([CMD_DELETE, block.ident]), "log block %d delete"
                              % block.ident, check=False)
                result = self._control(payload, what, check=False)
            if result != 0:
                # Create is not atomic: free the ops already added before reporting.
                self._control(bytes([CMD_DELETE, block.ident]), "log block %d delete"
                              % block.ident, check=False)
                raise LogConfigError("%s: cannot create log block %s: %s"
                                     % (self.link.uri, ", ".join(block.names),
                                        firmware_error(result)))

    def _start(self, block: LogBlock) -> None:
        with self._lock:
            period = block.period_ms
            if period % LOG_PERIOD_UNIT_MS == 0 and LOG_PERIOD_MIN_MS <= period <= LOG_PERIOD_MAX_MS:
                payload = bytes([CMD_START, block.ident, period // LOG_PERIOD_UNIT_MS])
            elif self.protocol_version >= START_V2_FROM:
                payload = struct.pack("<BBH", CMD_START_V2, block.ident, period)
            else:  # unreachable after _effective_period; kept as a guard
                raise LogConfigError("log period %d ms is not possible with this firmware" % period)
            self._control(payload, "log block %d start" % block.ident)
            block.started = True

    def _stop(self, block: LogBlock) -> None:
        with self._lock:
            self._control(bytes([CMD_STOP, block.ident]), "log block %d stop" % block.ident)
            block.started = False

    def _delete(self, block: LogBlock) -> None:
        with self._lock:
            result = self._control(bytes([CMD_DELETE, block.ident]),
                                   "log block %d delete" % block.ident, check=False)
            if result not in (0, ENOENT):  # ENOENT: already gone (e.g. a resent delete)
                raise ProtocolError("%s: deleting log block %d failed: %s"
                                    % (self.link.uri, block.ident, firmware_error(result)))
            block.started = False
            block.deleted = True
            self.blocks.pop(block.ident, None)

    def _control(self, payload: bytes, what: str, check: bool = True) -> int:
        """Send a control request, wait for ``[cmd, byte1, result]``; returns the result."""
        cmd = payload[0]
        reset = cmd == CMD_RESET

        def match(p: CRTPPacket) -> bool:
            if p.port != PORT_LOG or p.channel != CH_CONTROL or len(p.data) < 3:
                return False
            return p.data[0] == cmd and (reset or p.data[1] == payload[1])

        reply = self.link.request(CRTPPacket(PORT_LOG, CH_CONTROL, payload), match=match,
                                  timeout=self.timeout, what=what)
        result = reply.data[2]
        if check and result != 0:
            raise ProtocolError("%s: %s failed: %s" % (self.link.uri, what, firmware_error(result)))
        return result

    # -- data -------------------------------------------------------------------------------

    def _on_data(self, packet: CRTPPacket) -> None:
        if not packet.data:
            return
        block = self.blocks.get(packet.data[0])
        if block is None:
            return
        try:
            timestamp, values = block.decode(packet.data[1:])
        except ProtocolError as e:
            _LOG.warning("%s: %s", self.link.uri, e)
            return
        try:
            block.callback(timestamp, values)
        except Exception:  # a user callback must not kill the link thread
            _LOG.exception("%s: log block %d callback failed", self.link.uri, block.ident)
