"""Decoders of the simulated firmware's port 7 (generic setpoints) and port 6 (localization), byte by byte."""
from __future__ import annotations

import math
import random
import struct

import pytest

from crazyflie_driver.crtp.quaternion import compress_quaternion as compress_quat
from crazyflie_driver.crtp.quaternion import decompress_quaternion as decompress_quat
from crazyflie_driver.errors import CommandValueError
from crazyflie_driver.sim.crtp import localization_decode as loc
from crazyflie_driver.sim.crtp.setpoint_decode import (
    EXPECTED_LENGTH,
    FirmwareAssert,
    decode_meta,
    decode_setpoint,
)
from crazyflie_driver.sim.onboard.setpoint import MODE_ABS, MODE_DISABLE, MODE_VELOCITY


def four(kind, a, b, c, d):
    return bytes([kind]) + struct.pack("<ffff", a, b, c, d)


def test_velocity_world_legacy_negates_yaw_rate_v9_does_not():
    legacy, new = decode_setpoint(four(1, 0.5, -0.25, 0.1, 30.0)), decode_setpoint(four(8, 0.5, -0.25, 0.1, 30.0))
    for sp in (legacy, new):
        assert (sp.mode_x, sp.mode_y, sp.mode_z, sp.mode_yaw) == (MODE_VELOCITY,) * 4
        assert sp.velocity == (0.5, -0.25, pytest.approx(0.1))
        assert sp.mode_roll == sp.mode_pitch == MODE_DISABLE and sp.thrust == 0.0 and not sp.velocity_body
    assert legacy.attitude_rate[2] == -30.0 and new.attitude_rate[2] == 30.0


def test_hover_is_body_velocity_with_absolute_height():
    for kind, yaw_sign in ((5, -1.0), (10, 1.0)):
        sp = decode_setpoint(four(kind, 0.3, 0.1, 45.0, 0.7))
        assert (sp.mode_x, sp.mode_y, sp.mode_z) == (MODE_VELOCITY, MODE_VELOCITY, MODE_ABS)
        assert sp.velocity_body and sp.position[2] == pytest.approx(0.7)
        assert sp.attitude_rate[2] == yaw_sign * 45.0


def test_z_distance_and_alt_hold():
    for kind, yaw_sign in ((2, -1.0), (9, 1.0)):
        sp = decode_setpoint(four(kind, 5.0, -3.0, 10.0, 0.4))
        assert (sp.mode_roll, sp.mode_pitch, sp.mode_z, sp.mode_x) == (MODE_ABS, MODE_ABS, MODE_ABS, MODE_DISABLE)
        assert sp.attitude[:2] == (5.0, -3.0) and sp.attitude_rate[2] == yaw_sign * 10.0
    sp = decode_setpoint(four(4, 2.0, 1.0, 10.0, 0.3))
    assert sp.mode_z == MODE_VELOCITY and sp.velocity[2] == pytest.approx(0.3) and sp.attitude_rate[2] == 10.0


def test_position_has_no_length_check_and_yaw_in_degrees():
    sp = decode_setpoint(four(7, 1.0, -2.0, 0.5, 90.0))
    assert (sp.mode_x, sp.mode_y, sp.mode_z, sp.mode_yaw) == (MODE_ABS,) * 4
    assert sp.position == (1.0, -2.0, 0.5) and sp.attitude[2] == 90.0
    short = decode_setpoint(bytes([7]) + struct.pack("<ff", 1.0, 2.0))        # no assert in this decoder
    assert short.position == (1.0, 2.0, 0.0)


def test_full_state_units_and_quaternion():
    q = (0.0, 0.0, math.sin(0.4), math.cos(0.4))
    data = struct.pack("<hhhhhhhhhIhhh", 1000, -500, 250, 100, 200, -300, 10, 20, 30, compress_quat(q), 1000, 0, -500)
    sp = decode_setpoint(bytes([6]) + data)
    assert len(data) == EXPECTED_LENGTH[6] == 28
    assert sp.position == (1.0, -0.5, 0.25) and sp.velocity == (0.1, 0.2, -0.3)
    assert sp.acceleration == (0.01, 0.02, 0.03)
    assert sp.mode_quat == MODE_ABS and sp.mode_yaw == MODE_DISABLE
    assert sp.attitude_rate[0] == pytest.approx(math.degrees(1.0))
    assert sp.attitude_rate[2] == pytest.approx(-28.6479, 1e-4)
    assert sp.quaternion == pytest.approx(q, abs=2e-3)


