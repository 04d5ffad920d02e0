"""VRPN wire format against byte strings written by hand from docs/mocap.md, plus the
pure helpers around it: Y-up conversion, tracker names, staleness, node parameters."""
from __future__ import annotations

import math
import random
import struct

import pytest

from crazyflie_driver.mocap import frames
from crazyflie_driver.mocap import vrpn_protocol as vp
from crazyflie_driver.mocap.names import clean_tracker_name, is_valid_ros_name
from crazyflie_driver.mocap.staleness import StalenessMonitor
from crazyflie_driver.mocap.vrpn_bridge import VrpnBridge, VrpnConfigError, config_from_params
from crazyflie_driver.mocap.vrpn_client import PoseReport, TwistReport, VrpnSession, parse_server

H = bytes.fromhex

# Sender description of "VRPN Control" (id 0) at t = 0x6553f100 s, 0x0001e240 us, sequence 0:
# length 41 = 24 + 4 + 13, payload int32 13 + "VRPN Control\0", padded to 24 bytes.
SENDER_DESC = (H("00000029" "6553f100" "0001e240" "00000000" "ffffffff" "00000000")
               + H("0000000d") + b"VRPN Control\0" + b"\0" * 7)
# Type description: type id 4 = "vrpn_Tracker Pos_Quat" (21 chars + NUL): length 24 + 4 + 22 = 50.
TYPE_DESC = (H("00000032" "00000000" "00000000" "00000004" "fffffffe" "00000001")
             + H("00000016") + b"vrpn_Tracker Pos_Quat\0" + b"\0" * 6)
# Pos_Quat of sender 1, type 4, sensor 0: pos (1.0, -2.5, 0.5), quat (0, 0, 0.5, -0.75)
POS_QUAT = (H("00000058" "6553f100" "000f4240" "00000001" "00000004" "00000007")
            + H("00000000" "00000000")
            + H("3ff0000000000000" "c004000000000000" "3fe0000000000000")
            + H("0000000000000000" "0000000000000000" "3fe0000000000000" "bfe8000000000000"))
# Velocity of sender 2, type 5, sensor 3: vel (0.25, 0, -1), vel_quat (0,0,0,1), dt 0.125; 72 bytes
VELOCITY = (H("00000060" "00000001" "00000002" "00000002" "00000005" "00000000")
            + H("00000003" "00000003")
            + H("3fd0000000000000" "0000000000000000" "bff0000000000000")
            + H("0000000000000000" "0000000000000000" "0000000000000000" "3ff0000000000000")
            + H("3fc0000000000000"))


# -- cookie ----------------------------------------------------------------------------------
def test_cookie_is_the_24_bytes_a_vrpn_peer_sends():
    assert vp.encode_cookie("07.35") == b"vrpn: ver. 07.35  0" + b"\0" * 5
    assert len(vp.encode_cookie()) == 24
    assert vp.encode_cookie("07.38", log_mode=0) == b"vrpn: ver. 07.38  0\0\0\0\0\0"


def test_cookie_accepts_any_07_minor_and_rejects_other_majors_and_bad_log_modes():
    assert vp.decode_cookie(b"vrpn: ver. 07.33  0" + b"\0" * 5) == ("07.33", 0)
    with pytest.raises(vp.VrpnProtocolError, match="not a VRPN 07"):
        vp.decode_cookie(b"vrpn: ver. 04.00  0" + b"\0" * 5)
    with pytest.raises(vp.VrpnProtocolError, match="log mode"):
        vp.decode_cookie(b"vrpn: ver. 07.35  7" + b"\0" * 5)
    with pytest.raises(vp.VrpnProtocolError, match="24 bytes"):
        vp.decode_cookie(b"vrpn: ver. 07.35  0")


# -- framing ---------------------------------------------------------------------------------
def test_sender_description_matches_the_observed_bytes():
    assert vp.encode_sender_description(0, "VRPN Control", 0x6553f100, 0x1e240) == SENDER_DESC
    assert len(SENDER_DESC) == 48                       # 24 + 17 padded to 24


