"""Byte-exact behaviour of the simulated Crazyflie firmware, both generations (docs/protocol.md)."""
from __future__ import annotations

import random
import struct
import zlib

import pytest

from crazyflie_driver.crtp.nrf_system import reboot_packets, stm_power_off_packet, stm_power_on_packet
from crazyflie_driver.sim.crtp import tables as T
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from crazyflie_driver.sim.crtp.param import ParamService
from crazyflie_driver.sim.crtp.ports import boot_text
from support.sim_doubles import FakeVehicle, drain

ADDR = b"\xe7\xe7\xe7\xe7\x01"


def make(firmware="current", **kw):
    v = FakeVehicle(readings=kw.pop("readings", None), defaults=kw.pop("defaults", None))
    cf = SimulatedCrazyflie(ADDR, v, firmware=firmware, **kw)
    drain(cf)
    return cf, v


def ask(cf, raw: bytes):
    cf.handle_crtp(raw)
    return drain(cf)


def one(cf, raw: bytes) -> bytes:
    replies = ask(cf, raw)
    assert len(replies) == 1, replies
    return replies[0]


def param_id(cf, name):
    return cf.params.ident(name)


def log_id(cf, name):
    return [e.full_name for e in cf.logs.entries].index(name)


# --- console ----------------------------------------------------------------------------------
@pytest.mark.parametrize("fw,version", [("current", "2026.08"), ("2016.02", "2016.02")])
def test_boot_text_is_queued_as_console_packets_before_connect(fw, version):
    cf = SimulatedCrazyflie(ADDR, FakeVehicle(), firmware=fw)
    packets = drain(cf)
    assert all(p[0] == 0x00 and 1 <= len(p) - 1 <= 30 for p in packets)
    text = b"".join(p[1:] for p in packets).decode()
    assert text.startswith("SYS: ----------------------------\nSYS: Crazyflie 2.0 is up and running!\n")
    assert "SYS: Production release %s\n" % version in text
    assert text.endswith("SYS: Free heap: 21416 bytes\n")
    assert text == boot_text("Crazyflie 2.0", version, "00320024" "3435470D" "37323731", True)
    # a line of 34 characters goes out as 30 + 4 bytes
    assert packets[0] == b"\x00" + b"SYS: -------------------------"
    assert packets[1] == b"\x00---\n"


# --- link and platform ------------------------------------------------------------------------
def test_link_echo_source_sink_and_null():
    cf, _ = make()
    assert one(cf, b"\xfc\x01\x02\x03") == b"\xfc\x01\x02\x03"
    src = one(cf, b"\xfd\x00")
    assert src == b"\xfd" + b"Bitcraze Crazyflie" + b"\x00" * 12 and len(src) == 31
    assert ask(cf, b"\xfe\x01\x02") == []
    assert ask(cf, b"\xff") == []


@pytest.mark.parametrize("fw,proto,version,devtype", [("current", 12, b"2026.08", b"Crazyflie 2.0"),
                                                       ("2016.02", 2, b"2016.02", None)])
def test_platform_versions(fw, proto, version, devtype):
    cf, _ = make(fw)
    assert one(cf, b"\xdd\x00") == b"\xdd\x00" + struct.pack("<i", proto)
    assert one(cf, b"\xdd\x01") == b"\xdd\x01" + version
    if devtype:
        assert one(cf, b"\xdd\x02") == b"\xdd\x02" + devtype
    else:
        assert ask(cf, b"\xdd\x02") == []
    assert ask(cf, b"\xdd\x09") == []



def test_platform_commands_on_channel_0():
    cf, _ = make()
    assert ask(cf, b"\xdc\x03") == [b"\xdc"]                           # answered with no payload
    assert one(cf, b"\xdc\x00\x01") == b"\xdc\x00\x01"                  # others echoed (continuous wave)
    assert one(cf, b"\xdc\x09\x02\x03") == b"\xdc\x09\x02\x03"
    old, _ = make("2016.02")                                         # continuous wave only
    assert one(old, b"\xdc\x00\x01") == b"\xdc\x00\x01"
    assert ask(old, b"\xdc\x01\x01") == [] and ask(old, b"\xdc\x02") == [] and ask(old, b"\xdc\x03") == []

# --- parameters -------------------------------------------------------------------------------
def chained_crc(items):
    crc = 0
    for t, name in items:
        crc = zlib.crc32(struct.pack("<I", crc) + bytes([t]) + name.encode()) & 0xFFFFFFFF
    return crc


