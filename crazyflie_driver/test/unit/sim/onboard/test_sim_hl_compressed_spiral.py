"""The high-level commander's compressed trajectories, spiral and take-off/landing velocities in the
simulated firmware: decoded against the host library's encoder, flown on the world's true state, and
their malformed forms answered as the firmware answers them."""
from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest
from test_sim_high_level import ask, hl, takeoff
from test_sim_onboard_flight import Rig

from crazyflie_driver.protocol.trajectory import make_piece, pack_compressed
from crazyflie_driver.sim.crtp.trajectory_memory import MEMORY_SIZE, decode_compressed
from crazyflie_driver.sim.onboard.planner import Piece, Plan, figure_eight

TRAJ_MEM = 1      # memory id: the EEPROM is memory 0

ENOEXEC = 8


def host_pieces(pieces):
    return [make_piece(p.duration, *p.coeffs) for p in pieces]


def upload(rig, data, offset=0):
    for at in range(0, len(data), 24):
        header = bytes([TRAJ_MEM]) + struct.pack("<I", offset + at)
        assert ask(rig, 4, 2, header + data[at:at + 24])[-1] == 0


def define_compressed(traj_id, offset, n_pieces=0):
    return struct.pack("<BBBBIB", 6, traj_id, 1, 1, offset, n_pieces)


def start_2(traj_id, relative=False, relative_yaw=False, reversed_=False, timescale=1.0, mask=0):
    return struct.pack("<BBBBBBf", 13, mask, relative, relative_yaw, reversed_, traj_id, timescale)


def spiral(angle, r0, rf, ascent, duration, sideways=False, clockwise=False, mask=0):
    return struct.pack("<BBBBfffff", 11, mask, sideways, clockwise, angle, r0, rf, ascent, duration)


def test_compressed_decodes_to_the_host_encoders_curve():
    pieces = figure_eight(0.6, 0.3, 6.0, 6, 0.5)
    data = pack_compressed(host_pieces(pieces))
    decoded, past_end = decode_compressed(data.ljust(MEMORY_SIZE, b"\x00"), 0)
    assert not past_end and len(decoded) == len(pieces) + 1 and decoded[-1][0] == 0.0   # + the hold at the end
    ours = Plan(1, pieces, 0.0)
    theirs = Plan(1, [Piece(d, c) for d, c in decoded], 0.0)
    for t in np.linspace(0.0, 6.5, 131):
        a, b = ours.evaluate(t), theirs.evaluate(t)
        assert np.abs(a.pos - b.pos).max() < 0.003, t       # mm control points, ms durations
        assert np.abs(a.vel - b.vel).max() < 0.03, t


def test_compressed_yaw_is_scaled_as_the_firmware_scales_it():
    """The firmware divides the stored tenths of a degree by 0.1 and takes the result as radians."""
    data = struct.pack("<4h", 0, 0, 500, 1) + struct.pack("<BH", 0, 0)
    decoded, _ = decode_compressed(data, 0)
    assert decoded[0][1][3, 0] == pytest.approx(10.0) and decoded[0][1][2, 0] == pytest.approx(0.5)


def test_compressed_running_past_the_memory_end_reads_zeros():
    data = bytearray(MEMORY_SIZE)
    data[MEMORY_SIZE - 8:] = struct.pack("<4h", 100, 200, 300, 0)
    decoded, past_end = decode_compressed(data, MEMORY_SIZE - 8)
    assert past_end and len(decoded) == 1 and list(decoded[0][1][:3, 0]) == pytest.approx([0.1, 0.2, 0.3])
    decoded, past_end = decode_compressed(data, MEMORY_SIZE + 100)     # an offset outside the memory
    assert past_end and np.all(decoded[0][1] == 0.0)