def test_type_description_carries_the_described_id_in_the_sender_field():
    assert vp.encode_type_description(4, vp.TYPE_POS_QUAT, sequence=1) == TYPE_DESC
    [m] = vp.MessageReader().feed(TYPE_DESC)
    assert (m.type_id, m.sender_id, m.sequence) == (vp.TYPE_DESCRIPTION, 4, 1)
    assert vp.decode_name_payload(m.payload) == "vrpn_Tracker Pos_Quat"


def test_pos_quat_encodes_and_decodes_byte_exact():
    payload = vp.encode_pos_quat(vp.PosQuat(0, (1.0, -2.5, 0.5), (0.0, 0.0, 0.5, -0.75)))
    assert vp.encode_message(4, 1, payload, 0x6553f100, 1000000, 7) == POS_QUAT
    [m] = vp.MessageReader().feed(POS_QUAT)
    assert m.sec == 0x6553f100 and m.usec == 1000000 and m.sender_id == 1 and m.type_id == 4
    assert len(m.payload) == 64                         # length field 88 = 24 + 64, no padding
    assert vp.decode_pos_quat(m.payload) == vp.PosQuat(0, (1.0, -2.5, 0.5), (0.0, 0.0, 0.5, -0.75))


def test_pos_quat_of_wrong_size_is_refused():
    with pytest.raises(vp.VrpnProtocolError, match="64 bytes, got 56"):
        vp.decode_pos_quat(POS_QUAT[24:80])


def test_velocity_encodes_and_decodes_byte_exact():
    v = vp.Velocity(3, (0.25, 0.0, -1.0), (0.0, 0.0, 0.0, 1.0), 0.125)
    assert vp.encode_message(5, 2, vp.encode_velocity(v), 1, 2) == VELOCITY
    assert vp.decode_velocity(VELOCITY[24:]) == v
    with pytest.raises(vp.VrpnProtocolError, match="72 bytes"):
        vp.decode_velocity(VELOCITY[24:-8])


def test_text_and_udp_description_layouts():
    text = vp.encode_message(15, 0, vp.encode_text("hi", vp.TEXT_WARNING, 2))
    assert text[:4] == H("00000023")                    # 24 + 8 + "hi\0"
    assert text[24:] == H("00000001" "00000002") + b"hi\0" + b"\0" * 5
    assert vp.decode_text(text[24:35]) == (1, 2, "hi")
    udp = vp.encode_udp_description(4500, "127.0.0.1")
    assert udp[:24] == H("00000022" "00000000" "00000000" "00001194" "fffffffd" "00000000")
    assert udp[24:] == b"127.0.0.1\0" + b"\0" * 6
    [m] = list(vp.split_datagram(udp))
    assert vp.decode_udp_description(m) == ("127.0.0.1", 4500)


def test_reader_cuts_messages_from_arbitrary_fragments():
    stream = SENDER_DESC + TYPE_DESC + POS_QUAT + VELOCITY
    rng = random.Random(3)
    r = vp.MessageReader()
    got = []
    pos = 0
    while pos < len(stream):
        n = rng.randint(1, 13)
        got += r.feed(stream[pos:pos + n])
        pos += n
    assert [m.type_id for m in got] == [-1, -2, 4, 5]
    assert r.pending == 0
    assert vp.decode_velocity(got[3].payload).dt == 0.125


def test_reader_waits_for_the_padding_before_releasing_a_message():
    r = vp.MessageReader()
    assert r.feed(SENDER_DESC[:41]) == []               # unpadded length present, padding missing
    assert r.feed(SENDER_DESC[41:47]) == []
    assert len(r.feed(SENDER_DESC[47:])) == 1


def test_impossible_length_is_a_framing_error():
    with pytest.raises(vp.VrpnFramingError, match="length field 5"):
        vp.MessageReader().feed(struct.pack(">6i", 5, 0, 0, 0, 4, 0))
    with pytest.raises(vp.VrpnFramingError):
        vp.MessageReader().feed(struct.pack(">6i", 1 << 30, 0, 0, 0, 4, 0))


def test_datagram_with_two_messages_and_a_truncated_one():
    assert [m.type_id for m in vp.split_datagram(POS_QUAT + VELOCITY)] == [4, 5]
    with pytest.raises(vp.VrpnFramingError):
        list(vp.split_datagram(POS_QUAT + VELOCITY[:30]))