def test_param_toc_v2_info_item_and_crc_algorithm():
    table = [T.ParamVar("ring", "effect", "uint8_t", 6, persistent=True),
             T.ParamVar("ring", "fullCharge", "float", 4.2),
             T.ParamVar("cpu", "flash", "uint16_t", 1024, readonly=True)]
    cf, _ = make(param_table=table)
    expected_crc = chained_crc([(0x81, "ring"), (0x18, "effect"), (0x06, "fullCharge"), (0x80, "stop_ring"),
                                (0x81, "cpu"), (0x49, "flash"), (0x80, "stop_cpu")])
    assert one(cf, b"\x2c\x03") == b"\x2c\x03" + struct.pack("<HI", 3, expected_crc)
    assert one(cf, b"\x2c\x02\x00\x00") == b"\x2c\x02\x00\x00\x18ring\x00effect\x00"
    assert one(cf, b"\x2c\x02\x02\x00") == b"\x2c\x02\x02\x00\x49cpu\x00flash\x00"
    assert one(cf, b"\x2c\x02\x03\x00") == b"\x2c\x02"
    assert ask(cf, b"\x2c\x01") == [] and ask(cf, b"\x2c\x00\x00") == []   # V1 gone in 2026.04


def test_toc_crc_changes_when_the_table_changes():
    base = [T.ParamVar("ring", "effect", "uint8_t")]
    crc = lambda table: struct.unpack_from("<I", one(make(param_table=table)[0], b"\x2c\x03"), 4)[0]  # noqa: E731
    c0 = crc(base)
    assert crc(base + [T.ParamVar("ring", "neffect", "uint32_t")]) != c0
    assert crc([T.ParamVar("ring", "effect", "uint16_t")]) != c0
    assert crc([T.ParamVar("ring", "effect", "uint8_t", readonly=True)]) != c0
    assert crc(list(base)) == c0
    lc = lambda table: struct.unpack_from("<I", one(make(log_table=table)[0], b"\x5c\x03"), 4)[0]  # noqa: E731
    assert lc([T.LogVar("acc", "x", "float")]) != lc([T.LogVar("acc", "x", "float"), T.LogVar("acc", "y", "float")])


def test_param_toc_v1_for_2016():
    cf, _ = make("2016.02")
    n = len(cf.params.entries)
    info = one(cf, b"\x2c\x01")
    assert info[:3] == b"\x2c\x01" + bytes([n]) and len(info) == 7
    i = param_id(cf, "imu_tests.MPU6500")
    assert one(cf, bytes([0x2c, 0, i])) == bytes([0x2c, 0, i, 0x48]) + b"imu_tests\x00MPU6500\x00"
    assert one(cf, bytes([0x2c, 0, n])) == b"\x2c\x00"
    assert ask(cf, b"\x2c\x03") == []
    assert cf.params.ident("commander.enHighLevel") is None   # not in 2016.02


def test_param_read_write_errors_current():
    cf, v = make(defaults={"pid_rate.roll_kp": 70.0})
    i = param_id(cf, "ring.headlightEnable")
    lo, hi = i & 0xFF, i >> 8
    assert one(cf, bytes([0x2d, lo, hi])) == bytes([0x2d, lo, hi, 0, 0])
    assert one(cf, bytes([0x2e, lo, hi, 1])) == bytes([0x2e, lo, hi, 1])
    assert v.written == [("ring.headlightEnable", 1.0)]
    assert one(cf, bytes([0x2d, lo, hi])) == bytes([0x2d, lo, hi, 0, 1])
    k = param_id(cf, "pid_rate.roll_kp")
    assert one(cf, b"\x2d" + struct.pack("<H", k)) == b"\x2d" + struct.pack("<HBf", k, 0, 70.0)
    # every type path the real firmware's parameters have (it declares no 16-bit signed one)
    for name, fmt, value in [("sound.freq", "<H", 4000), ("cpu.id0", "<I", 0x00320024),
                             ("system.selftestPassed", "<b", 1), ("colAv.vorIters", "<i", 0),
                             ("lighthouse.systemType", "<B", 2), ("ring.fullCharge", "<f", 4.2)]:
        j = param_id(cf, name)
        assert one(cf, b"\x2d" + struct.pack("<H", j)) == b"\x2d" + struct.pack("<HB", j, 0) + struct.pack(fmt, value)
    g = param_id(cf, "radiotest.power")
    assert one(cf, b"\x2e" + struct.pack("<Hb", g, -30)) == b"\x2e" + struct.pack("<Hb", g, -30)
    assert cf.params.value("radiotest.power") == -30
    # ids past 255 (16-bit on the wire): read, write (reaches the vehicle), read back
    far = param_id(cf, "posCtlPid.zKp")
    assert far > 255
    assert one(cf, b"\x2d" + struct.pack("<H", far)) == b"\x2d" + struct.pack("<HBf", far, 0, 0.0)
    assert one(cf, b"\x2e" + struct.pack("<Hf", far, 3.5)) == b"\x2e" + struct.pack("<Hf", far, 3.5)
    assert one(cf, b"\x2d" + struct.pack("<H", far)) == b"\x2d" + struct.pack("<HBf", far, 0, 3.5)
    assert v.written[-1] == ("posCtlPid.zKp", 3.5)
    # unknown id, read-only write (silent, unchanged), short write dropped
    n = len(cf.params.entries)
    assert one(cf, b"\x2d" + struct.pack("<H", n)) == b"\x2d" + struct.pack("<HB", n, 2)
    assert one(cf, b"\x2e" + struct.pack("<HB", n, 1)) == b"\x2e" + struct.pack("<HB", n, 2)
    ro = param_id(cf, "firmware.revision0")
    assert ask(cf, b"\x2e" + struct.pack("<HI", ro, 5)) == []
    assert cf.params.value("firmware.revision0") == 0x2A18FC29
    assert ask(cf, b"\x2e" + struct.pack("<H", k) + b"\x00\x00") == []
    assert ask(cf, b"\x2d\x00") == []


