"""Log blocks packet by packet: reset, create V1/V2, start periods, data decoding, limits, errors."""
from __future__ import annotations

import struct

import pytest

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import LogConfigError, ProtocolError, UnknownName
from support.scripted_link import make_crazyflie


def control_packets(link):
    return [p.to_bytes().hex(" ") for p in link.sent if p.port == 5 and p.channel == 1]


def test_v2_create_and_start_on_the_wire():
    cf, link, fw = make_crazyflie(12)
    cf.log.fetch_toc()
    cf.log.reset()
    received = []
    block = cf.log.create_block(["acc.x", "pm.vbat"], 100, lambda ts, v: received.append((ts, v)))
    # acc.x is id 0, pm.vbat id 3, both float (code 7): type byte 0x77
    assert control_packets(link) == ["5d 05", "5d 06 01 77 00 00 77 03 00", "5d 03 01 0a"]
    assert block.ident == 1 and block.started
    link.push(fw.log_packet(1, 0x123456))
    link.drain()
    assert received == [(0x123456, [pytest.approx(0.01), pytest.approx(3.95)])]


def test_v1_create_uses_8_bit_ids():
    cf, link, fw = make_crazyflie(2)
    cf.log.create_block(["stab.thrust", "radio.rssi"], 10, lambda ts, v: None)
    assert control_packets(link) == ["5d 00 01 22 0b 11 09", "5d 03 01 01"]
    assert fw.blocks[1]["period"] == 10


def test_all_eight_types_decode():
    cf, link, fw = make_crazyflie(12)
    names = ["radio.rssi", "stab.thrust", "motor.m1", "pos.dx", "pos.dy", "pos.dz",
             "acc.z", "kf.q"]
    received = []
    cf.log.create_block(names, 20, lambda ts, v: received.append(v))
    link.push(fw.log_packet(1, 5))
    link.drain()
    assert received == [[42, 40000, 123456, -5, -300, -70000, 1.0, 0.25]]
    assert [type(v) for v in received[0]] == [int] * 6 + [float] * 2


def test_timestamp_is_24_bit_little_endian():
    cf, link, fw = make_crazyflie(12)
    stamps = []
    cf.log.create_block(["pm.vbat"], 100, lambda ts, v: stamps.append(ts))
    link.push(CRTPPacket(5, 2, bytes([1, 0x01, 0x02, 0xFF]) + struct.pack("<f", 4.0)))
    link.drain()
    assert stamps == [0xFF0201]


def test_data_for_other_or_short_blocks_is_ignored():
    cf, link, fw = make_crazyflie(12)
    got = []
    cf.log.create_block(["pm.vbat"], 100, lambda ts, v: got.append(v))
    link.push(CRTPPacket(5, 2, bytes([9, 0, 0, 0, 1, 2, 3, 4])),
              CRTPPacket(5, 2, bytes([1, 0, 0, 0, 1])))
    link.drain()
    assert got == []


def test_a_failing_callback_does_not_break_the_link():
    cf, link, fw = make_crazyflie(12)
    def boom(ts, v):
        raise RuntimeError("user bug")
    cf.log.create_block(["pm.vbat"], 100, boom)
    link.push(fw.log_packet(1, 1))
    link.drain()  # no exception


@pytest.mark.parametrize("period, start", [(10, "5d 03 01 01"), (2550, "5d 03 01 ff"),
                                           (1000, "5d 03 01 64"), (25, "5d 03 01 02")])
def test_start_period_in_10_ms_units(period, start):
    cf, link, fw = make_crazyflie(7)
    cf.log.create_block(["pm.vbat"], period, lambda ts, v: None)
    assert control_packets(link)[-1] == start


def test_start_v2_for_periods_start_cannot_express():
    cf, link, fw = make_crazyflie(12)
    cf.log.create_block(["pm.vbat"], 5, lambda ts, v: None)
    cf.log.create_block(["acc.x"], 5000, lambda ts, v: None)
    assert control_packets(link)[1] == "5d 08 01 05 00"
    assert control_packets(link)[3] == "5d 08 02 88 13"
    assert fw.blocks[2]["period"] == 5000


@pytest.mark.parametrize("period", [0, 5, 2551, 5000])
def test_period_out_of_range_on_older_firmware(period):
    cf, link, fw = make_crazyflie(7)
    with pytest.raises(LogConfigError, match="10..2550 ms"):
        cf.log.create_block(["pm.vbat"], period, lambda ts, v: None)
    assert control_packets(link) == []


