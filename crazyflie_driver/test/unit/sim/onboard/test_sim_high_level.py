"""The simulated high-level commander: planner polynomials, port 8 replies, trajectory memory (port 4),
priorities against low-level setpoints; flights checked on the world's true state."""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from test_sim_onboard_flight import Rig

from crazyflie_driver.sim.crtp.trajectory_memory import POLY4D_PIECE
from crazyflie_driver.sim.onboard.planner import Evaluation, Piece, Plan, evaluate, online_piece, poly7_nojerk

TRAJ_MEM = 1      # memory id: the EEPROM is memory 0


def test_poly7_nojerk_meets_its_constraints():
    c = poly7_nojerk(2.0, (0.1, 0.3, -0.2), (1.5, 0.0, 0.0))
    piece = Piece(2.0, np.vstack([c, c, c, c]))
    for t, (p, v, a) in ((0.0, (0.1, 0.3, -0.2)), (2.0, (1.5, 0.0, 0.0))):
        pp, vv, aa = evaluate(piece, t)
        assert (pp[0], vv[0], aa[0]) == pytest.approx((p, v, a), abs=1e-9)
    n = np.arange(8)
    jerk = lambda t: sum(c[k] * k * (k - 1) * (k - 2) * t ** (k - 3) for k in n[3:])   # noqa: E731
    assert jerk(0.0) == pytest.approx(0.0, abs=1e-9) and jerk(2.0) == pytest.approx(0.0, abs=1e-9)
    assert poly7_nojerk(0.0, (0, 0, 0), (2.0, 0, 0))[0] == 2.0                   # no duration: the goal


def test_online_piece_takes_the_short_way_round_in_yaw():
    start = Evaluation(np.zeros(3), np.zeros(3), np.zeros(3), math.radians(170), 0.0)
    piece = online_piece(1.0, start, (0, 0, 1), math.radians(-170))
    p, _, _ = evaluate(piece, 1.0)
    assert math.degrees(p[3]) == pytest.approx(190.0)


def test_trajectory_playback_timescale_reversed_and_shift():
    c = np.zeros((4, 8))
    c[0, 1] = 1.0                                    # x = t over 2 s
    plan = Plan(1, [Piece(2.0, c)], t_begin=10.0, timescale=2.0)
    assert plan.evaluate(12.0).pos[0] == pytest.approx(1.0) and plan.evaluate(12.0).vel[0] == pytest.approx(0.5)
    back = Plan(1, [Piece(2.0, c)], t_begin=0.0, reversed=True)
    assert back.evaluate(0.5).pos[0] == pytest.approx(1.5) and back.evaluate(0.5).vel[0] == pytest.approx(-1.0)
    assert back.evaluate(5.0).vel[0] == 0.0                                     # after the end: at rest


def ask(rig, port, channel, payload):
    """One packet; its reply (the console's boot text and older replies are drained first)."""
    while rig.cf.pop_outgoing() is not None:
        pass
    rig.send(port, channel, payload)
    return rig.cf.pop_outgoing()


def hl(rig, payload):
    return ask(rig, 8, 0, payload)


def takeoff(height, duration, mask=0):
    return struct.pack("<BBff?f", 7, mask, height, 0.0, False, duration)


def test_takeoff_follows_the_planner_polynomial_and_lands():
    rig = Rig()
    request = takeoff(0.6, 2.0)
    assert hl(rig, request) == b"\x8c" + request[:3] + b"\x00"              # [cmd, byte 1, byte 2, result]
    assert hl(rig, request) == b"\x8c" + request[:3] + b"\x01"              # not idle any more: refused
    piece = online_piece(2.0, Evaluation(np.zeros(3), np.zeros(3), np.zeros(3), 0.0, 0.0), (0, 0, 0.6), 0.0)
    heights, planned = [], []
    for _ in range(400):
        rig.fly(0.01)
        heights.append(rig.truth()[2])
        planned.append(evaluate(piece, rig.world.time)[0][2])
    # the PID position controller ignores the plan's velocity: it lags by about v / kp, then holds
    lag = np.array(planned) - np.array(heights)
    assert np.all(np.diff(heights[:150]) > -1e-3) and 0.05 < lag.max() < 0.3
    assert rig.truth()[2] == pytest.approx(0.6, abs=0.05)
    assert hl(rig, struct.pack("<BBff?f", 8, 0, 0.0, 0.0, False, 2.0))[-1] == 0
    rig.fly(2.5)
    assert rig.vehicle.motors().max() == 0 and rig.truth()[2] < 0.02        # landed: idle, motors off


