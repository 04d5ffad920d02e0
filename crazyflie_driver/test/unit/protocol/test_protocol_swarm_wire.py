"""Port 4/6/7/8/9 packets, byte for byte against what Bitcraze's cflib builds for the same calls.

cflib runs in its own interpreter (``support/cflib_encoders.py``), once for the whole module;
skipped with the reason when cflib is not installed (tools/bootstrap.sh --with-cflib).
"""
from __future__ import annotations

import json
import math
import random
import struct
import subprocess

import pytest
from test_cflib_peer import TEST, cflib_python

from crazyflie_driver.crtp.quaternion import compress_quaternion, decompress_quaternion
from crazyflie_driver.protocol import high_level as hl
from crazyflie_driver.protocol import localization as loc
from crazyflie_driver.protocol import setpoints as sp
from crazyflie_driver.protocol import supervisor as sup
from crazyflie_driver.protocol.memory import chunks, write_packet
from crazyflie_driver.protocol.trajectory import make_piece, pack_compressed, pack_poly4d

ENCODERS = TEST / "support" / "cflib_encoders.py"

_rng = random.Random(14)


def _quat():
    q = [_rng.uniform(-1, 1) for _ in range(4)]
    n = math.sqrt(sum(c * c for c in q))
    return [c / n for c in q]


def _hex(packets):
    if not isinstance(packets, (list, tuple)):
        packets = [packets]
    return [p.to_bytes().hex() for p in packets]


QUATS = [_quat() for _ in range(40)] + [[0, 0, 0, 1], [0, 0, 1, 0], [0.5, 0.5, 0.5, 0.5], [0, 0, -0.7071, 0.7071],
                                       [0.0, 0.0, 0.0, -1.0]]
POLY = ([0.1, 0.2, -0.3, 0.4, 0.01, -0.02, 0.003, -0.0004], [1.0, 0, 0.5, 0, 0, 0, 0, 1e-3],
        [0.5, 0, 0, 0, 0, 0, 0, 0], [0.0, 0.1, 0, 0, 0, 0, 0, 0])