def test_param_read_write_errors_2016():
    cf, v = make("2016.02")
    i = param_id(cf, "flightmode.althold")
    assert one(cf, bytes([0x2d, i])) == bytes([0x2d, i, 0])
    assert one(cf, bytes([0x2e, i, 1])) == bytes([0x2e, i, 1])
    assert one(cf, bytes([0x2d, i])) == bytes([0x2d, i, 1])
    g = param_id(cf, "ring.glowstep")    # the one 16-bit signed parameter, in the small table only
    assert one(cf, bytes([0x2e, g]) + struct.pack("<h", -300)) == bytes([0x2e, g]) + struct.pack("<h", -300)
    assert cf.params.value("ring.glowstep") == -300
    n = len(cf.params.entries)
    assert one(cf, bytes([0x2d, n])) == bytes([0x2d, 0xFF, n, 2])
    ro = param_id(cf, "cpu.flash")
    assert ask(cf, bytes([0x2e, ro, 1, 0])) == []
    assert v.written == [("flightmode.althold", 1.0), ("ring.glowstep", -300.0)]


def test_param_misc_set_by_name_and_extended_type():
    cf, v = make()
    req = b"\x2f\x00ring\x00headlightEnable\x00"
    assert one(cf, req + b"\x08\x01") == req + b"\x00"
    assert cf.params.value("ring.headlightEnable") == 1 and v.written[-1] == ("ring.headlightEnable", 1.0)
    assert one(cf, req + b"\x09\x01\x00") == req + b"\x16"                     # type mismatch: EINVAL
    ro = b"\x2f\x00cpu\x00flash\x00"
    assert one(cf, ro + b"\x49\x00\x00") == ro + b"\x0d"                       # read-only: EACCES
    unk = b"\x2f\x00ring\x00nope\x00"
    assert one(cf, unk + b"\x08\x01") == unk + b"\x02"                         # ENOENT
    assert ask(cf, b"\x2f\x00ring\x00") == []                                  # one NUL: ignored
    e = param_id(cf, "ring.effect")
    idb = struct.pack("<H", e)
    assert one(cf, b"\x2f\x02" + idb) == b"\x2f\x02" + idb + b"\x01"
    assert one(cf, b"\x2f\x07" + idb) == b"\x2f\x07" + idb + b"\x00\x01"
    h = struct.pack("<H", param_id(cf, "ring.headlightEnable"))
    assert one(cf, b"\x2f\x02" + h) == b"\x2f\x02" + h + b"\x02"
    assert one(cf, b"\x2f\x08" + h) == b"\x2f\x08" + h + b"\x00\x00"          # default value V2
    # the item's TOC type carries EXTENDED so cflib asks
    assert one(cf, b"\x2c\x02" + idb)[4] == 0x38                             # u8, EXTENDED, CORE



