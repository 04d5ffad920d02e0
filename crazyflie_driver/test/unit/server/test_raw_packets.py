"""send_packet's checks and the packets topic's fields: raw CRTP both ways, nothing that steers the motors."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp.packet import CRTPPacket, make_header
from crazyflie_driver.errors import CommandRejected, CommandValueError
from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.server.raw_packets import packet_fields, raw_packet
from support.radio_rig import RadioRig


def test_a_raw_packet_goes_as_given_and_comes_back_as_the_original_message_carries_it():
    p = raw_packet(0xFC, 3, list(b"abc") + [9] * 27)          # port 15 channel 0 (echo), 3 of 30 bytes
    assert (p.port, p.channel, p.data) == (15, 0, b"abc")
    size, header, data = packet_fields(CRTPPacket(0, 0, b"SYS: up\n"))
    assert (size, header, len(data), data[:8]) == (8, make_header(0, 0), 30, b"SYS: up\n")


@pytest.mark.parametrize("header, size, data, error, says", [
    (0x3C, 14, [0] * 30, CommandRejected, "port 3 steers the motors"),        # RPYT setpoint
    (0x7C, 1, [0] * 30, CommandRejected, "port 7 steers the motors"),         # generic setpoint
    (0x8C, 1, [0] * 30, CommandRejected, "port 8 steers the motors"),         # high-level commander
    (0x9C, 1, [1] * 30, CommandRejected, "port 9 steers the motors"),         # supervisor (arm, e-stop)
    (0x61, 1, [3] * 30, CommandRejected, "port 6 steers the motors"),         # localization e-stop
    (0xFF, 2, [0xF0, 0x01] + [0] * 28, CommandRejected, "reboot, power_off"),  # nRF system command
    (0x0C, 31, [0] * 31, CommandValueError, "size must be 0..30"),
    (0x0C, 5, [0] * 3, CommandValueError, "only 3 data bytes"),
    (256, 0, [], CommandValueError, "header must be a byte"),
])
def test_what_the_server_supervises_or_cannot_send_is_refused_by_name(header, size, data, error, says):
    with pytest.raises(error, match=says):
        raw_packet(header, size, data)


def test_the_radio_link_hands_packets_nobody_reads_to_its_unclaimed_callback():
    rig = RadioRig()
    cf = Crazyflie(rig.uri, radio_manager=rig.manager, timeout=1.0)
    unclaimed, lines = [], []
    cf.link.on_unclaimed(unclaimed.append)
    cf.console.on_line(lines.append)
    for raw in (CRTPPacket(15, 0, b"echo"), CRTPPacket(0, 0, b"console\n"), CRTPPacket(14, 1, b"dbg")):
        cf.link._dispatch(raw.to_bytes())          # as a round trip's ack payload arrives
    assert [(p.port, p.data) for p in unclaimed] == [(15, b"echo"), (14, b"dbg")]     # not the console's
    assert lines == ["console"]
    cf.link.on_unclaimed(None)
    cf.link._dispatch(CRTPPacket(15, 0, b"again").to_bytes())
    assert len(unclaimed) == 2
