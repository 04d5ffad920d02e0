"""Motion capture into packed broadcasts: one burst per radio per frame, positions when the orientation
is unusable, the first fix reported once, bad poses dropped."""
from __future__ import annotations

import math
import struct
import threading

from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server.swarm.broadcast import SwarmBroadcaster
from crazyflie_driver.server.swarm.mocap_stream import MocapStream, usable_quaternion
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.radio_doubles import AirReply, ScriptedMedium

URIS = {"cf1": "radio://0/80/2M/E7E7E7E701", "cf2": "radio://0/80/2M/E7E7E7E702",
        "cf3": "radio://0/80/2M/E7E7E7E703", "cf4": "radio://1/90/2M/E7E7E7E704"}
Q = (0.0, 0.0, 0.0, 1.0)


def rig():
    medium = ScriptedMedium(lambda tx: AirReply(False, retries=tx.arc), dongles=2)
    backend = FakeUsbBackend(medium, dongles=2, timing=DongleTiming.instant())
    bc = SwarmBroadcaster(list(URIS.values()), 12, RadioManager(backend))
    bc.open()
    return bc, medium


def sent(medium):
    return [(t.dongle, t.data) for t in medium.transmits if t.address == BROADCAST_ADDRESS]


def test_one_frame_is_one_burst_per_radio_with_packed_poses():
    bc, medium = rig()
    fixes = []
    stream = MocapStream(URIS, bc.send_poses, on_first_fix=lambda n, p: fixes.append((n, p)),
                         clock=lambda: 10.0)
    for i, name in enumerate(URIS):
        assert stream.pose(name, (0.1 * i, 0.0, 0.0), Q)
    frame = stream.pending()
    assert stream.send_frame(frame) == 3
    out = sent(medium)
    assert [(d, len(data)) for d, data in out] == [(0, 24), (0, 13), (1, 13)]     # poses: 2 per packet
    assert all(data[:2] == bytes([0x6D, 9]) for _, data in out)                  # port 6 ch 1, packed poses
    ids = [data[2 + 11 * k] for _, data in out for k in range((len(data) - 2) // 11)]
    assert ids == [1, 2, 3, 4]
    assert stream.frames == 1 and stream.poses_sent == 4
    assert stream._fixes.qsize() == 4 and [f for f in fixes] == []              # the fix thread is not running


def test_positions_when_the_orientation_is_missing_or_not_a_quaternion_and_bad_poses_dropped():
    bc, medium = rig()
    stream = MocapStream(URIS, bc.send_poses, clock=lambda: 0.0)
    stream.pose("cf4", (1.0, 2.0, 0.5), (math.nan, 0.0, 0.0, 1.0))
    assert not stream.pose("cf9", (0.0, 0.0, 0.0), Q)               # not in the swarm
    assert not stream.pose("cf1", (math.nan, 0.0, 0.0), Q)         # dropped, never sent
    stream.send_frame(stream.pending())
    assert sent(medium) == [(1, bytes([0x6E]) + struct.pack("<B3h", 4, 1000, 2000, 500))]
    assert usable_quaternion((0.0, 0.0, 0.0, 2.0)) is None and usable_quaternion((0, 0, 0, 1.1)) == (0, 0, 0, 1.0)


def test_the_sender_thread_streams_and_reports_each_first_fix_once():
    bc, medium = rig()
    fixed = []
    done = threading.Event()

    def on_fix(name, position):
        fixed.append((name, position))
        if len(fixed) == 2:
            done.set()

    stream = MocapStream(URIS, bc.send_poses, on_first_fix=on_fix, gather_s=0.0,
                         radio_of=lambda uri: uri.split("/")[2]).start()
    try:
        for k in range(3):
            stream.pose("cf1", (0.0, 0.0, 0.01 * k), Q)
            stream.pose("cf4", (1.0, 0.0, 0.0), Q)
        assert done.wait(5.0)
        for _ in range(500):
            if stream.poses_sent >= 2 and sent(medium):
                break
            threading.Event().wait(0.01)
    finally:
        stream.stop()
    assert fixed == [("cf1", (0.0, 0.0, 0.0)), ("cf4", (1.0, 0.0, 0.0))]
    assert stream.frames >= 1 and all(data[1] == 9 for _, data in sent(medium))


def test_refix_reports_the_next_pose_as_a_first_fix_again():
    """A Crazyflie whose initial-position write failed is placed from its next pose, not never."""
    bc, _ = rig()
    stream = MocapStream(URIS, bc.send_poses, clock=lambda: 0.0)
    stream.pose("cf1", (0.0, 0.0, 0.0), Q)
    stream.pose("cf1", (0.1, 0.0, 0.0), Q)
    assert stream._fixes.qsize() == 1                   # once per Crazyflie ...
    stream.refix("cf1")
    stream.pose("cf1", (0.2, 0.0, 0.0), Q)
    stream.pose("cf1", (0.3, 0.0, 0.0), Q)
    assert [stream._fixes.get_nowait() for _ in range(2)] == [("cf1", (0.0, 0.0, 0.0)), ("cf1", (0.2, 0.0, 0.0))]
    assert stream._fixes.empty()                        # ... and once more after refix


def test_a_radio_s_bursts_keep_the_period_its_budget_allows_and_carry_the_newest_poses():
    """Poses of one Crazyflie arrive faster than the radio's frame period: the bursts keep the period
    (on the stream's clock) and each carries the newest pose that arrived while it waited."""
    now = [0.0]
    fed = [0]
    lock = threading.Condition()
    bursts = []

    def sleep(seconds):          # the sender waits here until this frame's poses are all in
        with lock:
            assert lock.wait_for(lambda: fed[0] > len(bursts), 5.0)
            now[0] += seconds

    def send(poses, position_only):
        with lock:
            bursts.append((now[0], poses["radio://0/80/2M/E7E7E7E701"][2]))
            lock.notify_all()
        return 1

    stream = MocapStream({"cf1": URIS["cf1"]}, send, gather_s=0.001, clock=lambda: now[0], sleep=sleep,
                         frame_periods={0: 0.05}).start()
    try:
        for k in range(6):
            stream.pose("cf1", (0.0, 0.0, 0.1 * k), Q)
            stream.pose("cf1", (0.0, 0.0, 0.1 * k + 0.05), Q)       # replaces the one before, unsent
            with lock:
                fed[0] += 1
                lock.notify_all()
                assert lock.wait_for(lambda: len(bursts) > k, 5.0)
    finally:
        with lock:
            fed[0] += 100
            lock.notify_all()
        stream.stop()
    times = [t for t, _ in bursts]
    assert times[0] == 0.001 and [round(b - a, 9) for a, b in zip(times, times[1:])] == [0.05] * 5
    assert [round(z, 3) for _, z in bursts] == [round(0.1 * k + 0.05, 3) for k in range(6)]


def wire_ids(medium):
    """Crazyflie ids of every packed pose on the air, in order (2 poses of 11 bytes per packet)."""
    return [data[2 + 11 * k] for _, data in sent(medium) for k in range((len(data) - 2) // 11)]


def test_one_out_of_range_pose_never_costs_its_radio_neighbours_their_poses(caplog):
    """cf1 reports a ghost 100 m away every frame (beyond the packed format's +-32.767 m): cf2 and cf3 on
    the same radio still get a pose in every burst, cf1's ghost never goes out, the swarm watch sees only
    the poses that went out (cf1 goes stale and is landed), and the log names cf1 and the value once."""
    from crazyflie_driver.server.swarm.watch import SwarmWatch

    bc, medium = rig()
    now = [0.0]
    watch = SwarmWatch(URIS, stale_after=0.2, hold=0.5)
    stream = MocapStream(URIS, bc.send_poses, clock=lambda: now[0], on_pose=watch.pose_seen)
    stream.pose("cf1", (0.0, 0.0, 0.0), Q)          # one good pose first
    stream.send_frame(stream.take_pending())
    events = []
    frames = 100                                     # 1 s at 100 Hz
    for k in range(1, frames + 1):
        now[0] = 0.01 * k
        assert not stream.pose("cf1", (0.3, -0.2, 100.0), Q)
        assert stream.pose("cf2", (0.5, 0.0, 0.0), Q) and stream.pose("cf3", (1.0, 0.0, 0.0), Q)
        stream.send_frame(stream.take_pending())
        events += [(e.name, e.kind) for e in watch.check(now[0])]
    ids = wire_ids(medium)
    assert ids.count(2) == frames and ids.count(3) == frames and ids.count(1) == 1
    assert stream.sent_by_name == {"cf1": 1, "cf2": frames, "cf3": frames, "cf4": 0}
    assert stream.refused["cf1"] == frames and "z = 100.0" in stream.last_refusal["cf1"]
    assert events == [("cf1", "stale"), ("cf1", "land")]
    assert watch.state("cf2", now[0]) == "ok" and watch.state("cf1", now[0]) == "landing"
    lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert len(lines) == 1 and "cf1" in lines[0] and "100.0" in lines[0]


def test_a_bad_pose_inside_a_frame_is_left_out_and_nan_or_inf_are_refused_by_name(caplog):
    bc, medium = rig()
    stream = MocapStream(URIS, bc.send_poses, clock=lambda: 0.0)
    frame = {"cf1": (0.0, (40.0, 0.0, 0.0), Q), "cf2": (0.0, (0.1, 0.0, 0.0), Q),
             "cf3": (0.0, (-0.1, 0.0, 0.0), None)}
    assert stream.send_frame(frame) == 2            # cf2's pose and cf3's position, cf1 left out
    assert wire_ids(medium)[:1] == [2] and len(sent(medium)) == 2
    for bad in ((math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (0.0, 0.0, -1e300)):
        assert not stream.pose("cf4", bad, Q)
    assert stream.refused == {"cf1": 1, "cf2": 0, "cf3": 0, "cf4": 3}
    lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert len(lines) == 2 and "cf1" in lines[0] and "x = 40.0" in lines[0] and "cf4" in lines[1]


def test_refusals_are_logged_once_per_period_and_crazyflie_with_their_count(caplog):
    bc, _ = rig()
    now = [0.0]
    stream = MocapStream(URIS, bc.send_poses, clock=lambda: now[0])
    for k in range(1200):                           # 12 s of a 100 Hz ghost
        now[0] = 0.01 * k
        stream.pose("cf2", (0.0, 99.0, 0.0), Q)
    lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert len(lines) == 3                          # at 0 s, 5 s and 10 s
    assert "500 since the last report" in lines[1] and "1001 refused in all" in lines[2]


def test_a_ghost_within_the_packed_range_is_refused_as_a_jump_and_a_real_move_is_not():
    """Noise of 100 m puts some ghosts inside +-32.767 m: each is refused by the speed a jump from the
    Crazyflie's last accepted pose would need, so its estimator never sees one; a move at flying speed,
    or a body carried elsewhere while hidden for long enough, is taken."""
    from crazyflie_driver.server.swarm.mocap_stream import MAX_POSE_SPEED_M_S, POSE_JUMP_MARGIN_M

    bc, medium = rig()
    now = [0.0]
    stream = MocapStream(URIS, bc.send_poses, clock=lambda: now[0])
    assert stream.pose("cf1", (0.0, 0.0, 0.5), Q)
    now[0] = 0.01
    assert not stream.pose("cf1", (12.0, -20.0, 6.0), Q)                  # a ghost inside the range
    assert "jumped" in stream.last_refusal["cf1"]
    now[0] = 0.02                                                          # 2 cm in 20 ms: 1 m/s
    assert stream.pose("cf1", (0.02, 0.0, 0.5), Q)
    hidden = (3.0 - POSE_JUMP_MARGIN_M) / MAX_POSE_SPEED_M_S + 0.01        # long enough to explain 3 m
    now[0] = 0.02 + hidden
    assert stream.pose("cf1", (3.02, 0.0, 0.5), Q)
    stream.send_frame(stream.take_pending())
    assert wire_ids(medium).count(1) == 1 and stream.refused["cf1"] == 1
