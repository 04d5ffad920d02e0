"""Parameters packet by packet: V1 (FW16) and V2 read/write formats, conversion, errors."""
from __future__ import annotations

import struct

import pytest

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import ParamValueError, ProtocolError, ReadOnlyParam, UnknownName
from crazyflie_driver.protocol.param import ParamClient, param_value
from crazyflie_driver.protocol.toc import Toc, TocEntry
from support.scripted_link import ScriptedLink, make_crazyflie

ROLL_KP = TocEntry(0, "pid_rate", "roll_kp", "float")
EFFECT = TocEntry(1, "ring", "effect", "uint8_t")
RO = TocEntry(2, "imu", "ok", "uint8_t", True)
BIG = TocEntry(300, "motorPowerSet", "m1", "uint16_t")


def client(replies, version):
    link = ScriptedLink(responder=lambda p: [CRTPPacket.from_bytes(bytes.fromhex(r))
                                             for r in replies.get(p.to_bytes().hex(" "), [])])
    params = ParamClient(link)
    params.protocol_version = version
    params.toc = Toc([ROLL_KP, EFFECT, RO, BIG])
    return params, link


def test_v2_read_has_16_bit_id_and_status_byte():
    params, link = client({"2d 00 00": ["2d 00 00 00" + struct.pack("<f", 250.0).hex()],
                           "2d 2c 01": ["2d 2c 01 00 34 12"]}, 12)
    assert params.get("pid_rate.roll_kp") == 250.0
    assert params.get("motorPowerSet.m1") == 0x1234
    assert link.raw_sent() == ["2d 00 00", "2d 2c 01"]


def test_v1_read_has_8_bit_id_and_no_status():
    params, link = client({"2d 01": ["2d 01 06"]}, 2)
    assert params.get("ring.effect") == 6
    assert link.raw_sent() == ["2d 01"]


def test_v2_read_error_status_is_reported():
    params, link = client({"2d 01 00": ["2d 01 00 02"]}, 12)
    with pytest.raises(ProtocolError, match="ring.effect.*error 2"):
        params.get("ring.effect")


def test_v1_read_error_form_is_reported():
    params, link = client({"2d 01": ["2d ff 01 02"]}, 2)
    with pytest.raises(ProtocolError, match="ring.effect"):
        params.get("ring.effect")


def test_v2_write_is_echoed():
    params, link = client({"2e 01 00 07": ["2e 01 00 07"],
                           "2e 00 00 00 00 48 43": ["2e 00 00 00 00 48 43"]}, 12)
    assert params.set("ring.effect", "7") == 7
    assert params.set("pid_rate.roll_kp", 200) == 200.0
    assert link.raw_sent() == ["2e 01 00 07", "2e 00 00 00 00 48 43"]
    assert params.values["ring.effect"] == 7


def test_v2_write_of_value_2_is_not_mistaken_for_an_error():
    """The echo of a u8 write of 2 looks like the ENOENT reply [id u16, 2]; it is a success."""
    params, link = client({"2e 01 00 02": ["2e 01 00 02"]}, 12)
    assert params.set("ring.effect", 2) == 2


def test_v1_write_format():
    params, link = client({"2e 01 03": ["2e 01 03"]}, 2)
    params.set("ring.effect", 3.0)
    assert link.raw_sent() == ["2e 01 03"]


def test_v1_write_error_reply():
    params, link = client({"2e 01 03": ["2e ff 01 02"]}, 2)
    with pytest.raises(ProtocolError, match="writing parameter ring.effect failed"):
        params.set("ring.effect", 3)


def test_read_only_is_refused_before_sending():
    params, link = client({}, 12)
    with pytest.raises(ReadOnlyParam, match="imu.ok is read-only"):
        params.set("imu.ok", 1)
    assert link.sent == []


def test_unknown_name_is_refused_naming_it():
    params, link = client({}, 12)
    with pytest.raises(UnknownName, match="ring.nothere"):
        params.set("ring.nothere", 1)
    with pytest.raises(UnknownName, match="group.name"):
        params.get("effect")


