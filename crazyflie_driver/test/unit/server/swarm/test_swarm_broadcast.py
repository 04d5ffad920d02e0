"""SwarmBroadcaster through two fake dongles: what every radio sends for swarm-wide commands and mocap."""
from __future__ import annotations

import math
import struct
import threading

import pytest

from crazyflie_driver.crtp.quaternion import compress_quaternion
from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import CommandValueError, CrazyflieError, TrajectoryError
from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server.swarm.broadcast import SwarmBroadcaster, group_by_link
from crazyflie_driver.server.swarm.heartbeat import Heartbeat
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.radio_doubles import AirReply, FakeClock, ScriptedMedium

URIS = ["radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702", "radio://0/80/2M/E7E7E7E703",
        "radio://1/90/2M/E7E7E7E704", "radio://1/90/2M/E7E7E7E705"]


def swarm(version=12, repeats=15):
    medium = ScriptedMedium(lambda tx: AirReply(False, retries=tx.arc), dongles=2)
    backend = FakeUsbBackend(medium, dongles=2, timing=DongleTiming.instant())
    clock = FakeClock()
    bc = SwarmBroadcaster(URIS, version, RadioManager(backend), repeats=repeats, sleep=clock.sleep)
    bc.open()
    return bc, medium, clock


def broadcasts(medium):
    return [t for t in medium.transmits if t.address == BROADCAST_ADDRESS]


def test_commands_go_out_repeated_on_every_radio_without_acks():
    bc, medium, clock = swarm()
    assert bc.takeoff(0.5, 2.0, group_mask=2) == 30
    sent = broadcasts(medium)
    assert len(sent) == 30 and not any(t.ack_enabled for t in sent)
    assert sorted((t.dongle, t.channel) for t in sent) == [(0, 80)] * 15 + [(1, 90)] * 15   # the radios in parallel
    assert {t.data for t in sent} == {bytes([0x8C]) + struct.pack("<BBff?f", 7, 2, 0.5, 0.0, True, 2.0)}
    assert clock.time() == pytest.approx(2 * 14 * 0.001)
    bc.close()


def test_go_to_and_start_trajectory_are_always_relative():
    bc, medium, _ = swarm(repeats=1)
    bc.go_to((0.5, 0.0, 0.0), 0.0, 2.0)
    bc.start_trajectory(1, timescale=2.0)
    go_to, start = broadcasts(medium)[0].data, broadcasts(medium)[2].data
    assert go_to[1:5] == bytes([12, 0, 1, 0])            # GO_TO_2, mask 0, relative, not linear
    assert start[1:7] == bytes([13, 0, 1, 0, 0, 1])      # START_TRAJECTORY_2, relative position, id 1
    bc.close()


def test_bad_commands_send_nothing():
    bc, medium, _ = swarm()
    with pytest.raises(CommandValueError, match="group mask"):
        bc.takeoff(0.5, 2.0, group_mask=256)
    with pytest.raises(CommandValueError, match="goal x"):
        bc.go_to((math.nan, 0.0, 0.0), 0.0, 2.0)
    with pytest.raises(TrajectoryError):
        bc.start_trajectory(31)
    assert broadcasts(medium) == []
    bc.close()


def test_emergency_on_every_radio_by_protocol_version():
    bc, medium, _ = swarm(version=4, repeats=3)
    assert bc.emergency() == 6
    assert {t.data for t in broadcasts(medium)} == {bytes([0x6D, 3])}   # 6:1 [3] before protocol 12
    bc.close()


@pytest.mark.parametrize("version,packet", [(12, bytes([0x9D, 1, 1])), (8, bytes([0xDC, 1, 1]))])
def test_arming_every_crazyflie_by_protocol_version(version, packet):
    bc, medium, _ = swarm(version=version, repeats=2)
    assert bc.arm(True) == 4
    assert {t.data for t in broadcasts(medium)} == {packet}        # 9:1 [arm, 1]; 13:0 before protocol 12
    bc.close()


