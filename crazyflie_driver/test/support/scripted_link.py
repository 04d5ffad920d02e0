"""Test doubles for the protocol layer: a link that records every uplink packet and a
scripted Crazyflie that answers with byte-exact firmware replies (docs/protocol.md).

``ScriptedLink`` follows the link contract of docs/architecture.md, minus the radio:
each ``send`` hands the packet to the firmware double, and each round trip delivers at
most one queued downlink packet, as the nRF does. A request with nothing left to
deliver fails at once with the LinkTimeout the real link raises (no sleeping).
"""
from __future__ import annotations

import struct
import zlib
from collections import deque
from typing import Callable, Dict, List, Optional, Tuple

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import LinkTimeout
from crazyflie_driver.radio.statistics import LinkStatistics

ENOENT, E2BIG, ENOEXEC, ENOMEM, EEXIST = 2, 7, 8, 12, 17

PARAM_TYPE_BYTES = {"uint8_t": 0x08, "uint16_t": 0x09, "uint32_t": 0x0A, "int8_t": 0x00,
                    "int16_t": 0x01, "int32_t": 0x02, "float": 0x06, "FP16": 0x05,
                    "double": 0x07, "uint64_t": 0x0B, "int64_t": 0x03}
STRUCT = {"uint8_t": "<B", "uint16_t": "<H", "uint32_t": "<I", "int8_t": "<b", "int16_t": "<h",
          "int32_t": "<i", "float": "<f", "FP16": "<e", "double": "<d", "uint64_t": "<Q",
          "int64_t": "<q"}
LOG_CODES = {"uint8_t": 1, "uint16_t": 2, "uint32_t": 3, "int8_t": 4, "int16_t": 5,
             "int32_t": 6, "float": 7, "FP16": 8}

DEFAULT_PARAMS = [
    # (group, name, ctype, readonly, value)
    ("pid_rate", "roll_kp", "float", False, 250.0),
    ("ring", "effect", "uint8_t", False, 6),
    ("ring", "headlightEnable", "uint8_t", False, 0),
    ("imu_sensors", "HMC5883L", "uint8_t", True, 1),
    ("flightmode", "althold", "uint8_t", False, 0),
    ("motorPowerSet", "m1", "uint16_t", False, 0),
    ("stabilizer", "offset", "int16_t", False, -3),
    ("kalman", "pNAcc_xy", "FP16", False, 0.5),
]
DEFAULT_LOGS = [
    # (group, name, ctype, value)
    ("acc", "x", "float", 0.01), ("acc", "y", "float", -0.02), ("acc", "z", "float", 1.0),
    ("pm", "vbat", "float", 3.95), ("gyro", "x", "float", 0.5), ("gyro", "y", "float", 0.0),
    ("gyro", "z", "float", -0.5), ("baro", "temp", "float", 24.5),
    ("baro", "pressure", "float", 1013.25), ("radio", "rssi", "uint8_t", 42),
    ("motor", "m1", "uint32_t", 123456), ("stab", "thrust", "uint16_t", 40000),
    ("pos", "dx", "int8_t", -5), ("pos", "dy", "int16_t", -300), ("pos", "dz", "int32_t", -70000),
    ("kf", "q", "FP16", 0.25),
]


