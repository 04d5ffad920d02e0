"""Port 4 of the simulated firmware: the memory table, the EEPROM configuration block and the decks'
one-wire memories, byte for byte, and radio settings that take effect at the next boot."""
from __future__ import annotations

import struct
import zlib

import pytest

from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from crazyflie_driver.sim.crtp.memory_port import ONE_WIRE_SIZE, maxim_crc8
from support.sim_doubles import FakeVehicle, drain

ADDR = b"\xe7\xe7\xe7\xe7\x01"
MEM = 0x40            # port 4, channels 0 info, 1 read, 2 write


def make(**kw):
    cf = SimulatedCrazyflie(ADDR, FakeVehicle(), **kw)
    drain(cf)
    return cf


def one(cf, raw: bytes) -> bytes:
    cf.handle_crtp(raw)
    replies = drain(cf)
    assert len(replies) == 1, replies
    return replies[0]


def details(cf, ident):
    return one(cf, bytes([MEM, 2, ident]))


def read(cf, ident, address, length):
    return one(cf, bytes([MEM | 1, ident]) + struct.pack("<IB", address, length))


def write(cf, ident, address, data):
    return one(cf, bytes([MEM | 2, ident]) + struct.pack("<I", address) + data)


@pytest.mark.parametrize("fw,count", [("current", 2), ("2016.02", 1)])
def test_table_lists_the_eeprom_first_then_the_trajectory_memory(fw, count):
    cf = make(firmware=fw)
    assert one(cf, bytes([MEM, 1])) == bytes([MEM, 1, count])
    assert details(cf, 0) == bytes([MEM, 2, 0, 0x00]) + struct.pack("<I", 8192) + bytes(8)
    if count == 2:
        assert details(cf, 1) == bytes([MEM, 2, 1, 0x12]) + struct.pack("<I", 4096) + bytes(8)
    assert details(cf, count) == bytes([MEM, 2, count])          # past the end: the short reply


def test_eeprom_holds_a_valid_version_1_block_with_the_crazyflies_address():
    cf = make()
    reply = read(cf, 0, 0, 21)
    assert reply[:7] == bytes([MEM | 1, 0]) + struct.pack("<I", 0) + b"\x00"
    block = reply[7:]
    assert block[:5] == b"0xBC\x01" and block[5:7] == bytes([80, 2])
    assert block[15:20] == b"\xe7\x01\xe7\xe7\xe7"                      # upper byte, then the low u32 LE
    assert block[20] == sum(block[:20]) % 256
    assert cb.decode(block) == cb.ConfigBlock(80, 2, 0.0, 0.0, 0xE7E7E7E701)
    assert read(cf, 0, 8190, 3)[6] == 5                                 # past the end: EIO


def test_written_channel_and_address_take_effect_at_the_next_boot_and_survive_it():
    medium = LocalMedium()
    cf = make()
    medium.add_crazyflie(cf, 20, 2)
    assert cb.decode(read(cf, 0, 0, 21)[7:]).channel == 20              # programmed for its slot
    new = cb.encode(cb.ConfigBlock(channel=42, datarate=1, address=0xE7E7E7E7AA, roll_trim=1.5))
    assert write(cf, 0, 0, new[:16])[6] == 0 and write(cf, 0, 16, new[16:])[6] == 0
    assert medium.crazyflie(20, 2, ADDR) is cf                          # still there until a reboot
    cf.reboot()
    assert medium.crazyflie(20, 2, ADDR) is None
    assert medium.crazyflie(42, 1, b"\xe7\xe7\xe7\xe7\xaa") is cf
    assert (cf.radio_channel, cf.radio_datarate, cf.address) == (42, 1, b"\xe7\xe7\xe7\xe7\xaa")
    drain(cf)
    assert read(cf, 0, 0, 21)[7:] == new                                # the EEPROM keeps its bytes


def test_a_broken_block_boots_on_the_defaults_and_a_taken_slot_is_refused():
    medium = LocalMedium()
    cf, other = make(), SimulatedCrazyflie(b"\xe7\xe7\xe7\xe7\x02", FakeVehicle())
    medium.add_crazyflie(cf, 20, 2)
    medium.add_crazyflie(other, 80, 2)
    block = bytearray(cb.encode(cb.ConfigBlock(channel=80, address=0xE7E7E7E702)))
    write(cf, 0, 0, bytes(block[:21]))
    cf.reboot()                                      # `other` listens there: cf stays where it was
    drain(cf)
    assert medium.crazyflie(20, 2, ADDR) is cf and medium.crazyflie(80, 2, b"\xe7\xe7\xe7\xe7\x02") is other
    block[5] = 30
    write(cf, 0, 0, bytes(block[:21]))                # checksum no longer matches: defaults (80, 2M, E7..E7)
    cf.reboot()
    assert cf.config_block() == cb.ConfigBlock()
    assert medium.crazyflie(80, 2, b"\xe7" * 5) is cf


def test_plugged_decks_come_first_as_one_wire_memories_cflib_can_parse():
    cf = make(decks=("bcFlow2", "bcLighthouse4"))
    assert one(cf, bytes([MEM, 1])) == bytes([MEM, 1, 4])
    info = details(cf, 1)
    assert info[3] == 0x01 and struct.unpack_from("<I", info, 4)[0] == ONE_WIRE_SIZE
    serial = info[8:16]
    assert serial[0] == 0x2D and maxim_crc8(serial[:7]) == serial[7]
    assert details(cf, 2)[3] == 0x00 and details(cf, 3)[3] == 0x12
    image = read(cf, 1, 0, 24)[7:] + read(cf, 1, 24, 24)[7:]
    assert image[0] == 0xEB and image[5:7] == bytes([0xBC, 0x10])
    assert image[7] == zlib.crc32(image[:7]) & 0xFF
    length = image[9]
    elements = image[8:10 + length + 1]
    assert elements[-1] == zlib.crc32(elements[:-1]) & 0xFF
    assert elements[2:] .startswith(bytes([1, 13]) + b"bcLighthouse4")


def test_an_unknown_deck_is_refused_with_the_known_names():
    with pytest.raises(ValueError, match="bcFlow2"):
        make(decks=("bcNoSuchDeck",))


def test_world_config_plugs_decks_and_names_the_known_ones(tmp_path):
    from crazyflie_driver.sim.world_server import load_vehicle_config
    good = tmp_path / "v.yaml"
    good.write_text("- uri: radio://0/80/2M/E7E7E7E701\n  decks: [bcFlow2, bcMultiranger]\n")
    assert load_vehicle_config(str(good))[0]["decks"] == ["bcFlow2", "bcMultiranger"]
    good.write_text("- uri: radio://0/80/2M/E7E7E7E701\n  decks: [bcFlow3]\n")
    with pytest.raises(ValueError, match="decks must be a list of deck names out of bcDWM1000"):
        load_vehicle_config(str(good))


def test_plugged_decks_read_one_in_their_deck_params_and_the_others_zero():
    cf = make(decks=("bcFlow2", "bcLighthouse4"))
    assert cf.params.value("deck.bcFlow2") == 1 and cf.params.value("deck.bcLighthouse4") == 1
    assert cf.params.value("deck.bcMultiranger") == 0
    cf.reboot()
    drain(cf)
    assert cf.params.value("deck.bcFlow2") == 1
    assert make().params.value("deck.bcFlow2") == 0