def test_param_misc_defaults_and_persistent_storage_by_id():
    table = [T.ParamVar("ring", "effect", "uint8_t", 6, persistent=True),
             T.ParamVar("ring", "fullCharge", "float", 4.2),
             T.ParamVar("cpu", "flash", "uint16_t", 1024, readonly=True)]
    cf, _ = make(param_table=table)
    eff, full, ro = (struct.pack("<H", param_id(cf, n)) for n in ("ring.effect", "ring.fullCharge", "cpu.flash"))
    past = struct.pack("<H", 3)                                                   # past the table
    misc = lambda cmd, ident: one(cf, bytes([0x2F, cmd]) + ident)  # noqa: E731
    # GET_DEFAULT (6) and GET_DEFAULT_V2 (8, a status byte first); read-only or unknown: ENOENT
    assert misc(6, full) == b"\x2f\x06" + full + struct.pack("<f", 4.2)
    assert misc(8, full) == b"\x2f\x08" + full + b"\x00" + struct.pack("<f", 4.2)
    for cmd in (6, 8):
        for ident in (ro, past):
            assert misc(cmd, ident) == bytes([0x2F, cmd]) + ident + b"\x02"
    assert misc(2, past) == b"\x2f\x02" + past + b"\x02"                          # extended type: ENOENT
    assert misc(7, full) == b"\x2f\x07" + full + b"\x02"
    # persistent storage: state (4) = stored?, default[, stored]; store (3), clear (5)
    assert misc(4, eff) == b"\x2f\x04" + eff + b"\x00\x06"
    assert one(cf, b"\x2e" + eff + b"\x09") == b"\x2e" + eff + b"\x09"              # write 9
    assert misc(3, eff) == b"\x2f\x03" + eff + b"\x00"
    assert cf.params.stored == {param_id(cf, "ring.effect"): 9}
    assert misc(4, eff) == b"\x2f\x04" + eff + b"\x01\x06\x09"
    assert misc(5, eff) == b"\x2f\x05" + eff + b"\x00"
    assert misc(4, eff) == b"\x2f\x04" + eff + b"\x00\x06"
    for cmd in (3, 4, 5):                                                          # not persistent, or no such id
        for ident in (full, past):
            assert misc(cmd, ident) == bytes([0x2F, cmd]) + ident + b"\x02"
    assert cf.params.stored == {}
    assert ask(cf, b"\x2f\x02\x00") == [] and ask(cf, b"\x2f\x09" + eff) == []      # short; unknown command


def test_param_misc_v2_commands_need_protocol_11_and_the_2016_firmware_answers_only_set_by_name():
    sent = []
    table = [T.ParamVar("ring", "effect", "uint8_t", 6, persistent=True)]
    params = ParamService(T.GEN_CURRENT, 10, table, {}, lambda name, value: None,
                          lambda header, data: sent.append(data) or True)
    for cmd in (7, 8):
        params.handle(0x2F, 3, bytes([cmd, 0, 0]))
    assert sent == []
    params.handle(0x2F, 3, bytes([2, 0, 0]))
    assert sent == [bytes([2, 0, 0, T.EXTENDED_PERSISTENT])]
    old, _ = make("2016.02")
    for cmd in (2, 3, 4, 5, 6, 7, 8):
        assert ask(old, bytes([0x2F, cmd, 0, 0])) == []

# --- log ----------------------------------------------------------------------------------------
def test_log_toc_info_and_items():
    cf, _ = make()
    n = len(cf.logs.entries)
    info = one(cf, b"\x5c\x03")
    assert info == b"\x5c\x03" + struct.pack("<HIBB", n, cf.logs.crc, 16, 128)
    i = log_id(cf, "acc.z")
    assert one(cf, b"\x5c\x02" + struct.pack("<H", i)) == b"\x5c\x02" + struct.pack("<HB", i, 7) + b"acc\x00z\x00"
    assert one(cf, b"\x5c\x02" + struct.pack("<H", n)) == b"\x5c\x02"
    assert ask(cf, b"\x5c\x01") == []
    old, _ = make("2016.02")
    n16 = len(old.logs.entries)
    assert one(old, b"\x5c\x01") == b"\x5c\x01" + struct.pack("<BIBB", n16, old.logs.crc, 8, 64)
    j = log_id(old, "motor.m1")
    assert one(old, bytes([0x5c, 0, j])) == bytes([0x5c, 0, j, 6]) + b"motor\x00m1\x00"
    assert ask(old, b"\x5c\x03") == []


def create_v2(cf, block, items, cmd=6):
    body = bytes([cmd, block]) + b"".join(struct.pack("<BH", t, log_id(cf, n)) for n, t in items)
    return one(cf, b"\x5d" + body)