class ScriptedFirmware:
    """A Crazyflie's CRTP answers, in the format of ``protocol_version`` (2 = FW16, 12 = current).

    ``silent_ports``: ports that never answer (to provoke timeouts).
    """

    def __init__(self, protocol_version: int = 12, params=None, logs=None,
                 magic: bool = True) -> None:
        self.protocol_version = protocol_version
        self.v2 = protocol_version >= 4
        self.magic = magic
        self.params = [list(p) for p in (params if params is not None else DEFAULT_PARAMS)]
        self.logs = [list(entry) for entry in (logs if logs is not None else DEFAULT_LOGS)]
        self.silent_ports: set = set()
        self.max_blocks = 16 if self.v2 else 8
        self.blocks: Dict[int, dict] = {}
        self.ops_used = 0
        self.max_ops = 128

    # CRC over the table as the firmware chains it (the FW16 value is opaque; any stable one works).
    def crc(self, kind: str) -> int:
        crc = 0
        rows = self.params if kind == "param" else self.logs
        for row in rows:
            crc = zlib.crc32(struct.pack("<I", crc) + ("%s.%s.%s" % tuple(row[:3])).encode())
        return crc

    def handle(self, p: CRTPPacket) -> List[CRTPPacket]:
        if p.port in self.silent_ports:
            return []
        handler = {15: self._link, 13: self._platform, 2: self._param, 5: self._log}.get(p.port)
        return handler(p) if handler else []

    def _link(self, p):
        if p.channel == 1:
            data = (b"Bitcraze Crazyflie" + bytes(12)) if self.magic else bytes(30)
            return [CRTPPacket(15, 1, data)]
        if p.channel == 0:
            return [p]
        return []

    def _platform(self, p):
        if p.channel == 1 and p.data[:1] == b"\x00":
            return [CRTPPacket(13, 1, b"\x00" + struct.pack("<i", self.protocol_version))]
        if p.channel == 1 and p.data[:1] == b"\x01":
            return [CRTPPacket(13, 1, b"\x01" + (b"2026.04" if self.v2 else b"2016.02"))]
        return []

    # -- param ---------------------------------------------------------------------------------
    def _param(self, p):
        d = p.data
        if p.channel == 0:
            return [CRTPPacket(2, 0, self._toc_reply("param", d))] if d else []
        if p.channel == 1:
            ident, n = self._ident(d)
            if ident >= len(self.params):
                err = d[:2] + bytes([ENOENT]) if self.v2 else bytes([0xFF, d[0], ENOENT])
                return [CRTPPacket(2, 1, err)]
            g, name, ctype, ro, value = self.params[ident]
            status = b"\x00" if self.v2 else b""
            return [CRTPPacket(2, 1, d[:n] + status + struct.pack(STRUCT[ctype], value))]
        if p.channel == 2:
            ident, n = self._ident(d)
            if ident >= len(self.params):
                err = d[:2] + bytes([ENOENT]) if self.v2 else bytes([0xFF, d[0], ENOENT])
                return [CRTPPacket(2, 2, err)]
            row = self.params[ident]
            if row[3]:
                return []  # read-only: no reply
            row[4] = struct.unpack(STRUCT[row[2]], d[n:])[0]
            return [p]
        return []

    def _ident(self, d: bytes) -> Tuple[int, int]:
        if self.v2:
            return d[0] | (d[1] << 8), 2
        return d[0], 1

    def _toc_reply(self, kind: str, d: bytes) -> bytes:
        rows = self.params if kind == "param" else self.logs
        cmd = d[0]
        if self.v2 and cmd == 3:
            reply = bytes([3]) + struct.pack("<HI", len(rows), self.crc(kind))
            return reply + (bytes([self.max_blocks, self.max_ops]) if kind == "log" else b"")
        if not self.v2 and cmd == 1:
            reply = bytes([1]) + struct.pack("<BI", len(rows), self.crc(kind))
            return reply + (bytes([self.max_blocks, 64]) if kind == "log" else b"")
        if (self.v2 and cmd == 2) or (not self.v2 and cmd == 0):
            ident = (d[1] | (d[2] << 8)) if self.v2 else d[1]
            id_bytes = d[1:3] if self.v2 else d[1:2]
            if ident >= len(rows):
                return bytes([cmd])
            row = rows[ident]
            if kind == "param":
                type_byte = PARAM_TYPE_BYTES[row[2]] | (0x40 if row[3] else 0)
            else:
                type_byte = LOG_CODES[row[2]]
            return (bytes([cmd]) + id_bytes + bytes([type_byte]) + row[0].encode() + b"\x00"
                    + row[1].encode() + b"\x00")
        return b""

    # -- log -------------------------------------------------------------------------------------
    def _log(self, p):
        d = p.data
        if p.channel == 0:
            return [CRTPPacket(5, 0, self._toc_reply("log", d))] if d else []
        if p.channel != 1 or not d:
            return []
        cmd = d[0]
        block = d[1] if len(d) > 1 else 0
        return [CRTPPacket(5, 1, bytes([cmd, block, self._log_command(cmd, block, d)]))]

    def _log_command(self, cmd: int, block: int, d: bytes) -> int:
        """The result code of log control command ``cmd`` on ``block``."""
        if cmd == 5:                    # RESET
            self.blocks.clear()
            self.ops_used = 0
            return 0
        if cmd in (0, 1, 6, 7):         # CREATE, APPEND (V1), CREATE, APPEND (V2)
            return self._log_add(cmd, block, d)
        if cmd in (2, 3, 4, 8):         # DELETE, START, STOP, START (V2)
            return ENOENT if block not in self.blocks else self._log_block_command(cmd, block, d)
        return ENOEXEC

    def _log_add(self, cmd: int, block: int, d: bytes) -> int:
        """CREATE makes the block, APPEND needs it; then the ops one by one (an error keeps the earlier ones)."""
        v2cmd = cmd in (6, 7)
        if v2cmd != self.v2:
            return ENOEXEC
        if cmd in (0, 6):
            code = self._log_new_block(block)
        else:
            code = 0 if block in self.blocks else ENOENT
        if code:
            return code
        step = 3 if v2cmd else 2
        items = d[2:]
        for i in range(0, len(items), step):
            ident = (items[i + 1] | (items[i + 2] << 8)) if v2cmd else items[i + 1]
            code = self._log_add_op(block, ident)
            if code:
                return code
        return 0

    def _log_new_block(self, block: int) -> int:
        if block in self.blocks:
            return EEXIST
        if len(self.blocks) >= self.max_blocks:
            return ENOMEM
        self.blocks[block] = {"vars": [], "period": 0, "running": False}
        return 0

    def _log_add_op(self, block: int, ident: int) -> int:
        """Variable ``ident`` into ``block`` within 26 bytes of values and ``max_ops`` ops in all."""
        if ident >= len(self.logs):
            return ENOENT
        size = sum(struct.calcsize(STRUCT[self.logs[j][2]]) for j in self.blocks[block]["vars"])
        if size + struct.calcsize(STRUCT[self.logs[ident][2]]) > 26:
            return E2BIG
        if self.ops_used >= self.max_ops:
            return ENOMEM
        self.ops_used += 1
        self.blocks[block]["vars"].append(ident)
        return 0

    def _log_block_command(self, cmd: int, block: int, d: bytes) -> int:
        """DELETE, START (period in 10 ms), START V2 (period in ms, u16) or STOP of an existing block."""
        if cmd == 2:
            self.ops_used -= len(self.blocks.pop(block)["vars"])
        elif cmd == 3:
            self.blocks[block].update(period=d[2] * 10, running=True)
        elif cmd == 8:
            self.blocks[block].update(period=d[2] | (d[3] << 8), running=True)
        else:
            self.blocks[block]["running"] = False
        return 0

    def log_packet(self, block: int, timestamp_ms: int) -> CRTPPacket:
        """The data packet the firmware would send for ``block`` now."""
        values = b"".join(struct.pack(STRUCT[self.logs[i][2]], self.logs[i][3])
                          for i in self.blocks[block]["vars"])
        ts = struct.pack("<I", timestamp_ms)[:3]
        return CRTPPacket(5, 2, bytes([block]) + ts + values)


