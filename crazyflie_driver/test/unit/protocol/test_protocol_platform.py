"""Platform detection packet by packet: 15:1 magic, then 13:1 protocol version."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import LinkTimeout
from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.protocol.platform import Platform, toc_version
from support.scripted_link import ScriptedFirmware, ScriptedLink


def test_asks_source_then_version_current_firmware():
    link = ScriptedLink(responder=lambda p: {
        "fd 00": [CRTPPacket(15, 1, b"Bitcraze Crazyflie" + bytes(12))],
        "dd 00": [CRTPPacket(13, 1, bytes([0, 12, 0, 0, 0]))],
    }.get(p.to_bytes().hex(" "), []))
    assert Platform(link).detect_protocol_version() == 12
    assert link.raw_sent() == ["fd 00", "dd 00"]


def test_version_from_single_byte_reply():
    """cflib reads byte 1 only; a short reply still gives the version."""
    link = ScriptedLink(responder=lambda p: {
        "fd 00": [CRTPPacket(15, 1, b"Bitcraze Crazyflie" + bytes(12))],
        "dd 00": [CRTPPacket(13, 1, bytes([0, 2]))],
    }.get(p.to_bytes().hex(" "), []))
    assert Platform(link).detect_protocol_version() == 2


def test_no_magic_means_minus_one_and_no_version_query():
    link = ScriptedLink(responder=lambda p: [CRTPPacket(15, 1, bytes(30))] if p.port == 15 else [])
    assert Platform(link).detect_protocol_version() == -1
    assert link.raw_sent() == ["fd 00"]


def test_unrelated_downlink_is_not_taken_for_the_reply():
    link = ScriptedLink(responder=lambda p: {
        "fd 00": [CRTPPacket(0, 0, b"SYS: hello\n"), CRTPPacket(15, 0, b"x"),
                  CRTPPacket(15, 1, b"Bitcraze Crazyflie" + bytes(12))],
        "dd 00": [CRTPPacket(13, 0, b"\x00"), CRTPPacket(13, 1, bytes([1, 0x32])),
                  CRTPPacket(13, 1, bytes([0, 7, 0, 0, 0]))],
    }.get(p.to_bytes().hex(" "), []))
    assert Platform(link).detect_protocol_version() == 7


@pytest.mark.parametrize("version, expected", [(-1, 1), (2, 1), (3, 1), (4, 2), (12, 2)])
def test_toc_generation(version, expected):
    assert toc_version(version) == expected


@pytest.mark.parametrize("version", [2, 12])
def test_connect_sets_version_on_every_client(version):
    firmware = ScriptedFirmware(version)
    link = ScriptedLink(responder=firmware.handle)
    cf = Crazyflie("radio://0/80/2M/E7E7E7E701", link=link)
    cf.connect()
    assert link.opened == 1
    assert cf.protocol_version == version
    assert cf.params.protocol_version == cf.log.protocol_version == version
    assert cf.toc_version == (2 if version >= 4 else 1)


def test_firmware_version_query():
    firmware = ScriptedFirmware(12)
    link = ScriptedLink(responder=firmware.handle)
    assert Platform(link).firmware_version() == "2026.04"
    assert link.raw_sent() == ["dd 01"]


def test_silent_crazyflie_times_out_naming_uri_and_step_and_closes_link():
    firmware = ScriptedFirmware(12)
    firmware.silent_ports.add(15)
    link = ScriptedLink("radio://0/80/2M/E7E7E7E702", responder=firmware.handle)
    cf = Crazyflie("radio://0/80/2M/E7E7E7E702", link=link)
    with pytest.raises(LinkTimeout) as info:
        cf.connect()
    assert "radio://0/80/2M/E7E7E7E702" in str(info.value)
    assert "link source query" in str(info.value)
    assert link.closed == 1