def test_compressed_figure_eight_flown_with_mellinger_and_its_refusals():
    rig = Rig()
    rig.param("stabilizer.controller", 2)
    pieces = figure_eight(0.6, 0.3, 6.0, 6, 0.5)
    data = pack_compressed(host_pieces(pieces))
    upload(rig, data, offset=256)
    assert hl(rig, define_compressed(2, 256))[-1] == 0
    assert hl(rig, start_2(2, timescale=2.0))[-1] == ENOEXEC           # compressed: timescale 1 only
    assert hl(rig, start_2(2, reversed_=True))[-1] == ENOEXEC          # and forwards only
    rig.param("hlCommander.groupmask", 1)
    assert hl(rig, start_2(2, timescale=2.0, mask=2))[-1] == 0        # not in the group: nothing to refuse
    hl(rig, takeoff(0.5, 2.0))
    rig.fly(2.5)
    t0 = rig.world.time + 0.005
    assert hl(rig, struct.pack("<BBBBBf", 5, 0, 0, 0, 2, 1.0))[-1] == 0      # the old START_TRAJECTORY
    plan = Plan(1, pieces, t0)
    errors = []
    for _ in range(600):
        rig.fly(0.01)
        errors.append(np.linalg.norm(rig.truth() - plan.evaluate(rig.world.time).pos))
    # the figure starts in motion (0.6 m/s) from a hover: a first-second lag, then it tracks
    assert np.mean(errors) < 0.05 and max(errors[100:]) < 0.08
    rig.fly(1.0)
    assert np.linalg.norm(rig.truth() - (0.0, 0.0, 0.5)) < 0.03           # the end is held


def test_compressed_relative_start_shifts_position_only():
    rig = Rig()
    line = [make_piece(2.0, [0.0, 0.5, 0, 0, 0, 0, 0, 0], [0.0] * 8, [0.5] + [0.0] * 7, [0.0] * 8)]
    upload(rig, pack_compressed(line))
    hl(rig, define_compressed(0, 0))
    hl(rig, takeoff(0.8, 2.0))
    rig.fly(2.5)
    assert hl(rig, start_2(0, relative=True, relative_yaw=True))[-1] == 0
    rig.fly(3.0)
    assert np.linalg.norm(rig.truth() - (1.0, 0.0, 0.8)) < 0.05


def test_spiral_follows_the_firmwares_arc():
    rig = Rig()
    hl(rig, takeoff(0.5, 2.0))
    rig.fly(2.5)
    start = rig.truth()
    centre = start[:2] + (0.0, 0.5)             # counter-clockwise, forward: the centre is to the left
    assert hl(rig, spiral(math.pi / 2, 0.5, 0.5, 0.2, 3.0))[-1] == 0
    radii = []
    for _ in range(300):
        rig.fly(0.01)
        radii.append(np.linalg.norm(rig.truth()[:2] - centre))
    assert max(abs(r - 0.5) for r in radii) < 0.06
    rig.fly(1.5)
    assert np.linalg.norm(rig.truth() - (start[0] + 0.5, start[1] + 0.5, start[2] + 0.2)) < 0.05
    assert rig.vehicle.read("stateEstimate.yaw") == pytest.approx(90.0, abs=3.0)


def test_spiral_arguments_are_limited_as_the_planner_limits_them():
    rig = Rig()
    hl(rig, takeoff(0.5, 2.0))
    rig.fly(2.5)
    plans = rig.world.flight.hl.plans
    assert hl(rig, spiral(20.0, 0.3, 0.3, 0.0, 4.0, clockwise=True))[-1] == 0     # saturated at 2 pi
    end = plans[0].evaluate(rig.world.time + 5.0)
    assert np.linalg.norm(end.pos[:2] - rig.truth()[:2]) < 0.02 and end.yaw == pytest.approx(-2 * math.pi, abs=0.05)
    assert hl(rig, spiral(1.0, -1.0, -2.0, 0.0, 2.0, sideways=True))[-1] == 0     # radii below 0 count as 0
    here = plans[0].evaluate(rig.world.time)
    end = plans[0].evaluate(rig.world.time + 3.0)
    assert np.linalg.norm(end.pos - here.pos) < 1e-6 and end.yaw - here.yaw == pytest.approx(1.0, abs=1e-6)
    assert hl(rig, spiral(1.0, 0.5, 0.5, 0.3, 0.0))[-1] == 0                      # duration 0: the end at once
    assert plans[0].duration == 0.0
    assert hl(rig, spiral(float("nan"), 0.5, 0.5, 0.0, 2.0))[-1] == 0             # accepted, as the firmware does
    rig.fly(0.02)
    # the NaN plan disables the planner: no setpoint at all, the last one holds until the watchdog,
    # which levels out after 0.5 s and stops the motors and locks after 2 s
    assert rig.vehicle.supervisor_flags()["hl_disabled"] and rig.vehicle.motors().max() > 0
    rig.fly(1.5)
    assert rig.vehicle.motors().max() > 0 and rig.vehicle.lock_reason == ""
    rig.fly(1.5)
    state = rig.vehicle.state()
    assert rig.vehicle.lock_reason == "setpoint watchdog" and rig.vehicle.motors().max() == 0
    assert np.all(np.isfinite(state["position"])) and rig.truth()[2] < 0.02
    assert hl(rig, takeoff(0.5, 1.0))[-1] == 16                                   # locked: EBUSY