def test_log_variable_past_id_255_streams_its_live_value():
    cf, v = make(readings={"stateEstimate.z": 0.75, "acc.z": 1.0})
    far = log_id(cf, "stateEstimate.z")
    assert far > 255
    item = one(cf, b"\x50\x02" + struct.pack("<H", far))
    assert item == b"\x50\x02" + struct.pack("<HB", far, 7) + b"stateEstimate\x00z\x00"
    assert create_v2(cf, 3, [("stateEstimate.z", 7), ("acc.z", 7)]) == b"\x5d\x06\x03\x00"
    assert one(cf, b"\x5d\x03\x03\x01") == b"\x5d\x03\x03\x00"
    v.t = 0.01
    cf.tick(v.t)
    (p,) = drain(cf)
    assert p[0] == 0x52 and p[1] == 3 and p[5:] == struct.pack("<ff", 0.75, 1.0)


def test_log_crc_hashes_core_and_by_function_flags_items_carry_the_low_nibble():
    plain = [T.LogVar("pm", "vbat", "float", (T.GEN_CURRENT,))]
    core = [T.LogVar("pm", "vbat", "float", (T.GEN_CURRENT,), core=True)]
    crc = lambda table: make(log_table=table)[0].logs.crc  # noqa: E731
    assert crc(plain) == chained_crc([(0x81, "pm"), (0x07, "vbat"), (0x80, "stop_pm")])
    assert crc(core) == chained_crc([(0x81, "pm"), (0x27, "vbat"), (0x80, "stop_pm")])
    cf = make(log_table=core)[0]
    assert one(cf, b"\x50\x02\x00\x00")[4] == 0x07


def test_log_block_data_at_period_with_conversion():
    cf, v = make(readings={"acc.z": 1.25, "stabilizer.roll": -12.7, "motor.m1": 70000.0, "baro.pressure": 1013.5})
    assert create_v2(cf, 1, [("acc.z", 7), ("stabilizer.roll", 4), ("motor.m1", 2), ("baro.pressure", 8)]) \
        == b"\x5d\x06\x01\x00"
    assert one(cf, b"\x5d\x03\x01\x01") == b"\x5d\x03\x01\x00"       # START, 10 ms
    packets = []
    for step in range(1, 36):                                         # 35 ms of 1 kHz ticks
        v.t = step * 0.001
        cf.tick(v.t)
        packets += [(step, p) for p in drain(cf)]
    steps = [s for s, _ in packets]
    assert steps == [10, 20, 30]       # first packet one period after START
    step, p = packets[1]
    assert p[0] == 0x52 and p[1] == 1
    assert int.from_bytes(p[2:5], "little") == 20
    assert p[5:] == struct.pack("<fbHe", 1.25, -12, 65535, 1013.5)   # u16 var saturates, float->i8 truncates
    assert one(cf, b"\x5d\x04\x01") == b"\x5d\x04\x01\x00"            # STOP keeps the block
    v.t = 0.05
    cf.tick(v.t)
    assert drain(cf) == []
    assert one(cf, b"\x5d\x08\x01\x05\x00") == b"\x5d\x08\x01\x00"   # START_V2 5 ms
    got = []
    for step in range(51, 67):
        v.t = step * 0.001
        cf.tick(v.t)
        got += [step for _ in drain(cf)]
    assert got == [55, 60, 65]
    assert one(cf, b"\x5d\x03\x01\x00") == b"\x5d\x03\x01\x00"       # period 0: once
    for step in range(66, 80):
        v.t = step * 0.001
        cf.tick(v.t)
    assert len(drain(cf)) == 1


