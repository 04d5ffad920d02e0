"""The small ports of the simulated firmware: console (0), commander (3), memory (4),
localization (6), generic setpoint (7), supervisor (9), platform (13) and link (15).

Each ``*_port`` function builds a handler ``(header, channel, payload) -> None`` from the narrow
things that port needs: ``send`` for replies, the ``SimState`` record it updates, ``vehicle_hook`` for
the vehicle's optional hooks, and callables for the rest. Packet formats: docs/protocol.md.
"""
from __future__ import annotations

import logging
import struct
from typing import Any, Callable, List, Tuple

from crazyflie_driver.sim.crtp import localization_decode as loc
from crazyflie_driver.sim.crtp.setpoint_decode import FirmwareAssert, decode_meta, decode_setpoint
from crazyflie_driver.sim.crtp.state import SimState

_log = logging.getLogger(__name__)

CONSOLE_HEADER = 0x00        # CRTP_HEADER(CONSOLE, 0)
CONSOLE_LINE = 30
LINK_SOURCE = b"Bitcraze Crazyflie".ljust(30, b"\x00")
RPYT = struct.Struct("<fffH")
EIO = 5

Handler = Callable[[int, int, bytes], None]
Send = Callable[[int, bytes], bool]
VehicleHook = Callable[..., bool]       # (hook name, *args) -> whether the vehicle has that hook
Request = Callable[[bool], Tuple[bool, bool]]   # a supervisor request -> (success, resulting state)


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


def vehicle_hook(vehicle: Any) -> VehicleHook:
    """``hook(name, *args)`` calls the vehicle's optional method ``name``, logging (not raising) a
    failure inside the physics; returns False when the vehicle has no such method."""
    def hook(name: str, *args) -> bool:
        fn = getattr(vehicle, name, None)
        if fn is None:
            return False
        try:
            fn(*args)
        except Exception:
            _log.exception("vehicle.%s failed", name)
        return True
    return hook


def commander_port(state: SimState, hook: VehicleHook) -> Handler:
    """Port 3: the legacy RPYT setpoint (14 bytes). No reply."""
    def handle(header: int, channel: int, data: bytes) -> None:
        if channel != 0 or len(data) < RPYT.size:
            return
        roll, pitch, yaw, thrust = RPYT.unpack_from(data)
        state.last_setpoint = (roll, pitch, yaw, thrust)
        state.setpoints += 1
        hook("set_rpyt", roll, pitch, yaw, thrust)
    return handle


def generic_setpoint_port(state: SimState, hook: VehicleHook, halt: Callable[[str, bytes], None]) -> Handler:
    """Port 7: generic setpoints (ch 0) and notify-setpoints-stop (ch 1). No reply.

    A packet whose length the firmware asserts calls ``halt(reason, packet)``, as the assert halts
    the real Crazyflie.
    """
    def handle(header: int, channel: int, data: bytes) -> None:
        try:
            if channel == 0:
                sp = decode_setpoint(data)
                state.last_generic = (sp.kind, bytes(data[1:]))
                state.setpoints += 1
                if sp.is_stop:          # stop and unknown types: the zeroed setpoint, motors off
                    state.last_setpoint = (0.0, 0.0, 0.0, 0)
                    if not hook("stop_motors"):
                        hook("set_rpyt", 0.0, 0.0, 0.0, 0)
                else:
                    hook("set_setpoint", sp)
            elif channel == 1:
                if decode_meta(data) is not None:
                    state.setpoint_stop_notices += 1
                    hook("notify_setpoint_stop")
        except FirmwareAssert as e:
            halt("port 7 channel %d: %s" % (channel, e), bytes([header]) + bytes(data))
    return handle


def localization_port(state: SimState, hook: VehicleHook, emergency_stop: Callable[[str], None],
                      now: Callable[[], float], my_id: int) -> Handler:
    """Port 6: external position/pose (single, and packed items matched by ``my_id``, the radio
    address's low byte) for the onboard estimator; the emergency stop and its watchdog (ch 1 types
    3 and 4). No reply."""
    def handle(header: int, channel: int, data: bytes) -> None:
        measurement = None
        if channel == loc.CH_POSITION:
            measurement = loc.decode_position(data)
        elif channel == loc.CH_POSITION_PACKED:
            measurement, _ = loc.decode_packed_positions(data, my_id)
        elif channel == loc.CH_GENERIC and data:
            kind = data[0]
            if kind == loc.EMERGENCY_STOP:
                emergency_stop("localization emergency stop")
            elif kind == loc.EMERGENCY_STOP_WATCHDOG:
                state.estop_watchdog = now()
            elif kind == loc.EXT_POSE:
                measurement = loc.decode_pose(data[1:])
            elif kind == loc.EXT_POSE_PACKED:
                measurement, _ = loc.decode_packed_poses(data[1:], my_id)
        if measurement is not None:
            state.external_position = measurement.position
            state.external_measurements += 1
            hook("external_measurement", measurement.position, measurement.quaternion)
    return handle


