"""Port 5 of the simulated firmware: the log TOC, log blocks and their periodic data packets.

docs/protocol.md, "Port 5 (log)": every control packet is answered ``[cmd, request byte 1, result]``; the firmware
generation sets the TOC version (V2 16-bit ids / V1 8-bit ids), the create commands and the limits
(current: 16 blocks, 128 ops, 26 value bytes; 2016.02: 8, 64, 30). Data packets are
``[block, timestamp u24 ms, values...]`` with each value converted to the type the host asked for.
"""
from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from crazyflie_driver.crtp.firmware_limits import LOG_LIMITS, LOG_LIMITS_2016
from crazyflie_driver.sim.crtp import tables as T

ENOENT = 2
E2BIG = 7
ENOEXEC = 8
ENOMEM = 12
EEXIST = 17

CH_TOC, CH_CONTROL, CH_DATA = 0, 1, 2
TOC_ITEM_V1, TOC_INFO_V1, TOC_ITEM_V2, TOC_INFO_V2 = 0, 1, 2, 3
CMD_CREATE, CMD_APPEND, CMD_DELETE, CMD_START, CMD_STOP, CMD_RESET = 0, 1, 2, 3, 4, 5
CMD_CREATE_V2, CMD_APPEND_V2, CMD_START_V2 = 6, 7, 8
DATA_HEADER = (5 << 4) | CH_DATA   # CRTP_HEADER(LOG, DATA): link bits 0

_log = logging.getLogger(__name__)


LIMITS = {T.GEN_CURRENT: LOG_LIMITS, T.GEN_2016: LOG_LIMITS_2016}


@dataclass
class LogBlock:
    ident: int
    ops: List[Tuple[int, T.CType]] = field(default_factory=list)   # (variable index, fetch type)
    period_s: float = 0.0
    running: bool = False
    next_due: Optional[float] = None    # world time of the next packet; None = at the next tick

    @property
    def size(self) -> int:
        return sum(ct.size for _, ct in self.ops)


def _op_items(data: bytes, v2: bool) -> List[Tuple[int, int, int]]:
    """The ops of a CREATE/APPEND packet (``[cmd, block, ops...]``) as (type byte, variable id, the id
    that means raw memory): a type byte and a u8 id each (V1), or a u16 id (V2); a partial op is ignored."""
    stride = 3 if v2 else 2
    items = []
    for off in range(2, len(data) - stride + 1, stride):
        var = struct.unpack_from("<H", data, off + 1)[0] if v2 else data[off + 1]
        items.append((data[off], var, 0xFFFF if v2 else 0xFF))
    return items