def test_description_payload_checks():
    assert vp.encode_name_payload("cf1") == H("00000004") + b"cf1\0"
    with pytest.raises(vp.VrpnProtocolError, match="does not fit"):
        vp.decode_name_payload(H("00001000") + b"abc\0")
    with pytest.raises(vp.VrpnProtocolError, match="empty"):
        vp.decode_name_payload(H("00000001") + b"\0")
    with pytest.raises(ValueError):
        vp.encode_name_payload("x" * 100)


def test_split_time_rounds_into_the_next_second():
    assert vp.split_time(12.5) == (12, 500000)
    assert vp.split_time(12.9999996) == (13, 0)


# -- session (bytes in, reports out) -----------------------------------------------------------
def _described(types=((4, vp.TYPE_POS_QUAT), (5, vp.TYPE_VELOCITY)),
               senders=((0, "VRPN Control"), (1, "cf1"), (2, "Rigid Body 2"))):
    out = b"".join(vp.encode_sender_description(i, n) for i, n in senders)
    return out + b"".join(vp.encode_type_description(i, n) for i, n in types)


def test_session_dispatches_by_described_names_not_numbers():
    poses, twists, found = [], [], []
    s = VrpnSession(on_pose=poses.append, on_twist=twists.append, on_tracker=found.append)
    s.feed(POS_QUAT, 1.0)                               # before any description: dropped
    assert poses == [] and s.stats.undescribed == 1
    s.feed(_described() + POS_QUAT + VELOCITY, 2.0)
    assert found == ["cf1", "Rigid Body 2"]             # "VRPN Control" is not a tracker
    [p] = poses
    assert p == PoseReport("cf1", 0, (1.0, -2.5, 0.5), (0.0, 0.0, 0.5, -0.75), 0x6553f100, 1000000, 2.0)
    [t] = twists
    assert t == TwistReport("Rigid Body 2", 3, (0.25, 0.0, -1.0), (0.0, 0.0, 0.0, 1.0), 0.125, 1, 2, 2.0)
    # the same numbers meaning something else on another server: Pos_Quat is type 9 there
    poses.clear()
    s.reset()
    s.feed(_described(types=((9, vp.TYPE_POS_QUAT), (4, "vrpn_Analog Channel"))) + POS_QUAT, 3.0)
    assert poses == [] and s.stats.ignored >= 1


def test_session_skips_malformed_messages_and_keeps_going():
    poses = []
    s = VrpnSession(on_pose=poses.append)
    bad_pose = vp.encode_message(4, 1, b"\0" * 40)
    bad_desc = vp.encode_message(vp.SENDER_DESCRIPTION, 7, H("00000100") + b"x\0")
    s.feed(_described() + bad_pose + bad_desc + POS_QUAT, 0.0)
    assert s.stats.malformed == 2 and len(poses) == 1


def test_session_filters_trackers_and_survives_a_failing_callback():
    calls = []

    def boom(report):
        calls.append(report.tracker)
        raise RuntimeError("consumer bug")

    s = VrpnSession(trackers=["cf1"], on_pose=boom)
    other = vp.encode_message(4, 2, vp.encode_pos_quat(vp.PosQuat(0, (0, 0, 0), (0, 0, 0, 1))))
    s.feed(_described() + other + POS_QUAT + POS_QUAT, 0.0)
    assert calls == ["cf1", "cf1"] and s.stats.callback_errors == 2 and s.stats.ignored == 1


# -- frames ----------------------------------------------------------------------------------
def _mat_vec(m, v):
    return tuple(sum(m[i][j] * v[j] for j in range(3)) for i in range(3))


def _mat_mul(a, b):
    return tuple(tuple(sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)) for i in range(3))


def _transpose(m):
    return tuple(tuple(m[j][i] for j in range(3)) for i in range(3))


def test_y_up_conversion_is_a_rotation_not_a_mirror():
    r = frames.Y_UP_TO_Z_UP
    assert frames.determinant(r) == pytest.approx(1.0)
    assert _mat_mul(r, _transpose(r)) == ((1, 0, 0), (0, 1, 0), (0, 0, 1))
    swap = ((1, 0, 0), (0, 0, 1), (0, 1, 0))             # the common mistake
    assert frames.determinant(swap) == pytest.approx(-1.0)
    m = frames.quaternion_to_matrix(frames.Y_UP_TO_Z_UP_QUAT)
    for i in range(3):
        assert m[i] == pytest.approx(r[i], abs=1e-12)
    for v in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (0.3, -2, 5)):
        assert frames.y_up_to_z_up_vector(v) == pytest.approx(_mat_vec(r, v))