def _flags(result: Tuple[bool, bool]) -> bytes:
    """An (success, state) answer of arm or recover as the two bytes the firmware sends."""
    return bytes(int(v) for v in result)


def supervisor_port(state: SimState, send: Send, supervisor_bits: Callable[[], int], arm: Request,
                    recover: Callable[[], Tuple[bool, bool]], emergency_stop: Callable[[str], None],
                    now: Callable[[], float]) -> Handler:
    """Port 9 (protocol 12): state queries on ch 0, arm / recover / e-stop on ch 1.

    ``arm(do_arm)`` and ``recover()`` return (success, armed) and (success, not crashed)."""
    return _SupervisorPort(state, send, supervisor_bits, arm, recover, emergency_stop, now).handle


class _SupervisorPort:
    def __init__(self, state: SimState, send: Send, supervisor_bits: Callable[[], int], arm: Request,
                 recover: Callable[[], Tuple[bool, bool]], emergency_stop: Callable[[str], None],
                 now: Callable[[], float]) -> None:
        self._state = state
        self._send = send
        self._supervisor_bits = supervisor_bits
        self._arm = arm
        self._recover = recover
        self._emergency_stop = emergency_stop
        self._now = now

    def handle(self, header: int, channel: int, data: bytes) -> None:
        if not data:
            return
        if channel == 0:
            self._query(header, data[0])
        elif channel == 1:
            self._command(header, data)

    def _query(self, header: int, cmd: int) -> None:
        """Commands 1..11 ask for one state bit (bit ``cmd - 1``), 12 for all of them (u16)."""
        bits = self._supervisor_bits()
        if 0x01 <= cmd <= 0x0B:
            self._send(header, bytes([0x80 | cmd, (bits >> (cmd - 1)) & 1]))
        elif cmd == 0x0C:
            self._send(header, struct.pack("<BH", 0x8C, bits))

    def _command(self, header: int, data: bytes) -> None:
        """1 arm/disarm (answered), 2 recover (answered), 3 emergency stop, 4 its watchdog."""
        cmd = data[0]
        if cmd == 1 and len(data) >= 2:
            self._send(header, bytes([0x81]) + _flags(self._arm(bool(data[1]))))
        elif cmd == 2:
            self._send(header, bytes([0x82]) + _flags(self._recover()))
        elif cmd == 3:
            self._emergency_stop("supervisor emergency stop")
        elif cmd == 4:
            self._state.estop_watchdog = self._now()


def platform_port(send: Send, protocol_version: int, firmware_version: str, device_type: str,
                  device_type_query: bool, arm: Request, recover: Callable[[], Tuple[bool, bool]]) -> Handler:
    """Port 13: protocol version, firmware version, device type; ch 0 platform commands (arming and
    crash recovery answer as on port 9).

    ``device_type_query`` false plays the 2016 firmware: no device type, and on ch 0 only the
    continuous-wave command, echoed."""
    return _PlatformPort(send, protocol_version, firmware_version, device_type, device_type_query, arm,
                         recover).handle


class _PlatformPort:
    def __init__(self, send: Send, protocol_version: int, firmware_version: str, device_type: str,
                 device_type_query: bool, arm: Request, recover: Callable[[], Tuple[bool, bool]]) -> None:
        self._send = send
        self._protocol_version = protocol_version
        self._firmware_version = firmware_version
        self._device_type = device_type
        self._device_type_query = device_type_query
        self._arm = arm
        self._recover = recover

    def handle(self, header: int, channel: int, data: bytes) -> None:
        if not data:
            return
        if channel == 1:
            self._version(header, data[0])
        elif channel == 0 and self._device_type_query:
            self._platform_command(header, data)
        elif channel == 0 and data[0] == 0:
            self._send(header, bytes(data))     # the 2016 firmware: continuous wave only, echoed

    def _version(self, header: int, cmd: int) -> None:
        """0 protocol version (i32), 1 firmware version, 2 device type (text, at most 29 bytes)."""
        if cmd == 0:
            self._send(header, struct.pack("<Bi", 0, self._protocol_version))
        elif cmd == 1:
            self._send(header, b"\x01" + self._firmware_version.encode("ascii")[:29])
        elif cmd == 2 and self._device_type_query:
            self._send(header, b"\x02" + self._device_type.encode("ascii")[:29])

    def _platform_command(self, header: int, data: bytes) -> None:
        """1 arm/disarm and 2 recover as on port 9, 3 answered empty, anything else echoed."""
        cmd = data[0]
        if cmd == 1 and len(data) >= 2:
            self._send(header, bytes([1]) + _flags(self._arm(bool(data[1]))))
        elif cmd == 2:
            self._send(header, bytes([2]) + _flags(self._recover()))
        elif cmd == 3:
            self._send(header, b"")
        else:
            self._send(header, bytes(data))


def link_port(send: Send) -> Handler:
    """Port 15: echo (unchanged), source string (30 bytes), sink; ch 3 (null) dropped."""
    def handle(header: int, channel: int, data: bytes) -> None:
        if channel == 0:
            send(header, bytes(data))
        elif channel == 1:
            send(header, LINK_SOURCE)
    return handle
