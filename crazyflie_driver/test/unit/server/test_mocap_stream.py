"""Motion capture into packed broadcasts: one burst per radio per frame, positions when the orientation
is unusable, the first fix reported once, bad poses dropped."""
from __future__ import annotations

import math
import struct
import threading

from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server.mocap_stream import MocapStream, usable_quaternion
from crazyflie_driver.server.swarm_broadcast import SwarmBroadcaster
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
