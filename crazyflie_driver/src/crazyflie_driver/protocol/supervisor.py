"""Arming, crash recovery, supervisor state and the emergency-stop watchdog.

From protocol 12 these live on the supervisor port (9); before, arming and crash recovery were
platform commands (13:0) and the e-stop and its watchdog were localization packets (6:1). The
watchdog is armed by the first keep-alive: from then on, a second without one stops the motors
for good (until the Crazyflie is restarted), so a host that dies cannot leave it flying.
"""
from __future__ import annotations

import struct
from typing import Dict, NamedTuple

from crazyflie_driver.crtp.packet import PORT_PLATFORM, PORT_SUPERVISOR, CRTPPacket
from crazyflie_driver.errors import NotSupported, ProtocolError
from crazyflie_driver.protocol.commander import SUPERVISOR_FROM, emergency_stop_packet
from crazyflie_driver.protocol.localization import emergency_stop_watchdog_packet_legacy

CH_INFO = 0
CH_COMMAND = 1
CMD_ARM = 1
CMD_RECOVER = 2
CMD_EMERGENCY_STOP = 3
CMD_WATCHDOG = 4
INFO_BITFIELD = 0x0C
REPLY_FLAG = 0x80
PLATFORM_CH_COMMAND = 0
#: Protocol versions from which the platform port can arm (2023.06) and recover from a crash (2024.10).
PLATFORM_ARM_FROM = 6
PLATFORM_RECOVER_FROM = 8
#: Without a keep-alive for this long the firmware stops the motors (ms).
WATCHDOG_TIMEOUT_MS = 1000
#: Keep-alives go out this often (s): four chances per watchdog period.
WATCHDOG_KEEPALIVE_PERIOD_S = 0.25

STATE_BITS = ("can_arm", "armed", "auto_arm", "can_fly", "flying", "tumbled", "locked", "crashed",
              "hl_active", "hl_trajectory_finished", "hl_disabled", "deck_fault")


class SupervisorState(NamedTuple):
    """The supervisor's bit field and its decoding."""

    bits: int
    flags: Dict[str, bool]


def decode_state(bits: int) -> SupervisorState:
    return SupervisorState(bits, {name: bool(bits >> i & 1) for i, name in enumerate(STATE_BITS)})


def arm_packet(do_arm: bool, protocol_version: int) -> CRTPPacket:
    if protocol_version >= SUPERVISOR_FROM:
        return CRTPPacket(PORT_SUPERVISOR, CH_COMMAND, bytes([CMD_ARM, bool(do_arm)]))
    if protocol_version >= PLATFORM_ARM_FROM:
        return CRTPPacket(PORT_PLATFORM, PLATFORM_CH_COMMAND, bytes([CMD_ARM, bool(do_arm)]))
    raise NotSupported("arming needs protocol version %d or later (this Crazyflie speaks %d; it arms itself)"
                       % (PLATFORM_ARM_FROM, protocol_version))


def crash_recovery_packet(protocol_version: int) -> CRTPPacket:
    if protocol_version >= SUPERVISOR_FROM:
        return CRTPPacket(PORT_SUPERVISOR, CH_COMMAND, bytes([CMD_RECOVER]))
    if protocol_version >= PLATFORM_RECOVER_FROM:
        return CRTPPacket(PORT_PLATFORM, PLATFORM_CH_COMMAND, bytes([CMD_RECOVER]))
    raise NotSupported("crash recovery needs protocol version %d or later (this Crazyflie speaks %d)"
                       % (PLATFORM_RECOVER_FROM, protocol_version))


def watchdog_packet(protocol_version: int) -> CRTPPacket:
    """The emergency-stop watchdog keep-alive."""
    if protocol_version >= SUPERVISOR_FROM:
        return CRTPPacket(PORT_SUPERVISOR, CH_COMMAND, bytes([CMD_WATCHDOG]))
    return emergency_stop_watchdog_packet_legacy()


def state_request_packet() -> CRTPPacket:
    return CRTPPacket(PORT_SUPERVISOR, CH_INFO, bytes([INFO_BITFIELD]))


class Supervisor:
    """Arming, recovery, state and e-stop for one Crazyflie over the link's ``send``/``request``."""

    def __init__(self, send, request, protocol_version: int = -1, timeout: float = 1.0, label: str = "") -> None:
        self._send = send
        self._request = request
        self.protocol_version = protocol_version
        self.timeout = timeout
        self.label = label

    def _command(self, packet: CRTPPacket, what: str) -> bytes:
        if packet.port == PORT_SUPERVISOR:
            want = bytes([REPLY_FLAG | packet.data[0]])
            match = (lambda p: p.port == PORT_SUPERVISOR and p.channel == CH_COMMAND and p.data[:1] == want)
        else:
            want = packet.data[:1]
            match = (lambda p: p.port == PORT_PLATFORM and p.channel == PLATFORM_CH_COMMAND and p.data[:1] == want)
        reply = self._request(packet, match=match, timeout=self.timeout, what=what)
        if len(reply.data) < 2:
            raise ProtocolError("%s: %s reply too short: %s" % (self.label, what, reply.data.hex(' ')))
        return reply.data

    def arm(self, do_arm: bool = True) -> bool:
        """Arm (or disarm); True when the Crazyflie reports success."""
        return bool(self._command(arm_packet(do_arm, self.protocol_version), "arming request")[1])

    def recover(self) -> bool:
        """Leave the crashed state; True when the Crazyflie reports success."""
        return bool(self._command(crash_recovery_packet(self.protocol_version), "crash recovery request")[1])

    def state(self) -> SupervisorState:
        """The supervisor's state bits (protocol 12 and later)."""
        if self.protocol_version < SUPERVISOR_FROM:
            raise NotSupported("the supervisor state needs protocol version %d or later (this Crazyflie speaks %d)"
                               % (SUPERVISOR_FROM, self.protocol_version))
        want = bytes([REPLY_FLAG | INFO_BITFIELD])
        reply = self._request(state_request_packet(),
                              match=lambda p: p.port == PORT_SUPERVISOR and p.channel == CH_INFO and p.data[:1] == want,
                              timeout=self.timeout, what="supervisor state (9:0)")
        if len(reply.data) < 3:
            raise ProtocolError("%s: supervisor state reply too short: %s" % (self.label, reply.data.hex(' ')))
        return decode_state(struct.unpack_from("<H", reply.data, 1)[0])

    def keep_alive(self) -> bool:
        """One watchdog keep-alive (the first one arms the watchdog); True when acked."""
        return self._send(watchdog_packet(self.protocol_version))

    def emergency_stop(self) -> bool:
        """Motors off until the Crazyflie is restarted; True when acked."""
        return self._send(emergency_stop_packet(self.protocol_version))