class ScriptedLink:
    """The link contract over a ScriptedFirmware (or any ``responder(packet) -> [packets]``)."""

    def __init__(self, uri: str = "radio://0/80/2M/E7E7E7E701",
                 responder: Optional[Callable[[CRTPPacket], List[CRTPPacket]]] = None) -> None:
        self.uri = parse_uri(uri)
        self.stats = LinkStatistics()
        self.responder = responder or (lambda p: [])
        self.sent: List[CRTPPacket] = []
        self.downlink: deque = deque()
        self.opened = 0
        self.closed = 0
        self._subs: List[Tuple[int, Optional[int], Callable]] = []

    # contract
    def open(self) -> None:
        self.opened += 1

    def close(self) -> None:
        self.closed += 1

    def send(self, packet: CRTPPacket) -> bool:
        self.sent.append(packet)
        self.stats.record(True)
        self.downlink.extend(self.responder(packet))
        self._deliver_one()
        return True

    def poll(self) -> bool:
        self.stats.record(True)
        self._deliver_one()
        return True

    def subscribe(self, port, channel, callback):
        entry = (port, channel, callback)
        self._subs.append(entry)
        return lambda: self._subs.remove(entry)

    def request(self, packet, match, timeout=1.0, resend_interval=0.2, what=""):
        self._match = match
        self._result = None
        try:
            self.send(packet)
            while self._result is None:
                if not self.downlink:
                    raise LinkTimeout("%s: no answer to %s within %.2f s"
                                      % (self.uri, what or repr(packet), timeout))
                self.poll()
            return self._result
        finally:
            self._match = None

    # helpers
    _match = None
    _result = None

    def push(self, *packets: CRTPPacket) -> None:
        """Queue unsolicited downlink packets (log data, console text)."""
        self.downlink.extend(packets)

    def drain(self) -> None:
        while self.downlink:
            self.poll()

    def raw_sent(self) -> List[str]:
        """Uplink packets as hex with the header as cflib builds it, e.g. '2c 03'."""
        return [p.to_bytes().hex(" ") for p in self.sent]

    def clear(self) -> None:
        self.sent.clear()

    def _deliver_one(self) -> None:
        if not self.downlink:
            return
        packet = self.downlink.popleft()
        if self._match is not None and self._result is None and self._match(packet):
            self._result = packet
        for port, channel, callback in list(self._subs):
            if port == packet.port and (channel is None or channel == packet.channel):
                callback(packet)


def make_crazyflie(protocol_version: int = 12, cache_dir=None, **firmware_options):
    """A connected Crazyflie over a ScriptedLink; returns (cf, link, firmware)."""
    import tempfile

    from crazyflie_driver.protocol.crazyflie import Crazyflie
    if cache_dir is None:  # never the user's real cache
        cache_dir = tempfile.mkdtemp(prefix="toc-cache-")
    firmware = ScriptedFirmware(protocol_version, **firmware_options)
    link = ScriptedLink(responder=firmware.handle)
    cf = Crazyflie("radio://0/80/2M/E7E7E7E701", cache_dir=cache_dir, link=link)
    cf.connect()
    return cf, link, firmware