# (id, our packets or bytes, cflib call)
CASES = [
    ("position", _hex(sp.position_packet(1.5, -2.25, 0.5, 90.0)),
     {"api": "commander", "method": "send_position_setpoint", "args": [1.5, -2.25, 0.5, 90.0]}),
    ("velocity world v12", _hex(sp.velocity_world_packet(0.1, -0.2, 0.3, 12.5, 12)),
     {"api": "commander", "method": "send_velocity_world_setpoint", "args": [0.1, -0.2, 0.3, 12.5], "version": 12}),
    ("velocity world v8 (legacy)", _hex(sp.velocity_world_packet(0.1, -0.2, 0.3, 12.5, 8)),
     {"api": "commander", "method": "send_velocity_world_setpoint", "args": [0.1, -0.2, 0.3, 12.5], "version": 8}),
    ("hover v12", _hex(sp.hover_packet(0.4, 0.0, -30.0, 0.7, 12)),
     {"api": "commander", "method": "send_hover_setpoint", "args": [0.4, 0.0, -30.0, 0.7], "version": 12}),
    ("hover v4 (legacy)", _hex(sp.hover_packet(0.4, 0.0, -30.0, 0.7, 4)),
     {"api": "commander", "method": "send_hover_setpoint", "args": [0.4, 0.0, -30.0, 0.7], "version": 4}),
    ("full state", _hex(sp.full_state_packet((1.2345, -0.5, 2.0), (0.1, 0.25, -0.3), (0.0, 1.5, -9.81),
                                             QUATS[0], (0.5, -1.25, 3.0))),
     {"api": "commander", "method": "send_full_state_setpoint",
      "args": [[1.2345, -0.5, 2.0], [0.1, 0.25, -0.3], [0.0, 1.5, -9.81], QUATS[0], 0.5, -1.25, 3.0]}),
    ("stop", _hex(sp.SetpointSender(lambda p: p, 12).stop()),
     {"api": "commander", "method": "send_stop_setpoint"}),
    ("notify setpoints stop", _hex(sp.notify_setpoints_stop_packet(250)),
     {"api": "commander", "method": "send_notify_setpoint_stop", "args": [250]}),
    ("extpos", _hex(loc.external_position_packet(1.0, -2.5, 0.125)),
     {"api": "localization", "method": "send_extpos", "args": [[1.0, -2.5, 0.125]]}),
    ("extpose", _hex(loc.external_pose_packet(1.0, -2.5, 0.125, QUATS[1])),
     {"api": "localization", "method": "send_extpose", "args": [[1.0, -2.5, 0.125], QUATS[1]]}),
    ("set group mask", _hex(hl.set_group_mask_packet(0b101)),
     {"api": "high_level", "method": "set_group_mask", "args": [0b101]}),
    ("takeoff_2 current yaw", _hex(hl.takeoff_packet(0.5, 2.0, 12, group_mask=3)),
     {"api": "high_level", "method": "takeoff", "args": [0.5, 2.0, 3], "kwargs": {"yaw": None}}),
    ("takeoff_2 yaw", _hex(hl.takeoff_packet(0.5, 2.0, 12, yaw=1.25)),
     {"api": "high_level", "method": "takeoff", "args": [0.5, 2.0], "kwargs": {"yaw": 1.25}}),
    ("land_2", _hex(hl.land_packet(0.04, 3.0, 5, group_mask=1)),
     {"api": "high_level", "method": "land", "args": [0.04, 3.0, 1], "kwargs": {"yaw": None}}),
    ("hl stop", _hex(hl.stop_packet(2)), {"api": "high_level", "method": "stop", "args": [2]}),
    ("go_to v7 (old)", _hex(hl.go_to_packet(1.0, 2.0, 0.5, 0.3, 2.5, 7, relative=True, group_mask_=4)),
     {"api": "high_level", "method": "go_to", "args": [1.0, 2.0, 0.5, 0.3, 2.5], "version": 7,
      "kwargs": {"relative": True, "group_mask": 4}}),
    ("go_to_2", _hex(hl.go_to_packet(1.0, 2.0, 0.5, -0.3, 2.5, 12, linear=True)),
     {"api": "high_level", "method": "go_to", "args": [1.0, 2.0, 0.5, -0.3, 2.5], "version": 12,
      "kwargs": {"linear": True}}),
    ("start_trajectory v9 (old)", _hex(hl.start_trajectory_packet(3, 9, 1.5, reversed_=True, relative=True,
                                                                  group_mask_=1)),
     {"api": "high_level", "method": "start_trajectory", "args": [3, 1.5], "version": 9,
      "kwargs": {"relative_position": True, "reversed": True, "group_mask": 1}}),
    ("start_trajectory_2", _hex(hl.start_trajectory_packet(7, 12, 0.5, relative=True, relative_yaw=True)),
     {"api": "high_level", "method": "start_trajectory", "args": [7, 0.5], "version": 12,
      "kwargs": {"relative_position": True, "relative_yaw": True}}),
    ("define poly4d", _hex(hl.define_trajectory_packet(1, 264, 5)),
     {"api": "high_level", "method": "define_trajectory", "args": [1, 264, 5]}),
    ("define compressed", _hex(hl.define_trajectory_packet(2, 0, 4, compressed=True)),
     {"api": "high_level", "method": "define_trajectory", "args": [2, 0, 4, 1]}),
    ("arm v12", _hex(sup.arm_packet(True, 12)), {"api": "supervisor", "method": "send_arming_request",
                                                 "args": [True], "version": 12}),
    ("disarm v7", _hex(sup.arm_packet(False, 7)), {"api": "supervisor", "method": "send_arming_request",
                                                   "args": [False], "version": 7}),
    ("recover v12", _hex(sup.crash_recovery_packet(12)),
     {"api": "supervisor", "method": "send_crash_recovery_request", "version": 12}),
    ("recover v8", _hex(sup.crash_recovery_packet(8)),
     {"api": "supervisor", "method": "send_crash_recovery_request", "version": 8}),
    ("watchdog v12", _hex(sup.watchdog_packet(12)),
     {"api": "supervisor", "method": "send_emergency_stop_watchdog", "version": 12}),
    ("watchdog v7", _hex(sup.watchdog_packet(7)),
     {"api": "supervisor", "method": "send_emergency_stop_watchdog", "version": 7}),
    ("poly4d piece", [pack_poly4d([make_piece(1.75, *POLY)]).hex()],
     {"api": "poly4d", "args": [1.75] + [list(a) for a in POLY]}),
]