def test_go_to_relative_and_linear():
    rig = Rig()
    hl(rig, takeoff(0.5, 1.5))
    rig.fly(3.0)
    assert hl(rig, struct.pack("<BBBBfffff", 12, 0, 1, 0, 0.5, -0.5, 0.2, 0.0, 2.0))[-1] == 0   # relative
    rig.fly(3.0)
    assert np.linalg.norm(rig.truth() - (0.5, -0.5, 0.7)) < 0.05
    assert hl(rig, struct.pack("<BBBBfffff", 12, 0, 0, 1, 0.0, 0.0, 0.7, 0.0, 2.0))[-1] == 0    # linear
    rig.fly(3.0)
    assert np.linalg.norm(rig.truth() - (0.0, 0.0, 0.7)) < 0.05


def test_group_mask_decides_who_takes_off():
    rig = Rig()
    rig.param("hlCommander.groupmask", 0b0010)
    hl(rig, takeoff(0.5, 1.0, mask=0b0100))
    rig.fly(1.5)
    assert rig.vehicle.motors().max() == 0
    hl(rig, takeoff(0.5, 1.0, mask=0b0110))
    rig.fly(2.0)
    assert rig.truth()[2] > 0.3


def test_low_level_setpoint_takes_over_and_notify_hands_back():
    rig = Rig()
    hl(rig, takeoff(0.5, 1.0))
    rig.fly(2.0)
    rig.position_setpoint(0.3, 0.0, 0.5)              # priority 2: the planner stops
    rig.fly(3.0)
    assert rig.truth()[0] == pytest.approx(0.3, abs=0.05)
    rig.setpoint = None
    assert hl(rig, struct.pack("<BBBBfffff", 12, 0, 0, 0, -0.3, 0.0, 0.5, 0.0, 1.0))[-1] == 0
    rig.send(7, 1, b"\x00" + struct.pack("<I", 0))    # hands control to the planner: it flies the go_to
    rig.fly(2.5)
    assert rig.truth()[0] == pytest.approx(-0.3, abs=0.05) and rig.vehicle.motors().max() > 0


def notify(rig):
    rig.send(7, 1, b"\x00" + struct.pack("<I", 0))


def test_takeoff_after_low_level_setpoints_flies_only_after_notify():
    """The trap: a connect's zero RPYT setpoints (port 3) take the priority; a takeoff is accepted and
    planned, but its setpoints lose until notify-setpoints-stop, which then flies the plan as it
    stands (here: its end point)."""
    rig = Rig()
    for _ in range(100):
        rig.send(3, 0, struct.pack("<fffH", 0.0, 0.0, 0.0, 0))
    assert hl(rig, takeoff(0.5, 1.0))[-1] == 0                               # accepted
    rig.fly(3.0)
    assert rig.truth()[2] < 0.01 and rig.vehicle.motors().max() == 0         # and ignored
    flags = rig.vehicle.supervisor_flags()
    assert flags["hl_active"] and not flags["hl_disabled"]
    notify(rig)
    rig.fly(3.0)
    assert rig.truth()[2] == pytest.approx(0.5, abs=0.05)


def test_land_while_low_level_holds_the_priority_is_ignored_until_the_watchdog():
    """Streamed setpoints stop and a land follows without notify: the land is accepted but its setpoints
    lose; the last streamed setpoint ages, the watchdog levels out after 0.5 s, stops the motors and
    locks after 2 s. With notify first, the same land flies down softly."""
    for hand_over in (False, True):
        rig = Rig()
        rig.position_setpoint(0.0, 0.0, 0.6)
        rig.fly(3.0)
        rig.setpoint = None
        if hand_over:
            notify(rig)
        assert hl(rig, struct.pack("<BBff?f", 8, 0, 0.0, 0.0, False, 1.5))[-1] == 0
        rig.fly(1.0)
        if hand_over:
            assert rig.truth()[2] < 0.5 and rig.vehicle.lock_reason == ""     # on the way down
            rig.fly(2.5)
            assert rig.truth()[2] < 0.02 and rig.vehicle.motors().max() == 0 and rig.vehicle.lock_reason == ""
        else:
            assert rig.truth()[2] == pytest.approx(0.6, abs=0.05)                # still hovering
            rig.fly(1.5)
            assert rig.vehicle.lock_reason == "setpoint watchdog" and rig.vehicle.motors().max() == 0