def test_log_control_errors_and_limits_current():
    cf, _ = make()
    assert create_v2(cf, 1, [("acc.x", 7)]) == b"\x5d\x06\x01\x00"
    assert create_v2(cf, 1, [("acc.x", 7)]) == b"\x5d\x06\x01\x11"                  # EEXIST
    n = len(cf.logs.entries)
    assert one(cf, b"\x5d\x06\x02" + struct.pack("<BH", 7, n)) == b"\x5d\x06\x02\x02"  # ENOENT var
    assert one(cf, b"\x5d\x07\x09" + struct.pack("<BH", 7, 0)) == b"\x5d\x07\x09\x02"  # append: no block
    for cmd in (2, 3, 4):
        assert one(cf, bytes([0x5d, cmd, 0x33, 1])) == bytes([0x5d, cmd, 0x33, 2])
    # 26 bytes: six floats fit, the seventh is E2BIG and the first six stay (not atomic)
    names = ["acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z", "mag.x"]
    assert create_v2(cf, 3, [(nm, 7) for nm in names]) == b"\x5d\x06\x03\x07"
    assert len(cf.logs.blocks[3].ops) == 6
    assert create_v2(cf, 4, [("acc.x", 1)], cmd=7) == b"\x5d\x07\x04\x02"
    # V1 create is gone in current firmware; unknown command
    assert one(cf, b"\x5d\x00\x05\x07\x00") == b"\x5d\x00\x05\x08"
    assert one(cf, b"\x5d\x0b\x05") == b"\x5d\x0b\x05\x08"
    assert one(cf, b"\x5d\x05") == b"\x5d\x05\x00\x00"
    assert cf.logs.blocks == {}
    # 16 blocks, then ENOMEM
    for b in range(16):
        assert create_v2(cf, b, [("pm.state", 4)]) == bytes([0x5d, 6, b, 0])
    assert create_v2(cf, 16, [("pm.state", 4)]) == b"\x5d\x06\x10\x0c"
    # 128 operations
    assert one(cf, b"\x5d\x05") == b"\x5d\x05\x00\x00"
    for b in range(4):
        assert create_v2(cf, b, [("pm.state", 4)] * 9) == bytes([0x5d, 6, b, 0])
        for _ in range(2):
            assert create_v2(cf, b, [("pm.state", 4)] * 8, cmd=7) == bytes([0x5d, 7, b, 0])
    assert cf.logs.ops_used == 100
    for b in range(4, 7):
        assert create_v2(cf, b, [("pm.state", 4)] * 9) == bytes([0x5d, 6, b, 0])
    r = create_v2(cf, 7, [("pm.state", 4)] * 9)
    assert r == b"\x5d\x06\x07\x0c" and cf.logs.ops_used == 128


def test_log_v1_create_and_limits_2016():
    cf, v = make("2016.02", readings={"pm.vbat": 3.9})
    i = log_id(cf, "pm.vbat")
    assert one(cf, bytes([0x5d, 0, 1, 7, i])) == b"\x5d\x00\x01\x00"
    assert one(cf, bytes([0x5d, 1, 1, 7, i])) == b"\x5d\x01\x01\x00"
    assert one(cf, bytes([0x5d, 6, 2]) + struct.pack("<BH", 7, i)) == b"\x5d\x06\x02\x08"   # no V2
    assert one(cf, bytes([0x5d, 8, 1, 10, 0])) == b"\x5d\x08\x01\x08"                     # no START_V2
    # 30 bytes of values in 2016.02: seven floats fit (28), an eighth does not
    assert one(cf, bytes([0x5d, 0, 2]) + bytes([7, i]) * 8) == b"\x5d\x00\x02\x07"
    assert len(cf.logs.blocks[2].ops) == 7
    for b in range(3, 9):
        assert one(cf, bytes([0x5d, 0, b, 1, i])) == bytes([0x5d, 0, b, 0])
    assert one(cf, bytes([0x5d, 0, 9, 1, i])) == b"\x5d\x00\x09\x0c"                       # 8 blocks
    assert one(cf, bytes([0x5d, 3, 1, 10])) == b"\x5d\x03\x01\x00"
    v.t = 0.099
    cf.tick(v.t)
    assert drain(cf) == []
    v.t = 0.1
    cf.tick(v.t)
    (p,) = drain(cf)
    assert p == b"\x52\x01\x64\x00\x00" + struct.pack("<ff", 3.9, 3.9)


def test_log_blocks_deleted_after_radio_silence_in_current_firmware_only():
    for fw, kept in (("current", False), ("2016.02", True)):
        cf, v = make(fw)
        if fw == "current":
            create_v2(cf, 1, [("acc.x", 7)])
        else:
            one(cf, bytes([0x5d, 0, 1, 7, log_id(cf, "acc.x")]))
        one(cf, b"\x5d\x03\x01\x0a")
        cf.handle_radio_packet(b"\xff")
        v.t = 1.5
        cf.tick(v.t)
        assert (1 in cf.logs.blocks) is kept, fw


# --- commanders and safety ---------------------------------------------------------------------------
def test_rpyt_reaches_vehicle_raw():
    cf, v = make()
    assert ask(cf, b"\x3c" + struct.pack("<fffH", 1.5, -2.0, 30.0, 42000)) == []
    assert v.setpoints == [(1.5, -2.0, 30.0, 42000)]
    ask(cf, b"\x3c" + struct.pack("<fff", 1, 2, 3))                   # short: ignored
    assert len(v.setpoints) == 1
    ask(cf, b"\x7c\x00")                                             # generic stop
    assert v.setpoints[-1] == (0.0, 0.0, 0.0, 0)