@pytest.fixture(scope="module")
def cflib_results():
    python = cflib_python()
    calls = [c for _, _, c in CASES]
    calls += [{"api": "quaternion", "args": q} for q in QUATS]
    piece_bytes = pack_poly4d([make_piece(1.0 + i, *POLY) for i in range(3)])
    calls.append({"api": "mem_write", "args": [3, 396, piece_bytes.hex()]})
    proc = subprocess.run([python, str(ENCODERS)], input=json.dumps(calls), capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads(proc.stdout)
    return {"cases": results[:len(CASES)], "quats": results[len(CASES):len(CASES) + len(QUATS)],
            "mem_write": results[-1], "piece_bytes": piece_bytes}


@pytest.mark.parametrize("index", range(len(CASES)), ids=[c[0] for c in CASES])
def test_same_bytes_as_cflib(cflib_results, index):
    name, ours, _ = CASES[index]
    assert ours == cflib_results["cases"][index], name


def test_quaternion_compression_matches_cflib_and_round_trips(cflib_results):
    for q, (theirs,) in zip(QUATS, cflib_results["quats"]):
        word = compress_quaternion(q)
        assert "%08x" % word == theirs, q
        back = decompress_quaternion(word)
        sign = 1.0 if sum(a * b for a, b in zip(q, back)) >= 0 else -1.0
        assert all(abs(sign * a - b) < 3e-3 for a, b in zip(q, back)), (q, back)


def test_memory_write_chunks_match_cflib(cflib_results):
    data = cflib_results["piece_bytes"]
    ours = [write_packet(3, addr, chunk).to_bytes().hex() for addr, chunk in chunks(396, data)]
    assert ours == cflib_results["mem_write"]
    assert len(ours) == math.ceil(len(data) / 24.0)


def test_compressed_elements_match_cflib(cflib_results):
    """A compressed trajectory's start point and segments laid out as cflib lays them out."""
    python = cflib_python()
    # A cubic in x, linear in z, constant y, degree-7 in yaw, over 2 s.
    piece = make_piece(2.0, [0.25, 0.5, 0.0, -0.05, 0, 0, 0, 0], [1.0] + [0] * 7, [0.5, 0.1] + [0] * 6,
                       [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.001])
    ours = pack_compressed([piece])
    # The same curve as Bezier control points, computed independently from its values:
    # cubic x: b1 = x0 + x'(0)T/3, b2 = x(T) - x'(T)T/3, b3 = x(T).
    T = 2.0
    x = lambda t: 0.25 + 0.5 * t - 0.05 * t ** 3
    dx = lambda t: 0.5 - 0.15 * t ** 2
    xs = [x(0) + dx(0) * T / 3, x(T) - dx(T) * T / 3, x(T)]
    zs = [0.5 + 0.1 * T]
    yaw_end = 0.001 * T ** 7
    yaws = [yaw_end * (1 if i == 7 else 0) for i in range(1, 8)]   # t^7 over [0, T]: only the last point
    calls = [{"api": "compressed_start", "args": [0.25, 1.0, 0.5, 0.0]},
             {"api": "compressed_segment", "args": [2.0, xs, [], zs, yaws]}]
    proc = subprocess.run([python, str(ENCODERS)], input=json.dumps(calls), capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (start,), (segment,) = json.loads(proc.stdout)
    assert ours.hex() == start + segment + "000000"   # our end marker: a segment of duration 0


def test_packed_positions_four_per_packet():
    items = [(i + 1, 0.5 * i, -0.25 * i, 1.0 + 0.001 * i) for i in range(9)]
    packets = loc.packed_position_packets(items)
    assert [len(p.data) for p in packets] == [28, 28, 7]
    assert all((p.port, p.channel) == (6, 2) for p in packets)
    decoded = [struct.unpack_from("<B3h", p.data, 7 * k) for p in packets for k in range(len(p.data) // 7)]
    assert decoded == [(cf, int(x * 1000), int(y * 1000), int(z * 1000)) for cf, x, y, z in items]


def test_packed_poses_two_per_packet_with_compressed_quaternions():
    items = [(10 + i, 0.1 * i, 0.2, 0.3, *QUATS[i]) for i in range(5)]
    packets = loc.packed_pose_packets(items)
    assert [len(p.data) for p in packets] == [23, 23, 12]
    assert all((p.port, p.channel, p.data[0]) == (6, 1, 9) for p in packets)
    decoded = [struct.unpack_from("<B3hI", p.data, 1 + 11 * k) for p in packets for k in range((len(p.data) - 1) // 11)]
    assert [d[0] for d in decoded] == [10, 11, 12, 13, 14]
    assert [d[4] for d in decoded] == [compress_quaternion(QUATS[i]) for i in range(5)]
    assert decoded[3][1:4] == (int(0.1 * 3 * 1000), 200, 300)


def test_address_id_is_the_last_address_byte():
    assert loc.address_id(bytes.fromhex("E7E7E7E705")) == 5