def test_notify_hands_over_at_the_planners_next_tick_and_go_to_starts_at_the_estimate():
    """After notify an idle planner stops the motors at its next 100 Hz tick, not at once, so a command
    sent right after it takes over in flight; a go_to from the idle planner starts at the estimated
    position and velocity."""
    rig = Rig()
    rig.position_setpoint(0.0, 0.0, 0.5)
    rig.fly(3.0)
    rig.setpoint = bytes([10]) + struct.pack("<ffff", 0.4, 0.0, 0.0, 0.5)      # hover setpoints, 0.4 m/s along x
    rig.fly(1.0)
    rig.setpoint = None
    notify(rig)
    assert rig.vehicle.motors().min() > 0
    rig.fly(0.011)
    assert rig.vehicle.motors().max() == 0                                     # idle with the priority: stopped
    rig = Rig()
    rig.position_setpoint(0.0, 0.0, 0.5)
    rig.fly(3.0)
    rig.setpoint = bytes([10]) + struct.pack("<ffff", 0.4, 0.0, 0.0, 0.5)
    rig.fly(1.0)
    rig.setpoint = None
    notify(rig)
    estimate = np.array([rig.vehicle.read("stateEstimate." + k) for k in ("x", "y", "z", "vx", "vy", "vz")])
    assert hl(rig, struct.pack("<BBBBfffff", 12, 0, 0, 0, 1.0, 0.0, 0.5, 0.0, 2.0))[-1] == 0
    plan = rig.world.flight.hl.plans[0]
    start = plan.evaluate(plan.t_begin)
    assert np.abs(np.concatenate([start.pos, start.vel]) - estimate).max() < 1e-6 and estimate[3] > 0.3
    lowest = np.inf
    for _ in range(300):
        rig.fly(0.01)
        lowest = min(lowest, rig.vehicle.motors().min())
    assert lowest > 0 and np.linalg.norm(rig.truth() - (1.0, 0.0, 0.5)) < 0.05


def test_a_land_planned_before_notify_takes_over_without_an_idle_tick_however_late_notify_is():
    """The order the host uses: the land goes out while the last streamed setpoint still holds the
    priority (planned, its setpoints lose), notify follows; here 50 ms later, five planner ticks. The
    motors never stop on the way down. Notify first and the land 50 ms later: the idle planner's null
    setpoint stops the motors in the air."""
    for land_first in (True, False):
        rig = Rig()
        rig.position_setpoint(0.0, 0.0, 0.6)
        rig.fly(3.0)
        rig.setpoint = None
        land = struct.pack("<BBff?f", 8, 0, 0.0, 0.0, False, 1.5)
        if land_first:
            assert hl(rig, land)[-1] == 0
        else:
            notify(rig)
        lowest = np.inf
        for _ in range(5):
            rig.fly(0.01)
            lowest = min(lowest, rig.vehicle.motors().min())
        if land_first:
            notify(rig)
        else:
            assert hl(rig, land)[-1] == 0
        in_the_air = np.inf                     # the lowest motor command while above 0.2 m
        for _ in range(150):
            rig.fly(0.01)
            if rig.truth()[2] > 0.2:
                in_the_air = min(in_the_air, rig.vehicle.motors().min())
        if land_first:
            assert lowest > 0 and in_the_air > 0
            rig.fly(1.0)
            assert rig.truth()[2] < 0.02 and rig.vehicle.lock_reason == ""
        else:
            assert lowest == 0                                                   # stopped in the air


def figure_eight_pieces():
    """Two pieces drawing an ellipse-like loop at 0.5 m: enough to test upload and playback."""
    pieces = []
    for k in range(4):
        c = np.zeros((4, 8))
        angle0 = k * math.pi / 2
        c[0] = poly7_nojerk(1.5, (0.5 * math.cos(angle0), 0, 0), (0.5 * math.cos(angle0 + math.pi / 2), 0, 0))
        c[1] = poly7_nojerk(1.5, (0.3 * math.sin(angle0), 0, 0), (0.3 * math.sin(angle0 + math.pi / 2), 0, 0))
        c[2, 0] = 0.5
        pieces.append((1.5, c))
    return pieces