def test_takeoff_and_landing_velocity_parameters():
    rig = Rig()
    assert rig.cf.params.value("hlCommander.vtoff") == pytest.approx(0.5)
    assert rig.cf.params.value("hlCommander.vland") == pytest.approx(0.5)
    rig.param("hlCommander.vtoff", 0.25)
    rig.param("hlCommander.vland", 1.0)
    with_velocity = struct.Struct("<BBf?f?f")
    assert hl(rig, with_velocity.pack(9, 0, 0.5, False, 0.0, False, 0.0))[-1] == 0   # velocity 0: vtoff
    assert rig.world.flight.hl.plans[0].duration == pytest.approx(2.0, abs=0.01)
    rig.fly(2.5)
    assert rig.truth()[2] == pytest.approx(0.5, abs=0.05)
    assert hl(rig, with_velocity.pack(10, 0, 0.4, True, 0.0, True, -1.0))[-1] == 0   # relative, v <= 0: vland
    assert rig.world.flight.hl.plans[0].duration == pytest.approx(0.4, abs=0.03)
    rig.cf.reboot()
    assert rig.cf.params.value("hlCommander.vtoff") == pytest.approx(0.5)
    assert rig.world.flight.hl.takeoff_velocity[0] == pytest.approx(0.5)


def test_fuzz_ports_8_and_9_never_break_the_world():
    rig = Rig()
    rnd = random.Random(8)
    upload(rig, pack_compressed(host_pieces(figure_eight(0.6, 0.3, 6.0, 3, 0.5))))
    for k in range(1500):
        if k % 3 == 0:                      # the supervisor port: queries, arming, recovery (no e-stop or its watchdog)
            channel = rnd.randrange(2)
            cmd = rnd.choice((1, 2, rnd.randrange(5, 256))) if channel else rnd.randrange(16)
            rig.send(9, channel, bytes([cmd]) + bytes(rnd.randrange(256) for _ in range(rnd.randrange(4))))
        else:
            fuzz_high_level(rig, rnd)
        if k % 10 == 0:
            rig.fly(0.005)
    assert not rig.cf.state.halted and not rig.cf.state.emergency
    state = rig.vehicle.state()
    assert np.all(np.isfinite(state["position"])) and np.all(np.isfinite(state["velocity"]))


def fuzz_high_level(rig, rnd):
    """One random port-8 packet, biased to the trajectory and spiral commands; it always gets its reply."""
    cmd = rnd.choice((5, 6, 11, 13, rnd.randrange(256)))
    body = bytes(rnd.randrange(256) for _ in range(rnd.randrange(28)))
    if cmd == 6:
        body = struct.pack("<BBBI", rnd.randrange(34), 1, rnd.randrange(3), rnd.randrange(5000)) + body[:1]
    elif cmd in (5, 13) and body:
        body = body[:3] + bytes([rnd.randrange(32)]) + body[4:]
    reply = hl(rig, bytes([cmd]) + body)
    assert reply is not None and len(reply) == 5