def test_known_pose_maps_to_ros_axes():
    # Motive: 1 m along X, 1.5 m up (Y), 2 m towards -Z; yawed +90 deg about its up axis (Y)
    s = math.sqrt(0.5)
    pos, quat = frames.y_up_to_z_up_pose((1.0, 1.5, -2.0), (0.0, s, 0.0, s))
    assert pos == (1.0, 2.0, 1.5)                       # x = X, y = -Z, z = Y
    assert quat == pytest.approx((0.0, 0.0, s, s))      # yaw +90 deg about ROS z
    assert frames.yaw_of(quat) == pytest.approx(math.pi / 2)
    # the body's nose (its +X) now points along ROS +y, its up (Motive +Y) along ROS +z
    m = frames.quaternion_to_matrix(quat)
    assert _mat_vec(m, (1, 0, 0)) == pytest.approx((0, 1, 0), abs=1e-12)
    assert _mat_vec(m, (0, 0, 1)) == pytest.approx((0, 0, 1), abs=1e-12)


def test_quaternion_conversion_equals_conjugation_by_the_rotation():
    rng = random.Random(7)
    qr = frames.Y_UP_TO_Z_UP_QUAT
    qr_inv = (-qr[0], -qr[1], -qr[2], qr[3])
    r = frames.Y_UP_TO_Z_UP
    for _ in range(50):
        q = [rng.gauss(0, 1) for _ in range(4)]
        n = math.sqrt(sum(c * c for c in q))
        q = tuple(c / n for c in q)
        want = frames.quaternion_multiply(frames.quaternion_multiply(qr, q), qr_inv)
        got = frames.y_up_to_z_up_quaternion(q)
        assert got == pytest.approx(want, abs=1e-12)
        m_want = _mat_mul(_mat_mul(r, frames.quaternion_to_matrix(q)), _transpose(r))
        m_got = frames.quaternion_to_matrix(got)
        for i in range(3):
            assert m_got[i] == pytest.approx(m_want[i], abs=1e-12)
        assert frames.z_up_to_y_up_quaternion(got) == pytest.approx(q, abs=1e-15)
        v = (rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-3, 3))
        assert frames.z_up_to_y_up_vector(frames.y_up_to_z_up_vector(v)) == v


def test_rotation_vector():
    s = math.sin(0.25)
    assert frames.quaternion_to_rotation_vector((0, 0, s, math.cos(0.25))) == pytest.approx((0, 0, 0.5))
    assert frames.quaternion_to_rotation_vector((0, 0, -s, -math.cos(0.25))) == pytest.approx((0, 0, 0.5))
    assert frames.quaternion_to_rotation_vector((0, 0, 0, 1)) == (0, 0, 0)


# -- names ------------------------------------------------------------------------------------
@pytest.mark.parametrize("raw,clean", [
    ("crazyflie1", "crazyflie1"), ("Rigid Body 1", "RigidBody1"), ("cf-1", "cf1"), ("_cf", "cf"),
    ("1cf", "cf"), ("cf 1.2", "cf12"), ("/room/cf1", "/room/cf1"), ("cf_a", "cf_a"),
    ("12cf", None), ("", None), ("-", None), ("é cf", "cf"), ("~cf", "~cf"),
])
def test_tracker_names_are_cleaned_like_vrpn_client_ros(raw, clean):
    assert clean_tracker_name(raw) == clean
    if clean is not None:
        assert is_valid_ros_name(clean)