def test_mocap_frame_each_radio_carries_only_its_crazyflies():
    bc, medium, _ = swarm()
    q = (0.0, 0.0, 0.3826834, 0.9238795)
    poses = {uri: (0.5 * i, 1.0, 0.25, *q) for i, uri in enumerate(URIS)}
    assert bc.send_poses(poses) == 3                     # radio 0: 3 poses = 2 packets; radio 1: 2 = 1 packet
    sent = broadcasts(medium)
    assert [(t.dongle, len(t.data)) for t in sent] == [(0, 24), (0, 13), (1, 24)]
    items = [(t.dongle,) + struct.unpack_from("<B3hI", t.data, 2 + 11 * k) for t in sent
             for k in range((len(t.data) - 2) // 11)]
    word = compress_quaternion(q)
    assert items == [(0, 1, 0, 1000, 250, word), (0, 2, 500, 1000, 250, word), (0, 3, 1000, 1000, 250, word),
                     (1, 4, 1500, 1000, 250, word), (1, 5, 2000, 1000, 250, word)]
    before = len(sent)
    assert bc.send_poses({URIS[3]: poses[URIS[3]]}, position_only=True) == 1
    last = broadcasts(medium)[before:]
    assert [(t.dongle, t.data) for t in last] == [(1, bytes([0x6E]) + struct.pack("<B3h", 4, 1500, 1000, 250))]
    with pytest.raises(ValueError, match="not in this swarm"):
        bc.send_poses({"radio://0/80/2M/E7E7E7E709": poses[URIS[0]]})
    bc.close()


def test_the_same_last_address_byte_twice_on_one_channel_is_refused():
    with pytest.raises(ValueError, match="ending 0x01"):
        group_by_link([parse_uri("radio://0/80/2M/E7E7E7E701"), parse_uri("radio://0/80/2M/E7E7E7AA01")])
    assert list(group_by_link([parse_uri("radio://0/80/2M/E7E7E7E701"), parse_uri("radio://1/90/2M/E7E7E7E701")]))


def test_an_unplugged_radio_does_not_keep_a_command_from_the_others():
    medium = ScriptedMedium(lambda tx: AirReply(False, retries=tx.arc, unplugged=tx.dongle == 0), dongles=2)
    backend = FakeUsbBackend(medium, dongles=2, timing=DongleTiming.instant())
    bc = SwarmBroadcaster(URIS, 12, RadioManager(backend), repeats=3, sleep=FakeClock().sleep)
    bc.open()
    with pytest.raises(CrazyflieError, match=r"not sent on 1 of 2 radio links .*radio 0 channel 80"):
        bc.land(0.0, 2.0)
    assert sorted(t.dongle for t in broadcasts(medium) if t.data[1] in (2, 8)) == [0, 1, 1, 1]   # radio 1 took all 3
    bc.close()


def test_the_watchdog_keepalive_is_one_packet_per_radio():
    bc, medium, _ = swarm(version=12)
    assert bc.watchdog() == 2
    assert sorted((t.dongle, t.data) for t in broadcasts(medium)) == [(0, bytes([0x9D, 4])), (1, bytes([0x9D, 4]))]
    bc.close()
    bc, medium, _ = swarm(version=4)
    bc.watchdog()
    assert {t.data for t in broadcasts(medium)} == {bytes([0x6D, 4])}     # localization type 4 before port 9
    bc.close()


def test_the_heartbeat_sends_until_stopped_and_survives_a_failing_radio():
    sent = threading.Semaphore(0)
    calls = []

    def send():
        calls.append(1)
        sent.release()
        if len(calls) == 2:
            raise CrazyflieError("radio 1 channel 90: unplugged")
        return 2

    beat = Heartbeat(send, period_s=0.001).start()
    for _ in range(4):
        assert sent.acquire(timeout=5.0)
    beat.stop()
    n = len(calls)
    assert not beat.running and beat.errors == 1 and beat.sent >= 3
    threading.Event().wait(0.02)
    assert len(calls) == n                     # nothing after stop() returned
    with pytest.raises(ValueError, match="period_s"):
        Heartbeat(send, period_s=0)