def test_trajectory_upload_define_start_and_errors():
    rig = Rig()
    data = b"".join(POLY4D_PIECE.pack(*c.reshape(-1), d) for d, c in figure_eight_pieces())
    for offset in range(0, len(data), 24):                           # memory writes, 24 bytes each
        header = bytes([TRAJ_MEM]) + struct.pack("<I", offset)
        assert ask(rig, 4, 2, header + data[offset:offset + 24]) == b"\x4e" + header + b"\x00"
    assert ask(rig, 4, 2, bytes([TRAJ_MEM]) + struct.pack("<I", 4090) + bytes(8))[-1] == 5    # past the end: EIO
    assert ask(rig, 4, 1, bytes([TRAJ_MEM]) + struct.pack("<IB", 132, 20))[6:] == b"\x00" + data[132:152]   # read back
    assert hl(rig, struct.pack("<BBBBIB", 6, 31, 1, 0, 0, 4))[-1] == 8    # id out of range: ENOEXEC
    assert hl(rig, struct.pack("<BBBBBBf", 13, 0, 0, 0, 0, 3, 1.0))[-1] == 8   # undefined: ENOEXEC
    assert hl(rig, struct.pack("<BBBBIB", 6, 3, 1, 0, 4000, 4))[-1] == 0       # defined, overflowing
    assert hl(rig, struct.pack("<BBBBBBf", 13, 0, 0, 0, 0, 3, 1.0))[-1] == 8
    assert hl(rig, struct.pack("<BBBBIB", 6, 3, 1, 0, 0, 4))[-1] == 0
    assert hl(rig, bytes([99]))[-1] == 8                                        # unknown command
    hl(rig, takeoff(0.5, 1.5))
    rig.fly(2.0)
    hl(rig, struct.pack("<BBBBfffff", 12, 0, 0, 0, 0.5, 0.0, 0.5, 0.0, 1.5))
    rig.fly(2.0)
    assert hl(rig, struct.pack("<BBBBBBf", 13, 0, 0, 0, 0, 3, 1.0))[-1] == 0
    errs = []
    plan = Plan(1, [Piece(d, c) for d, c in figure_eight_pieces()], rig.world.time)
    for _ in range(600):
        rig.fly(0.01)
        errs.append(np.linalg.norm(rig.truth() - plan.evaluate(rig.world.time).pos))
    # the path is followed with the PID controller's lag (no feed-forward: about v / kp = 0.2 m at
    # this speed), and the end point is held
    assert np.mean(errs) < 0.3 and max(errs) < 0.4
    rig.fly(3.0)
    assert np.linalg.norm(rig.truth() - plan.evaluate(rig.world.time).pos) < 0.05


def test_mellinger_tracks_the_figure_eight_with_feed_forward():
    from crazyflie_driver.sim.onboard.planner import figure_eight
    errors = {}
    for controller in (1, 2):
        rig = Rig()
        rig.param("stabilizer.controller", controller)
        assert rig.cf.params.value("ctrlMel.massThrust") == 132000.0
        hl(rig, takeoff(0.5, 2.0))
        rig.fly(4.0)
        pieces = figure_eight(0.6, 0.3, 6.0, 6, 0.5)
        data = b"".join(POLY4D_PIECE.pack(*p.coeffs.reshape(-1), p.duration) for p in pieces)
        for offset in range(0, len(data), 24):
            ask(rig, 4, 2, bytes([TRAJ_MEM]) + struct.pack("<I", offset) + data[offset:offset + 24])
        hl(rig, struct.pack("<BBBBIB", 6, 1, 1, 0, 0, len(pieces)))
        assert hl(rig, struct.pack("<BBBBBBf", 13, 0, 0, 0, 0, 1, 1.0))[-1] == 0
        plan = Plan(1, pieces, rig.world.time)
        errs = []
        for _ in range(600):
            rig.fly(0.01)
            errs.append(np.linalg.norm(rig.truth() - plan.evaluate(rig.world.time).pos))
        errors[controller] = float(np.mean(errs))
    assert errors[2] < 0.05 and errors[1] > 3 * errors[2], errors     # feed-forward vs none


def test_mellinger_quirk_hover_setpoints_have_no_horizontal_control():
    moved = {}
    for controller in (1, 2):
        rig = Rig()
        rig.param("stabilizer.controller", controller)
        hl(rig, takeoff(0.5, 1.5))
        rig.fly(3.0)
        start = rig.truth().copy()
        rig.setpoint = bytes([10]) + struct.pack("<ffff", 0.3, 0.0, 0.0, 0.5)
        rig.fly(2.0)
        moved[controller] = rig.truth() - start
        assert rig.truth()[2] == pytest.approx(0.5, abs=0.08)                 # z is held by both
    assert moved[1][0] > 0.3 and abs(moved[2][0]) < 0.05, moved