def test_emergency_stop_ports():
    cf, v = make()
    i = cf.supervisor_bits()
    assert one(cf, b"\x9c\x0c") == b"\x9c\x8c" + struct.pack("<H", i) and i & (1 << 6) == 0
    assert one(cf, b"\x9c\x02") == b"\x9c\x82\x01"                   # armed
    ask(cf, b"\x9d\x03")
    assert v.estops == 1 and cf.state.emergency
    assert one(cf, b"\x9c\x07") == b"\x9c\x87\x01"                   # locked
    cf2, v2 = make()
    ask(cf2, b"\x6d\x03")
    assert v2.estops == 1
    old, v3 = make("2016.02")
    ask(old, b"\x6d\x03")
    ask(old, b"\x9d\x03")
    assert v3.estops == 0 and ask(old, b"\x9c\x0c") == []


@pytest.mark.parametrize("feed", [b"\x6d\x04", b"\x9d\x04"])      # localization or supervisor port
def test_estop_watchdog_fires_after_one_second(feed):
    cf, v = make()
    ask(cf, feed)
    v.t = 0.9
    cf.tick(v.t)
    assert v.estops == 0
    v.t = 1.01
    cf.tick(v.t)
    assert v.estops == 1


# --- nRF link ----------------------------------------------------------------------------------
def test_empty_ack_formats():
    cf, _ = make()
    assert [cf.handle_radio_packet(b"\xff") for _ in range(3)] == [b"\xf3", b"\xf7", b"\xf3"]
    old, _ = make("2016.02", rssi_dbm=-47.0)
    assert [old.handle_radio_packet(b"\xff") for _ in range(2)] == [b"\xf3\x01\x2f", b"\xf7\x01\x2f"]


def test_one_downlink_per_uplink_and_reply_in_a_later_ack():
    cf, _ = make()                                  # (its boot text already taken: port 0)
    assert cf.handle_radio_packet(b"\xdd\x00") == b"\xf3"            # answer not ready yet
    assert cf.handle_radio_packet(b"\xdd\x01") == b"\xd5\x00\x0c\x00\x00\x00"
    assert cf.handle_radio_packet(b"\xff") == b"\xd1\x012026.08"
    assert cf.handle_radio_packet(b"\xff") == b"\xf7"
    assert cf.state.sent_by_port.get(13) == 2      # two answers left in acks; empty acks are no packets
    assert cf.snapshot()["sent_by_port"]["13"] == 2


def test_safelink_dedupes_uplink_and_resends_lost_ack():
    cf, _ = make()
    assert cf.handle_radio_packet(b"\xff\x05\x01") == b"\xff\x05\x01"
    up = down = 0

    def send(port_header, payload=b""):
        return cf.handle_radio_packet(bytes([(port_header & 0xF3) | (up << 3) | (down << 2)]) + payload)

    ack = send(0xFD, b"\x00")                                          # source request
    assert ack == b"\xf3"                                              # empty ack with down bit 0
    down ^= 1
    up ^= 1
    ack = send(0xFF)                                                   # poll: the reply arrives
    assert ack[0] == 0xF0 | (down << 2) | 1 and ack[1:19] == b"Bitcraze Crazyflie"
    again = send(0xFF)                                                 # ack lost: same bits -> same ack
    assert again == ack
    assert cf.link.duplicates == 1
    down ^= 1
    up ^= 1
    dup_header = 0xFD | ((up ^ 1) << 3) | (down << 2)                 # an old uplink bit: duplicate
    before = cf.state.packets_by_port.get(15, 0)
    cf.handle_radio_packet(bytes([dup_header & 0xFF]) + b"\x00")
    assert cf.state.packets_by_port.get(15, 0) == before


def test_side_channel_reboot_and_radio_commands():
    cf, v = make()
    ask(cf, b"\x2e" + struct.pack("<HB", param_id(cf, "ring.headlightEnable"), 1))
    assert cf.handle_radio_packet(b"\xff\x03\x01\x50") in (b"\xf3", b"\xf7")
    assert cf.handle_radio_packet(b"\xff\xfe\xff") in (b"\xf3", b"\xf7")
    assert cf.handle_radio_packet(b"\xff\xfe\xf0\x01") in (b"\xf3", b"\xf7")
    assert v.reboots == 1 and cf.state.reboots == 1
    assert cf.params.value("ring.headlightEnable") == 0
    assert b"".join(p[1:] for p in drain(cf)).startswith(b"SYS: ---")
    assert cf.handle_radio_packet(b"\xff\x85\x00") == b""
    cf.handle_radio_packet(b"\xff\xfe\x01")
    assert not cf.powered and not cf.radio_on and cf.handle_radio_packet(b"\xff") == b""
    assert cf.handle_radio_packet(b"\xff\xfe\x03") == b"" and not cf.powered     # all off: no radio wakes it


