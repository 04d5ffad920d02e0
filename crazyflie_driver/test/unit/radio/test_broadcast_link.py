"""BroadcastLink: no-ack packets to 0xFFE7E7E7E7, sharing a dongle with unicast links."""
from __future__ import annotations

import threading
import time

import pytest

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.protocol.high_level import takeoff_packet
from crazyflie_driver.protocol.localization import packed_pose_packets, packed_position_packets
from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS, BroadcastLink, pair_transfers
from crazyflie_driver.radio.crazyradio import ACK_ENABLE, SET_RADIO_ADDRESS
from crazyflie_driver.radio.link import RadioLink
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.radio_doubles import AirReply, FakeClock, NrfPeer, ScriptedMedium

URI = "radio://0/80/2M/E7E7E7E701"


def setup(peer):
    medium = ScriptedMedium(lambda tx: peer(tx) if peer.hears(tx) else AirReply(False, retries=tx.arc))
    backend = FakeUsbBackend(medium, dongles=1, timing=DongleTiming.instant())
    return medium, backend, RadioManager(backend)


def vendor(backend):
    return [(r[1], r[2], r[4]) for r in backend.dongles[0].vendor_requests]


def test_broadcasts_go_to_the_broadcast_address_without_acks_and_unicast_switches_back():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = RadioLink(URI, manager)
    link.open()
    bc = BroadcastLink(0, 80, manager=manager)
    bc.open()
    assert manager.users(0) == 2
    backend.dongles[0].vendor_requests.clear()
    before = len(medium.transmits)
    packet = takeoff_packet(0.5, 2.0, 12)
    assert bc.send(packet) == 1
    assert bc.send(packet) == 1
    assert link.send(CRTPPacket(3, 0, b"\x01"))
    sent = medium.transmits[before:]
    assert [(t.channel, t.address, t.ack_enabled) for t in sent] == [
        (80, BROADCAST_ADDRESS, False), (80, BROADCAST_ADDRESS, False), (80, peer.address, True)]
    assert sent[0].data == packet.to_bytes()
    # Two vendor requests to switch to broadcast (address, acks off), none between the two
    # broadcasts, two to switch back (address, acks on).
    assert vendor(backend) == [(SET_RADIO_ADDRESS, 0, BROADCAST_ADDRESS), (ACK_ENABLE, 0, b""),
                               (SET_RADIO_ADDRESS, 0, peer.address), (ACK_ENABLE, 1, b"")]
    assert bc.stats.as_dict() == {"packets": 2, "transfers": 2, "failed_transfers": 0}
    bc.close()
    link.close()
    assert manager.users(0) == 0


def test_pairs_only_equal_lengths_in_order():
    a, b, c = b"\x01" * 24, b"\x02" * 24, b"\x03" * 12
    assert pair_transfers([a, b, c], False) == [a, b, c]
    assert pair_transfers([a, b, c], True) == [a + b, c]
    assert pair_transfers([c, a, b], True) == [c, a + b]
    assert pair_transfers([a, c, b], True) == [a, c, b]
    assert pair_transfers([], True) == []


def test_short_packets_stay_single_because_the_dongle_splits_only_transfers_over_32_bytes():
    short = [b"\x04" * 16, b"\x05" * 16, b"\x06" * 10, b"\x07" * 10]
    assert pair_transfers(short, True) == short
    long_pair = [b"\x08" * 17, b"\x09" * 17]
    assert pair_transfers(long_pair, True) == [long_pair[0] + long_pair[1]]


class RecordingRadio:
    """The Crazyradio interface the shared radio and the broadcast link use, recording transfers."""

    def __init__(self, version):
        self.version = version
        is_2 = 1.0 <= version < 99.0
        self.two_per_transfer = version >= 99.55 or is_2
        self.max_pair_bytes = (63 if is_2 else 64) if self.two_per_transfer else 0
        self.inline_capable = False
        self.in_inline_mode = False
        self._channel, self._datarate, self._address = 2, 2, b"\xe7" * 5
        self.ack_enabled = True
        self.transfers = []

    channel = property(lambda self: self._channel)
    datarate = property(lambda self: self._datarate)
    address = property(lambda self: self._address)

    def configure(self, channel, datarate, address):
        self._channel, self._datarate, self._address = channel, datarate, bytes(address)

    def set_ack_enable(self, on):
        self.ack_enabled = on

    def send_no_ack(self, data):
        self.ack_enabled = False
        self.transfers.append((self._channel, self._address, bytes(data)))
        return True

    def close(self):
        pass


@pytest.mark.parametrize("version, expected", [(99.55, [58, 58, 15]), (0.53, [29, 29, 29, 29, 15]),
                                               (5.4, [58, 58, 15]), (5.0, [58, 58, 15])])