def test_26_byte_limit_names_the_numbers():
    cf, link, fw = make_crazyflie(12)
    names = ["acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z", "pm.vbat"]  # 28 bytes
    with pytest.raises(LogConfigError, match="28 bytes.*at most 26"):
        cf.log.create_block(names, 10, lambda ts, v: None)
    assert control_packets(link) == []


def test_16_block_limit():
    cf, link, fw = make_crazyflie(12)
    for _ in range(16):
        cf.log.create_block(["pm.vbat"], 100, lambda ts, v: None)
    with pytest.raises(LogConfigError, match="all 16 log blocks the firmware holds are in use"):
        cf.log.create_block(["pm.vbat"], 100, lambda ts, v: None)


def test_variable_limit_is_counted_before_sending():
    cf, link, fw = make_crazyflie(12)
    cf.log.fetch_toc()
    assert (cf.log.max_blocks, cf.log.max_ops) == (16, 128)        # from the TOC info
    fw.max_ops = 1000           # the host refuses on its own count, not on the firmware's answer
    names = ["acc.x", "acc.y", "acc.z", "pm.vbat"] * 5              # 20 variables, 80 bytes: too big for one
    for _ in range(6):
        cf.log.create_block(names[:5] * 1 + names[:1], 100, lambda ts, v: None)   # 6 variables, 24 bytes
    assert cf.log.ops_used == 36
    sent = len(control_packets(link))
    cf.log.max_ops = 40
    with pytest.raises(LogConfigError, match="needs 6 log variables and 36 of the 40 .* in use by 6 blocks"):
        cf.log.create_block(names[:6], 100, lambda ts, v: None)
    assert len(control_packets(link)) == sent


def test_unknown_variable_is_named():
    cf, link, fw = make_crazyflie(12)
    with pytest.raises(UnknownName, match="'pm.vbatt'"):
        cf.log.create_block(["pm.vbat", "pm.vbatt"], 100, lambda ts, v: None)


def test_firmware_error_becomes_a_message_and_block_is_freed():
    cf, link, fw = make_crazyflie(12)
    cf.log.fetch_toc()
    fw.max_ops = 1              # fewer than the TOC info said (another session's blocks): the firmware refuses
    with pytest.raises(LogConfigError, match="ENOMEM"):
        cf.log.create_block(["acc.x", "acc.y"], 100, lambda ts, v: None)
    assert fw.blocks == {}
    assert cf.log.blocks == {}
    assert control_packets(link)[-1] == "5d 02 01"


def test_more_than_nine_variables_use_append():
    cf, link, fw = make_crazyflie(12)
    names = ["radio.rssi", "pos.dx"] * 5 + ["stab.thrust"]
    cf.log.create_block(names, 100, lambda ts, v: None)
    sent = control_packets(link)
    assert sent[0].startswith("5d 06 01") and len(bytes.fromhex(sent[0])) == 1 + 2 + 27
    assert sent[1].startswith("5d 07 01") and len(bytes.fromhex(sent[1])) == 1 + 2 + 6
    assert len(fw.blocks[1]["vars"]) == 11


def test_existing_block_id_is_replaced():
    """EEXIST (a leftover block or the first copy of a resent create) -> delete and create again."""
    cf, link, fw = make_crazyflie(12)
    fw.blocks[1] = {"vars": [2], "period": 0, "running": False}
    cf.log.create_block(["pm.vbat"], 100, lambda ts, v: None)
    assert control_packets(link) == ["5d 06 01 77 03 00", "5d 02 01", "5d 06 01 77 03 00",
                                     "5d 03 01 0a"]
    assert fw.blocks[1]["vars"] == [3]


def test_stop_start_delete():
    cf, link, fw = make_crazyflie(12)
    block = cf.log.create_block(["pm.vbat"], 100, lambda ts, v: None)
    link.clear()
    block.stop()
    assert not fw.blocks[1]["running"] and not block.started
    block.start()
    assert fw.blocks[1]["running"]
    block.delete()
    assert 1 not in fw.blocks and block.deleted
    assert control_packets(link) == ["5d 04 01", "5d 03 01 0a", "5d 02 01"]
    # the id is free again
    assert cf.log.create_block(["pm.vbat"], 100, lambda ts, v: None).ident == 1


def test_control_error_on_stop_is_reported():
    cf, link, fw = make_crazyflie(12)
    block = cf.log.create_block(["pm.vbat"], 100, lambda ts, v: None)
    fw.blocks.clear()
    with pytest.raises(ProtocolError, match="log block 1 stop failed.*ENOENT"):
        block.stop()