class LogService:
    """Log variables of one Crazyflie, its blocks and the data they stream."""

    def __init__(self, generation: str, table: Sequence[T.LogVar], read_value: Callable[[str], float],
                 send: Callable[[int, bytes], bool], clock: Callable[[], float] = lambda: 0.0) -> None:
        self.generation = generation
        self.v2 = generation == T.GEN_CURRENT
        self.limits = LIMITS[generation]
        self.entries: List[T.LogVar] = T.select(table, generation)
        T.check_names(self.entries)
        self.crc = T.toc_crc(self.entries, lambda e: e.crc_type_byte(generation))
        if not self.v2:
            self.crc ^= 0x20160200  # opaque in the 2016 firmware
        self._read_value = read_value
        self._send = send
        self._clock = clock
        self.blocks: Dict[int, LogBlock] = {}
        self.dropped = 0
        self._commands = self._command_table()

    @property
    def ops_used(self) -> int:
        return sum(len(b.ops) for b in self.blocks.values())

    def reset(self) -> None:
        self.blocks.clear()

    # --- protocol ---------------------------------------------------------------------------
    def handle(self, header: int, channel: int, data: bytes) -> None:
        if channel == CH_TOC:
            self._toc(header, data)
        elif channel == CH_CONTROL:
            self._control(header, data)
        # channel 2 is CF -> host only; 3 unused

    def _toc(self, header: int, data: bytes) -> None:
        if not data:
            return
        cmd, n, lim = data[0], len(self.entries), self.limits
        if self.v2 and cmd == TOC_INFO_V2:
            self._send(header, struct.pack("<BHIBB", cmd, n, self.crc, lim.max_blocks, lim.max_ops))
        elif self.v2 and cmd == TOC_ITEM_V2 and len(data) >= 3:
            ident = struct.unpack_from("<H", data, 1)[0]
            if ident >= n:
                self._send(header, bytes([cmd]))
            else:
                self._send(header, struct.pack("<BHB", cmd, ident, self._type_of(ident)) + self._name(ident))
        elif not self.v2 and cmd == TOC_INFO_V1:
            self._send(header, struct.pack("<BBIBB", cmd, min(n, 255), self.crc, lim.max_blocks, lim.max_ops))
        elif not self.v2 and cmd == TOC_ITEM_V1 and len(data) >= 2:
            ident = data[1]
            if ident >= n:
                self._send(header, bytes([cmd]))
            else:
                self._send(header, bytes([cmd, ident, self._type_of(ident)]) + self._name(ident))

    def _type_of(self, ident: int) -> int:
        code = T.CTYPES[self.entries[ident].ctype].log_code
        assert code is not None, "%s is in the log table but its type cannot be logged" % self.entries[ident].ctype
        return code

    def _name(self, ident: int) -> bytes:
        return T.toc_item_name(self.entries[ident])

    def _control(self, header: int, data: bytes) -> None:
        if not data:
            return
        cmd = data[0]
        arg = data[1] if len(data) > 1 else 0
        result = self._command(cmd, data)
        self._send(header, bytes([cmd, arg, result]))

    def _command(self, cmd: int, data: bytes) -> int:
        handler = self._commands.get(cmd)
        return ENOEXEC if handler is None else handler(data)

    def _command_table(self) -> Dict[int, Callable[[bytes], int]]:
        """The control commands this generation knows: the current firmware takes only the V2
        create/append commands, the 2016 one only the V1 ones and no START_V2."""
        commands: Dict[int, Callable[[bytes], int]] = {
            CMD_DELETE: self._delete_command, CMD_START: self._start_command, CMD_STOP: self._stop_command,
            CMD_RESET: self._reset_command}
        if self.v2:
            commands.update({CMD_CREATE_V2: self._create_command, CMD_APPEND_V2: self._append_command,
                             CMD_START_V2: self._start_v2_command})
        else:
            commands.update({CMD_CREATE: self._create_command, CMD_APPEND: self._append_command})
        return commands

    def _create_command(self, data: bytes) -> int:
        if len(data) < 2:
            return ENOENT
        return self._create(data[1], _op_items(data, self.v2))

    def _append_command(self, data: bytes) -> int:
        if len(data) < 2:
            return ENOENT
        block = self.blocks.get(data[1])
        return ENOENT if block is None else self._append(block, _op_items(data, self.v2))

    def _delete_command(self, data: bytes) -> int:
        return ENOENT if len(data) < 2 or self.blocks.pop(data[1], None) is None else 0

    def _start_command(self, data: bytes) -> int:
        """START: the period in one byte of 10 ms."""
        return self._start(data, (data[2] if len(data) > 2 else 0) * 0.010)

    def _start_v2_command(self, data: bytes) -> int:
        """START_V2: the period in a u16 of ms."""
        return self._start(data, (struct.unpack_from("<H", data, 2)[0] if len(data) > 3 else 0) * 0.001)

    def _start(self, data: bytes, period_s: float) -> int:
        block = self._block_of(data)
        if block is None:
            return ENOENT
        block.period_s = period_s
        block.running = True
        # like the firmware's timer: the first packet one period after START (period 0: next tick)
        block.next_due = self._clock() + period_s if period_s > 0 else None
        return 0

    def _stop_command(self, data: bytes) -> int:
        block = self._block_of(data)
        if block is None:
            return ENOENT
        block.running = False
        return 0

    def _reset_command(self, data: bytes) -> int:
        self.reset()
        return 0

    def _block_of(self, data: bytes) -> Optional[LogBlock]:
        """The block a control packet names in its byte 1 (None when absent or not given)."""
        return self.blocks.get(data[1]) if len(data) > 1 else None

    def _create(self, ident: int, items) -> int:
        if ident in self.blocks:
            return EEXIST
        if len(self.blocks) >= self.limits.max_blocks:
            return ENOMEM
        block = LogBlock(ident)
        self.blocks[ident] = block
        return self._append(block, items)

    def _append(self, block: LogBlock, items) -> int:
        """Add ops one by one; an error stops the list and keeps what was added (not atomic)."""
        for type_byte, var, raw_marker in items:
            fetch = T.LOG_TYPES.get(type_byte & 0x0F)
            if var == raw_marker or var >= len(self.entries) or fetch is None:
                return ENOENT  # no raw memory in the simulation; unknown variables and types
            if block.size + fetch.size > self.limits.max_bytes:
                return E2BIG
            if self.ops_used >= self.limits.max_ops:
                return ENOMEM
            block.ops.append((var, fetch))
        return 0

    # --- data --------------------------------------------------------------------------------
    def tick(self, now: float, timestamp_ms: int) -> None:
        """Send the data packet of every running block that is due at world time ``now``."""
        for block in list(self.blocks.values()):
            if not block.running:
                continue
            if block.next_due is not None and now + 1e-9 < block.next_due:
                continue
            self._send_block(block, timestamp_ms)
            if block.period_s <= 0:
                block.running = False  # period 0: sent once
                continue
            due = (block.next_due if block.next_due is not None else now) + block.period_s
            block.next_due = due if due > now else now + block.period_s

    def _send_block(self, block: LogBlock, timestamp_ms: int) -> None:
        payload = bytearray([block.ident]) + struct.pack("<I", timestamp_ms & 0xFFFFFF)[:3]
        for var, fetch in block.ops:
            entry = self.entries[var]
            try:
                raw = float(self._read_value(entry.full_name))
            except Exception:
                raw = 0.0
            stored = T.clamp(raw, T.CTYPES[entry.ctype])
            payload += T.pack(stored, fetch)
        if not self._send(DATA_HEADER, bytes(payload)):
            self.dropped += 1
