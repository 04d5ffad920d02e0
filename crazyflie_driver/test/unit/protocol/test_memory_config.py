"""MemoryClient's configuration block and deck identification against the simulated firmware's
port 4 (packets through SimulatedCrazyflie.handle_crtp; no world running)."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import ConfigBlockError, LinkTimeout, NotSupported
from crazyflie_driver.protocol.memory import TYPE_EEPROM, TYPE_ONE_WIRE, TYPE_TRAJECTORY, MemoryClient, type_name
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.sim_doubles import FakeVehicle


def client_of(cf):
    def request(packet, match, timeout, what):
        cf.handle_crtp(packet.to_bytes())
        while True:
            raw = cf.pop_outgoing()
            if raw is None:
                raise LinkTimeout("no answer to %s" % what)
            reply = CRTPPacket.from_bytes(raw)
            if match(reply):
                return reply
    return MemoryClient(request, label="cf1")


def test_memories_decks_and_config_block_as_the_firmware_answers():
    cf = SimulatedCrazyflie(b"\xe7\xe7\xe7\xe7\x01", FakeVehicle(), decks=("bcLighthouse4",))
    client = client_of(cf)
    assert [(m.id, m.type, m.size) for m in client.memories()] == [
        (0, TYPE_ONE_WIRE, 112), (1, TYPE_EEPROM, 8192), (2, TYPE_TRAJECTORY, 4096)]
    assert [type_name(m.type) for m in client.memories()] == ["1-wire", "EEPROM", "trajectory"]
    assert [(d.vid, d.pid, d.name, d.revision) for d in client.decks()] == [(0xBC, 0x10, "bcLighthouse4", "A")]
    assert client.read_config() == cb.ConfigBlock(80, 2, 0.0, 0.0, 0xE7E7E7E701)
    client.write_config(cb.ConfigBlock(7, 0, 1.0, 0.0, 0xE7E7E7E7E7))
    assert client.read_config() == cb.ConfigBlock(7, 0, 1.0, 0.0, 0xE7E7E7E7E7)
    assert cf.radio_channel == 80                     # in force only after a reboot
    cf.reboot()
    assert (cf.radio_channel, cf.radio_datarate, cf.address) == (7, 0, b"\xe7" * 5)


def test_a_broken_block_is_reported_and_a_bad_value_is_refused_before_any_write():
    cf = SimulatedCrazyflie(b"\xe7\xe7\xe7\xe7\x01", FakeVehicle())
    client = client_of(cf)
    cf.eeprom.data[5] ^= 0xFF
    with pytest.raises(ConfigBlockError, match="checksum"):
        client.read_config()
    before = bytes(cf.eeprom.data[:21])
    with pytest.raises(ConfigBlockError, match="channel 200"):
        client.write_config(cb.ConfigBlock(channel=200))
    assert bytes(cf.eeprom.data[:21]) == before


def test_no_eeprom_is_not_supported():
    client = MemoryClient(lambda *a, **k: CRTPPacket(4, 0, b"\x01\x00"), label="cf9")
    with pytest.raises(NotSupported, match="no EEPROM"):
        client.read_config()