# -- staleness --------------------------------------------------------------------------------
def test_staleness_transitions_and_throttled_repeats():
    m = StalenessMonitor(timeout=0.1, warn_period=1.0)
    m.watch("cf2")
    m.seen("cf1", 10.0)
    assert m.check(10.05) == []
    assert m.age("cf1", 10.05) == pytest.approx(0.05)
    [ev] = m.check(10.2)
    assert (ev.name, ev.kind) == ("cf1", "stale") and ev.age == pytest.approx(0.2)
    assert m.check(10.5) == []                          # throttled
    assert [e.kind for e in m.check(11.3)] == ["stale"]  # reminder after warn_period
    m.seen("cf1", 11.4)
    assert [e.kind for e in m.check(11.45)] == ["fresh"]
    rep = {r.name: r for r in m.report(11.45)}
    assert rep["cf1"].stale is False and rep["cf1"].count == 2
    assert rep["cf2"].stale is True and math.isinf(rep["cf2"].age) and rep["cf2"].count == 0
    with pytest.raises(ValueError, match="stale timeout"):
        StalenessMonitor(timeout=0)


# -- node parameters and the bridge ---------------------------------------------------------------
def test_config_defaults_match_vrpn_client_ros():
    c = config_from_params({})
    assert (c.host, c.port, c.frame_id, c.broadcast_tf, c.refresh_tracker_frequency, c.trackers,
            c.use_server_time, c.y_up, c.stale_timeout) == ("localhost", 3883, "world", False, 0.0, [],
                                                            False, False, 0.1)
    assert not c.auto_discover
    c = config_from_params({"server": "10.0.0.5:3884", "frame_id": "/world", "trackers": "cf1, cf2",
                            "refresh_tracker_frequency": 1.0, "y_up": "true"})
    assert (c.host, c.port, c.frame_id, c.trackers, c.auto_discover, c.y_up) == \
        ("10.0.0.5", 3884, "world", ["cf1", "cf2"], True, True)
    assert config_from_params({"server": "10.0.0.5:3884", "port": 3885}).port == 3885


@pytest.mark.parametrize("params,needle", [
    ({"port": "abc"}, "~port"), ({"port": 70000}, "65535"), ({"stale_timeout": 0}, "~stale_timeout"),
    ({"y_up": "maybe"}, "~y_up"), ({"trackers": [1, 2]}, "~trackers"), ({"server": ":3883"}, "no host"),
    ({"refresh_tracker_frequency": -1}, "~refresh_tracker_frequency"),
])
def test_config_errors_name_the_parameter(params, needle):
    with pytest.raises(VrpnConfigError, match=needle):
        config_from_params(params)


def test_parse_server_forms():
    assert parse_server("mocap") == ("mocap", 3883)
    assert parse_server("tcp://192.168.1.2:3890") == ("192.168.1.2", 3890)
    assert parse_server("Tracker0@mocap:3884") == ("mocap", 3884)


def test_bridge_converts_y_up_pose_and_twist():
    s = math.sqrt(0.5)
    b = VrpnBridge(config_from_params({"y_up": True, "refresh_tracker_frequency": 1.0}), clock=lambda: 0.0)
    out = b.pose(PoseReport("Rigid Body 1", 0, (1.0, 1.5, -2.0), (0.0, s, 0.0, s), 5, 6, 1.0))
    assert out.key == "RigidBody1" and out.child_frame == "RigidBody1"
    assert out.position == (1.0, 2.0, 1.5) and out.orientation == pytest.approx((0, 0, s, s))
    # 0.1 rad about Motive's up axis (Y) during dt 0.01 s: 10 rad/s yaw rate about ROS z
    h = math.sin(0.05)
    tw = b.twist(TwistReport("Rigid Body 1", 0, (0.0, 0.0, -1.0), (0.0, h, 0.0, math.cos(0.05)), 0.01, 5, 6, 1.0))
    assert tw.linear == (0.0, 1.0, 0.0)
    assert tw.angular == pytest.approx((0.0, 0.0, 10.0))
    assert b.pose(PoseReport("12", 0, (0, 0, 0), (0, 0, 0, 1), 0, 0, 1.0)) is None
    assert b.staleness.age("RigidBody1", 1.05) == pytest.approx(0.05)


def test_bridge_sensor_keys():
    b = VrpnBridge(config_from_params({"process_sensor_id": True, "trackers": ["cf1"]}))
    out = b.pose(PoseReport("cf1", 2, (0, 0, 0), (0, 0, 0, 1), 0, 0, 1.0))
    assert out.key == "cf1/2" and out.child_frame == "cf1/2"