def test_reset_needs_reset_init_first():
    cf, v = make()
    assert cf.handle_radio_packet(b"\xf3\xfe\xf0\x01") in (b"\xf3", b"\xf7")
    assert cf.state.reboots == 0
    cf.handle_radio_packet(b"\xf3\xfe\xff")
    cf.handle_radio_packet(b"\xf3\xfe\xf0\x01")
    assert cf.state.reboots == 1


def test_reboot_brings_back_fresh_state_and_restarts_uptime():
    cf, v = make()
    ask(cf, b"\x2e" + struct.pack("<HB", param_id(cf, "ring.headlightEnable"), 1))
    v.t += 5.0
    assert cf.timestamp_ms() >= 5000
    for packet in reboot_packets():
        cf.handle_radio_packet(packet)
    assert cf.state.reboots == 1 and cf.params.value("ring.headlightEnable") == 0
    assert cf.logs.blocks == {} and cf.timestamp_ms() == 0 and not cf.link.safelink


def test_reboot_into_the_bootloader_answers_no_crtp_until_reset_to_firmware():
    cf, v = make()
    for packet in reboot_packets(bootloader=True):
        cf.handle_radio_packet(packet)
    assert cf.in_bootloader and cf.radio_on
    assert drain(cf) == []                                         # no firmware boot text
    cf.handle_radio_packet(b"\xfd\x00")                          # link source query: no firmware runs
    assert drain(cf) == [] and cf.state.packets_by_port == {}
    for packet in reboot_packets():
        cf.handle_radio_packet(packet)
    assert not cf.in_bootloader and cf.powered


def test_stm_off_keeps_the_nrf_on_the_air_until_stm_on():
    cf, v = make()
    cf.handle_radio_packet(b"\xff\x05\x01")                     # safelink on
    assert cf.handle_radio_packet(stm_power_off_packet()) in (b"\xf3", b"\xf7")
    assert not cf.powered and cf.radio_on
    assert cf.handle_radio_packet(b"\xfd\x00") != b""            # acked by the nRF ...
    assert cf.state.packets_by_port == {}                          # ... the STM sees nothing
    cf.handle_radio_packet(stm_power_on_packet())
    assert cf.powered and cf.state.reboots == 1
    assert cf.link.safelink                                       # the nRF was not reset


def test_brushless_profile_does_not_arm_itself():
    cf, _ = make()
    assert cf.supervisor_bits() & 0x06 == 0x06                    # armed, auto-arm
    cf, _ = make(auto_arm=False)
    assert cf.supervisor_bits() & 0x07 == 0x01                    # can arm, not armed, no auto-arm
    assert cf.arm(True) == (True, True)
    cf.reboot()
    assert not cf.state.armed                                     # a reboot disarms it


@pytest.mark.parametrize("fw,size", [("current", 200), ("2016.02", 60)])
def test_tx_queue_drops_when_full(fw, size):
    cf, _ = make(fw)
    for _ in range(size + 5):
        cf.handle_crtp(b"\xfc\x01")
    assert cf.pending_outgoing() == size and cf.state.tx_dropped == 5


@pytest.mark.parametrize("fw", ["current", "2016.02"])
def test_garbage_never_raises(fw):
    rng = random.Random(7)
    cf, v = make(fw)
    halts = 0
    for _ in range(4000):
        n = rng.randint(0, 40)
        data = bytes(rng.randrange(256) for _ in range(n))
        if rng.random() < 0.5:
            cf.handle_crtp(data)
        else:
            cf.handle_radio_packet(data)
        v.t += 0.001
        cf.tick(v.t)
        drain(cf)
        if cf.state.halted:         # only a port-7 length assert halts, as on the real firmware
            assert cf.state.halted.startswith("port 7"), cf.state.halted
            halts += 1
            cf.reboot()
    assert (halts > 0) == (fw == "current")           # the 2016.02 firmware has no port 7
    cf.handle_crtp(b"\x5d\x05")
    assert drain(cf)[-1] == b"\x5d\x05\x00\x00" or not cf.powered
