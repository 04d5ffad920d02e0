"""The small ports of the simulated firmware: console (0), commander (3), memory (4),
localization (6), generic setpoint (7), supervisor (9), platform (13) and link (15).

Each handler takes the firmware object (for `send`, `profile`, `vehicle` and `state`), the request
header, channel and payload; formats are those of CRTP.md §P2, §P3, §P6, §P8-§P10.
"""
from __future__ import annotations

import logging
import struct
from typing import TYPE_CHECKING, Callable, List

if TYPE_CHECKING:  # pragma: no cover
    from crazyflie_driver.sim.firmware.firmware import SimulatedCrazyflie

_log = logging.getLogger(__name__)

CONSOLE_HEADER = 0x00        # CRTP_HEADER(CONSOLE, 0)
CONSOLE_LINE = 30
LINK_SOURCE = b"Bitcraze Crazyflie".ljust(30, b"\x00")
RPYT = struct.Struct("<fffH")
EIO = 5


class Console:
    """Console text as the firmware sends it: a packet per line or per 30 buffered characters."""

    def __init__(self, send: Callable[[int, bytes], bool]) -> None:
        self._send = send
        self._buffer = bytearray()
        self.history: List[str] = []

    def write(self, text: str) -> None:
        self.history.append(text)
        for ch in text.encode("utf-8", "replace"):
            self._buffer.append(ch)
            if ch == 0x0A or len(self._buffer) >= CONSOLE_LINE:
                self.flush()

    def flush(self) -> None:
        if self._buffer:
            self._send(CONSOLE_HEADER, bytes(self._buffer))
            self._buffer.clear()


def boot_text(device_type: str, firmware_version: str, cpu_id: str, production: bool) -> str:
    lines = ["SYS: ----------------------------",
             "SYS: %s is up and running!" % device_type]
    if production:
        lines.append("SYS: Production release %s" % firmware_version)
    else:
        lines.append("SYS: Build 0:0 (%s) CLEAN" % firmware_version)
    lines += ["SYS: I am 0x%s and I have 1024KB of flash!" % cpu_id,
              "IMU: MPU9250 I2C connection [OK].",
              "SYS: Self test passed!",
              "SYS: Free heap: 21416 bytes"]
    return "".join(line + "\n" for line in lines)


def _call(fn_name: str, fw: "SimulatedCrazyflie", *args) -> None:
    """Call an optional vehicle hook, logging (not raising) a failure inside the physics."""
    fn = getattr(fw.vehicle, fn_name, None)
    if fn is None:
        return
    try:
        fn(*args)
    except Exception:
        _log.exception("vehicle.%s failed", fn_name)


def commander(fw: "SimulatedCrazyflie", header: int, channel: int, data: bytes) -> None:
    """Port 3: the legacy RPYT setpoint (14 bytes). No reply."""
    if channel != 0 or len(data) < RPYT.size:
        return
    roll, pitch, yaw, thrust = RPYT.unpack_from(data)
    fw.state.last_setpoint = (roll, pitch, yaw, thrust)
    fw.state.setpoints += 1
    _call("set_rpyt", fw, roll, pitch, yaw, thrust)


def generic_setpoint(fw: "SimulatedCrazyflie", header: int, channel: int, data: bytes) -> None:
    """Port 7: type 0 stops the motors; other types are recorded and offered to the vehicle."""
    if channel != 0 or not data:
        return
    kind = data[0]
    fw.state.last_generic = (kind, bytes(data[1:]))
    if kind == 0:
        fw.state.setpoints += 1
        fw.state.last_setpoint = (0.0, 0.0, 0.0, 0)
        if hasattr(fw.vehicle, "stop_motors"):
            _call("stop_motors", fw)
        else:
            _call("set_rpyt", fw, 0.0, 0.0, 0.0, 0)
    else:
        _call("set_generic_setpoint", fw, kind, bytes(data[1:]))


def memory(fw: "SimulatedCrazyflie", header: int, channel: int, data: bytes) -> None:
    """Port 4: a Crazyflie without memories (`[1]` -> `[1, 0]`)."""
    if not data:
        return
    if channel == 0:
        if data[0] == 1:
            fw.send(header, b"\x01\x00")
        elif data[0] == 2 and len(data) >= 2:
            fw.send(header, bytes(data[:2]))  # short info reply: no such memory
    elif channel in (1, 2) and len(data) >= 5:
        fw.send(header, bytes(data[:5]) + bytes([EIO]))


def localization(fw: "SimulatedCrazyflie", header: int, channel: int, data: bytes) -> None:
    """Port 6: external position (recorded) and the emergency stop (ch 1 types 3 and 4)."""
    if channel == 0 and len(data) >= 12:
        fw.state.external_position = struct.unpack_from("<fff", data)
        _call("set_external_position", fw, *fw.state.external_position)
    elif channel == 1 and data:
        if data[0] == 3:
            fw.emergency_stop("localization emergency stop")
        elif data[0] == 4:
            fw.state.estop_watchdog = fw.now()


def supervisor(fw: "SimulatedCrazyflie", header: int, channel: int, data: bytes) -> None:
    """Port 9 (protocol 12): state queries on ch 0, arm / recover / e-stop on ch 1."""
    if not data:
        return
    cmd = data[0]
    if channel == 0:
        bits = fw.supervisor_bits()
        if 0x01 <= cmd <= 0x0B:
            fw.send(header, bytes([0x80 | cmd, (bits >> (cmd - 1)) & 1]))
        elif cmd == 0x0C:
            fw.send(header, struct.pack("<BH", 0x8C, bits))
    elif channel == 1:
        if cmd == 1 and len(data) >= 2:
            fw.state.armed = bool(data[1])
            fw.send(header, bytes([0x81, 1, int(fw.state.armed)]))
        elif cmd == 2:
            fw.send(header, bytes([0x82, 1, 1]))
        elif cmd == 3:
            fw.emergency_stop("supervisor emergency stop")
        elif cmd == 4:
            fw.state.estop_watchdog = fw.now()


def platform(fw: "SimulatedCrazyflie", header: int, channel: int, data: bytes) -> None:
    """Port 13: protocol version, firmware version, device type; ch 0 platform commands."""
    if not data:
        return
    cmd, profile = data[0], fw.profile
    if channel == 1:
        if cmd == 0:
            fw.send(header, struct.pack("<Bi", 0, profile.protocol_version))
        elif cmd == 1:
            fw.send(header, b"\x01" + profile.firmware_version.encode("ascii")[:29])
        elif cmd == 2 and profile.device_type_query:
            fw.send(header, b"\x02" + profile.device_type.encode("ascii")[:29])
    elif channel == 0:
        if not profile.device_type_query:  # the 2016 firmware: continuous wave only, echoed
            if cmd == 0:
                fw.send(header, bytes(data))
            return
        if cmd == 1 and len(data) >= 2:
            fw.state.armed = bool(data[1])
            fw.send(header, bytes([1, 1, int(fw.state.armed)]))
        elif cmd == 2:
            fw.send(header, bytes([2, 1, 1]))
        elif cmd == 3:
            fw.send(header, b"")
        else:
            fw.send(header, bytes(data))


def link(fw: "SimulatedCrazyflie", header: int, channel: int, data: bytes) -> None:
    """Port 15: echo (unchanged), source string (30 bytes), sink; ch 3 (null) dropped."""
    if channel == 0:
        fw.send(header, bytes(data))
    elif channel == 1:
        fw.send(header, LINK_SOURCE)