def test_cppm_channels():
    data = bytes([0x01]) + struct.pack("<HHHHH", 2000, 1000, 1500, 1500, 2000)      # aux 0 high: self-levelling
    sp = decode_setpoint(bytes([3]) + data)
    assert sp.mode_roll == MODE_ABS and sp.attitude[0] == -50.0 and sp.attitude[1] == 50.0
    assert sp.thrust == pytest.approx(65535 / 2)
    rate = decode_setpoint(bytes([3, 0x01]) + struct.pack("<HHHHH", 1750, 1500, 1500, 1000, 1000))
    assert rate.mode_roll == MODE_VELOCITY and rate.attitude_rate[0] == -360.0 and rate.thrust == 0.0
    with pytest.raises(FirmwareAssert):
        decode_setpoint(bytes([3, 0x02]) + struct.pack("<HHHHH", 1500, 1500, 1500, 1500, 1500))   # says 2 aux, has 1


def test_stop_and_unknown_types_are_the_zero_setpoint():
    for payload in (b"\x00", b"\x00junk", b"\x0c", b"\xff\x01\x02"):
        sp = decode_setpoint(payload)
        assert sp.is_stop, payload


@pytest.mark.parametrize("kind", [k for k, n in EXPECTED_LENGTH.items() if n is not None])
def test_wrong_length_trips_the_assert(kind):
    n = EXPECTED_LENGTH[kind]
    decode_setpoint(bytes([kind]) + bytes(n))
    for bad in (n - 1, n + 1, 0):
        with pytest.raises(FirmwareAssert, match="type %d" % kind):
            decode_setpoint(bytes([kind]) + bytes(bad))
    with pytest.raises(FirmwareAssert):
        decode_setpoint(b"")


def test_notify_setpoints_stop():
    assert decode_meta(b"\x00" + struct.pack("<I", 100)) == 100
    assert decode_meta(b"\x01abc") is None
    for bad in (b"\x00", b"\x00\x01\x02\x03", b"\x00" + bytes(5), b""):
        with pytest.raises(FirmwareAssert):
            decode_meta(bad)


def test_quaternion_compression_round_trip():
    """The host's encoder and the decoder the simulated firmware uses agree."""
    rng = random.Random(3)
    for _ in range(500):
        q = [rng.gauss(0, 1) for _ in range(4)]
        n = math.sqrt(sum(c * c for c in q))
        q = [c / n for c in q]
        back = decompress_quat(compress_quat(q))
        sign = 1.0 if sum(a * b for a, b in zip(q, back)) >= 0 else -1.0
        assert [sign * c for c in back] == pytest.approx(q, abs=3e-3)
        assert sum(c * c for c in back) == pytest.approx(1.0, abs=1e-9)
    assert decompress_quat(3 << 30) == (0.0, 0.0, 0.0, 1.0)
    with pytest.raises(CommandValueError):
        compress_quat((0, 0, 0, 0))


def test_localization_single_and_packed():
    assert loc.decode_position(struct.pack("<fff", 1.0, 2.0, 3.0)).position == (1.0, 2.0, 3.0)
    assert loc.decode_position(b"\x00" * 11) is None
    pose = loc.decode_pose(struct.pack("<7f", 1, 2, 3, 0, 0, 0, 1))
    assert pose.position == (1, 2, 3) and pose.quaternion == (0, 0, 0, 1)
    items = b"".join(struct.pack("<Bhhh", i, 100 * i, -100 * i, 1000) for i in (3, 5, 7, 9))
    mine, others = loc.decode_packed_positions(items, 5)
    assert mine.position == (0.5, -0.5, 1.0) and others == [3, 7, 9]
    assert loc.decode_packed_positions(items[:7] + b"\x05\x01", 5) == (None, [3])     # partial item ignored
    q = compress_quat((0.0, 0.0, 0.6, 0.8))
    poses = struct.pack("<BhhhI", 2, 10, 20, 30, q) + struct.pack("<BhhhI", 6, -10, -20, 300, q)
    mine, others = loc.decode_packed_poses(poses, 6)
    assert mine.position == (-0.01, -0.02, 0.3) and mine.quaternion == pytest.approx((0, 0, 0.6, 0.8), abs=2e-3)
    assert others == [2] and loc.decode_packed_poses(poses, 4)[0] is None