@pytest.mark.parametrize("ctype, value, expected", [
    ("uint8_t", "255", 255), ("uint8_t", 3.0, 3), ("uint8_t", True, 1), ("int8_t", -128, -128),
    ("uint16_t", "0x10", 16), ("int32_t", "-5", -5), ("float", "1.5", 1.5), ("FP16", 0.5, 0.5),
    ("double", 2, 2.0), ("uint32_t", 4294967295, 4294967295), ("uint8_t", "false", 0),
    ("uint8_t", " TRUE ", 1), ("int16_t", "7.0", 7), ("float", 3, 3.0), ("float", "-1e3", -1000.0),
    ("float", 3.4028234663852886e38, 3.4028234663852886e38), ("int64_t", -2 ** 63, -2 ** 63),
])
def test_conversion_to_the_toc_type(ctype, value, expected):
    result = param_value("g.n", ctype, value)
    assert result == expected and type(result) is type(expected)


@pytest.mark.parametrize("ctype, value, message", [
    ("uint8_t", 256, "out of range 0..255"), ("uint8_t", -1, "out of range 0..255"),
    ("int8_t", 128, "out of range -128..127"), ("uint16_t", 65536, "0..65535"),
    ("uint8_t", 1.5, "not an integer"), ("uint8_t", "abc", "not an integer"),
    ("float", "fast", "not a number"), ("FP16", 1e6, "out of range"),
    ("int16_t", float("nan"), "not an integer"), ("uint8_t", float("inf"), "not an integer"),
    ("float", float("nan"), "not a finite number"), ("float", float("-inf"), "not a finite number"),
    ("float", "nan", "not a finite number"), ("double", "inf", "not a finite number"),
    ("float", 1e39, "out of range"), ("float", -1e39, "out of range"), ("FP16", 65520.0, "out of range"),
    ("float", 10 ** 400, "not a number"), ("float", True, "not a number"), ("float", "true", "not a number"),
    ("float", [1], "not a number"), ("uint8_t", None, "not an integer"), ("uint8_t", {"a": 1}, "not an integer"),
    ("uint32_t", 2 ** 32, "out of range 0..4294967295"), ("int32_t", "0x80000000", "out of range"),
])
def test_bad_values_are_refused_with_the_range(ctype, value, message):
    with pytest.raises(ParamValueError, match=r"parameter g\.n \(%s\): .*%s" % (ctype, message)):
        param_value("g.n", ctype, value)


@pytest.mark.parametrize("version", [2, 12])
def test_read_all_and_set_against_scripted_firmware(version):
    cf, link, fw = make_crazyflie(version)
    values = cf.params.read_all()
    assert values == {"%s.%s" % (g, n): v for g, n, _, _, v in fw.params}
    cf.params.set("stabilizer.offset", -200)
    assert fw.params[6][4] == -200
    assert cf.params.get("stabilizer.offset") == -200
    cf.params.set("kalman.pNAcc_xy", 0.25)
    assert fw.params[7][4] == 0.25


def test_v2_toc_info_is_sent_before_the_first_read():
    cf, link, fw = make_crazyflie(12)
    cf.params.get("ring.effect")
    param_packets = [p.to_bytes().hex(" ") for p in link.sent if p.port == 2]
    assert param_packets[0] == "2c 03"
    assert param_packets[-1] == "2d 01 00"


def test_value_updated_from_firmware_updates_cache_and_calls_back():
    cf, link, fw = make_crazyflie(12)
    cf.params.fetch_toc()
    seen = []
    cf.params.on_update(lambda name, value: seen.append((name, value)))
    link.push(CRTPPacket(2, 3, bytes([1, 1, 0, 9])))
    link.drain()
    assert seen == [("ring.effect", 9)]
    assert cf.params.values["ring.effect"] == 9


@pytest.mark.parametrize("name,rule", [
    ("pid_rate.roll\x00kp", "a NUL character at position 13"),
    ("pid_rate.roll kp", "character ' ' at position 13"),
    ("pid_rate.roll.kp", "character '.' at position 13"),
    ("pid_rate.rollü", "character 'ü'"),
    ("roll_kp", "not of the form group.name"),
    ("pid_rate.", "not of the form group.name"),
    ("pid_rate." + "k" * 20, "at most 26 bytes"),
])
def test_names_no_crazyflie_can_have_are_refused_before_sending(name, rule):
    params, link = client({}, 12)
    for call in (lambda: params.get(name), lambda: params.set(name, 1.0)):
        with pytest.raises(UnknownName, match=rule):
            call()
    assert link.sent == []
