"""The original driver's raw CRTP pass-through, both ways, checked without ROS.

``send_packet`` (``crazyflie_driver/sendPacket``: ``crtpPacket`` = ``size``, ``header``, ``data[30]``)
hands the Crazyflie a packet the server does not interpret; ``packets`` (with
``enable_logging_packets``) publishes what the Crazyflie sends on ports nothing in the server reads.

What a raw packet may not do: steer the motors (setpoints, high-level commands, stops and emergency
stops: ``crtp.packet.MOTOR_COMMAND_PORTS``) or switch the Crazyflie (the radio chip's link-control
packets: reboot, power). The server supervises those: it must know a Crazyflie flies to land it on a
reaction or at shutdown, and a reboot sets up its logging again. The services that do them are named
in the refusal; everything else goes through as it is.
"""
from __future__ import annotations

from typing import Sequence, Tuple

from crazyflie_driver.crtp.packet import MAX_PAYLOAD, CRTPPacket, is_motor_command, is_null_header
from crazyflie_driver.errors import CommandRejected, CommandValueError

SEND_PACKET_SERVICE = "send_packet"
PACKETS_TOPIC = "packets"


def raw_packet(header: int, size: int, data: Sequence[int]) -> CRTPPacket:
    """The packet a ``crtpPacket`` describes: its header byte and the first ``size`` bytes of ``data``.
    CommandValueError for a malformed one, CommandRejected for one the server must not let through."""
    if not 0 <= header <= 0xFF:
        raise CommandValueError("send_packet: header must be a byte (0..255), got %r" % (header,))
    if not 0 <= size <= MAX_PAYLOAD:
        raise CommandValueError("send_packet: size must be 0..%d (the CRTP payload), got %r" % (MAX_PAYLOAD, size))
    if size > len(data):
        raise CommandValueError("send_packet: size %d but only %d data bytes given" % (size, len(data)))
    payload = bytes(int(b) & 0xFF for b in data[:size])
    if is_null_header(header):
        raise CommandRejected("send_packet refused: header 0x%02X is the radio's link control (reboot, power); "
                              "use the reboot, power_off and power_on services" % header)
    if is_motor_command(bytes([header]) + payload):
        raise CommandRejected("send_packet refused: port %d steers the motors, which the server must know to "
                              "supervise the flight; use cmd_vel, cmd_position, cmd_full_state, the takeoff, "
                              "land, go_to and emergency services instead" % (header >> 4))
    return CRTPPacket(header >> 4, header & 0x03, payload)


def packet_fields(packet: CRTPPacket) -> Tuple[int, int, bytes]:
    """``(size, header, data)`` of a ``crtpPacket`` message: ``data`` padded to MAX_PAYLOAD bytes."""
    data = bytes(packet.data[:MAX_PAYLOAD])
    return len(data), packet.header, data + bytes(MAX_PAYLOAD - len(data))