def test_packed_mocap_goes_two_packets_per_transfer_where_the_dongle_splits_them(version, expected):
    radio = RecordingRadio(version)
    manager = RadioManager(radio_factory=lambda i: radio)
    positions = packed_position_packets([(i, 0.1 * i, 0.2, 0.3) for i in range(1, 19)])   # 4 + 4 + 4 + 4 + 2
    assert [len(p.to_bytes()) for p in positions] == [29, 29, 29, 29, 15]
    with BroadcastLink(0, 60, manager=manager) as bc:
        taken = bc.send_all(positions)
    assert [len(t[2]) for t in radio.transfers] == expected
    assert taken == len(radio.transfers)
    assert b"".join(t[2] for t in radio.transfers) == b"".join(p.to_bytes() for p in positions)
    assert {(t[0], t[1]) for t in radio.transfers} == {(60, BROADCAST_ADDRESS)}


def test_poses_of_49_crazyflies_in_13_transfers_on_a_splitting_dongle():
    radio = RecordingRadio(99.55)
    manager = RadioManager(radio_factory=lambda i: radio)
    poses = packed_pose_packets([(i, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0) for i in range(49)])
    with BroadcastLink(0, 80, manager=manager) as bc:
        assert bc.send_all(poses) == 13   # 25 packets: 12 pairs + the last one alone
    assert bc.stats.packets == 25


def test_repeats_are_paced_and_each_is_its_own_turn():
    radio = RecordingRadio(0.53)
    manager = RadioManager(radio_factory=lambda i: radio)
    clock = FakeClock()
    with BroadcastLink(0, 80, manager=manager, sleep=clock.sleep) as bc:
        assert bc.send_repeated(takeoff_packet(0.5, 2.0, 12), repeats=15, interval_s=0.001) == 15
    assert len(radio.transfers) == 15 and len(set(t[2] for t in radio.transfers)) == 1
    assert clock.time() == pytest.approx(0.014)


@pytest.mark.parametrize("urgent, expected", [
    (False, "bbbubbb"),      # each burst whole, the unicast round trip in its turn between them
    (True, "bbbbbbu"),       # commands and motion capture go before the polls waiting, as setpoints do
])
def test_a_burst_is_one_turn_of_the_dongle(urgent, expected):
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = RadioLink(URI, manager)
    link.open()
    bc = BroadcastLink(0, 80, manager=manager)
    bc.open()
    burst = packed_position_packets([(i, 0.0, 0.0, 0.0) for i in range(12)])   # 3 packets
    shared = manager.acquire(0)
    before = len(medium.transmits)
    threads = [threading.Thread(target=bc.send_all, args=(burst, urgent)), threading.Thread(target=link.poll),
               threading.Thread(target=bc.send_all, args=(burst, urgent))]
    shared.lock.acquire()            # hold the dongle while all three queue up, in this order
    try:
        for i, t in enumerate(threads):
            t.start()
            deadline = time.monotonic() + 5.0
            while len(shared.lock._waiters) + len(shared.lock._urgent) < i + 1 and time.monotonic() < deadline:
                time.sleep(0.001)
    finally:
        shared.lock.release()
    for t in threads:
        t.join(5.0)
    kinds = "".join("b" if t.address == BROADCAST_ADDRESS else "u" for t in medium.transmits[before:])
    assert kinds == expected
    manager.release(shared)
    bc.close()
    link.close()


def test_the_dongle_takes_two_packets_per_transfer_only_from_firmware_99_55():
    medium, backend, manager = setup(NrfPeer())
    shared = manager.acquire(0)
    radio = shared.radio
    assert radio.version == 0.53 and not radio.two_per_transfer
    with pytest.raises(ValueError, match="1-32 bytes"):
        radio.send_no_ack(b"\x60" * 58)
    assert radio.send_no_ack(b"\x60" * 29) and not radio.ack_enabled
    assert medium.transmits[-1].ack_enabled is False
    manager.release(shared)


def test_bad_use_is_refused_with_a_clear_error():
    radio = RecordingRadio(0.53)
    manager = RadioManager(radio_factory=lambda i: radio)
    bc = BroadcastLink(0, 80, manager=manager)
    with pytest.raises(CrazyflieError, match="not open"):
        bc.send(b"\x30\x00")
    with pytest.raises(CrazyflieError, match="channel"):
        BroadcastLink(0, 126, manager=manager)
    bc.open()
    with pytest.raises(ValueError, match="1-32 bytes"):
        bc.send(b"\x00" * 33)
    with pytest.raises(ValueError, match="repeats"):
        bc.send_repeated(b"\x30", repeats=0)
    assert radio.transfers == []
    bc.close()
