"""RadioManager / SharedRadio / RadioLink, packet by packet through the fake dongle."""
from __future__ import annotations

import threading
import time

import pytest

from crazyflie_driver.clock import ManualClock
from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import CommandValueError, CrazyflieError, LinkTimeout, RadioUnplugged
from crazyflie_driver.radio.fair_lock import FairLock
from crazyflie_driver.radio.link import RadioLink, open_link
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.radio.statistics import LinkStatistics
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.radio_doubles import AirReply, NrfPeer, ScriptedMedium

URI = "radio://0/80/2M/E7E7E7E701"


class Air:
    """Several NrfPeers on one ScriptedMedium: each packet reaches the peer at its channel/address."""

    def __init__(self, *peers):
        self.peers = list(peers)

    def __call__(self, tx):
        for peer in self.peers:
            if peer.hears(tx):
                return peer(tx)
        return AirReply(False, retries=tx.arc)


def setup(*peers, dongles=1):
    medium = ScriptedMedium(Air(*peers), dongles=dongles)
    backend = FakeUsbBackend(medium, dongles=dongles, timing=DongleTiming.instant())
    return medium, backend, RadioManager(backend)


def headers_for(medium, peer):
    return [t.data[0] for t in medium.transmits if peer.hears(t)]


def test_open_with_safelink_then_sequence_bits():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = RadioLink(URI, manager)
    link.open()
    assert link.safelink and not link.needs_resending
    assert medium.transmits[-1].data == b"\xff\x05\x01"
    assert (medium.transmits[-1].channel, medium.transmits[-1].address) == (80, b"\xe7\xe7\xe7\xe7\x01")
    for i in range(4):
        assert link.send(CRTPPacket(3, 0, bytes([i])))
    sent = [t.data for t in medium.transmits[-4:]]
    # bit 3 = up (0, 1, 0, 1); bit 2 = down, flipped by every fresh downlink (empty acks included)
    assert [d[0] & 0x0C for d in sent] == [0x00, 0x0C, 0x00, 0x0C]
    assert [d[0] & 0xF3 for d in sent] == [0x30] * 4
    assert peer.received == [bytes([0x30, i]) for i in range(4)]
    link.close()


def test_fallback_to_plain_acks_when_the_handshake_is_not_echoed():
    peer = NrfPeer(safelink_capable=False)
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    assert not link.safelink and link.needs_resending
    assert [t.data for t in medium.transmits if peer.hears(t)] == [b"\xff\x05\x01"] * 10
    assert link.send(CRTPPacket(2, 1, b"\x05"))
    assert medium.transmits[-1].data == b"\x2d\x05"       # cflib's header form, bits 3-2 set
    link.close()


def test_open_without_any_ack_raises_and_releases_the_dongle():
    medium, backend, manager = setup()                  # nobody on the air
    link = RadioLink(URI, manager)
    with pytest.raises(LinkTimeout, match="radio://0/80/2M/E7E7E7E701: no answer"):
        link.open()
    assert manager.users(0) == 0
    assert backend.dongles[0].claimed_by is None          # dongle closed again
    assert link.stats.sent == 10 and link.stats.acked == 0


def test_safelink_ack_loss_resends_same_bit_and_the_peer_drops_the_duplicate():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    peer.lose_ack = {peer.count, peer.count + 1}         # the peer hears it, the acks get lost twice
    assert link.send(CRTPPacket(3, 0, b"\x01"))
    tries = [t.data for t in medium.transmits[-3:]]
    assert tries[0] == tries[1] == tries[2]              # same sequence bit every time
    assert peer.received == [b"\x30\x01"]                 # delivered once
    assert link.send(CRTPPacket(3, 0, b"\x02"))
    assert peer.received == [b"\x30\x01", b"\x30\x02"]
    assert link.stats.sent == 1 + 3 + 1 and link.stats.acked == 3


def test_safelink_downlink_delivered_once_despite_lost_acks():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    got = []
    link.subscribe(0, None, got.append)
    peer.queue.extend([b"\x00first", b"\x00second"])
    peer.lose_ack = {peer.count + 1}     # the ack carrying "first" is lost on the 2nd round trip
    for _ in range(6):
        link.poll()
    assert [p.data for p in got] == [b"first", b"second"]


def test_plain_link_dispatch_and_null_acks_ignored():
    peer = NrfPeer(safelink_capable=False)
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    on_port2, on_2_1, anything = [], [], []
    unsubscribe = link.subscribe(2, None, on_port2.append)
    link.subscribe(2, 1, on_2_1.append)
    link.subscribe(0, None, anything.append)
    peer.queue.extend([b"\x28\x00\x01", b"\x29\x07", b"\x00hi"])
    for _ in range(5):
        link.poll()
    assert [(p.port, p.channel, p.data) for p in on_port2] == [(2, 0, b"\x00\x01"), (2, 1, b"\x07")]
    assert [p.data for p in on_2_1] == [b"\x07"]
    assert [p.data for p in anything] == [b"hi"]       # the empty acks (F3/F7) never reach anyone
    unsubscribe()
    peer.queue.append(b"\x28\x09")
    link.poll()
    assert len(on_port2) == 2 and len(on_2_1) == 2 - 1


def test_rssi_from_three_byte_empty_acks():
    peer = NrfPeer(rssi=42)
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    assert link.stats.rssi is None                      # the handshake echo carries no RSSI
    link.poll()
    assert link.stats.rssi == 42
    peer.rssi = 55
    link.poll()
    assert link.stats.rssi == 55


def test_callback_errors_do_not_break_the_sender(caplog):
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    good = []
    link.subscribe(0, None, lambda p: 1 / 0)
    link.subscribe(0, None, good.append)
    peer.queue.append(b"\x00x")
    link.poll()
    assert len(good) == 1
    assert "callback" in caplog.text


def test_request_returns_the_matching_reply():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    peer.on_packet = lambda data: peer.queue.extend([b"\x00noise", bytes([0xDD, 0x00, 0x0C])])
    reply = link.request(CRTPPacket(13, 1, b"\x00"), lambda p: p.port == 13 and p.channel == 1,
                         what="protocol version")
    assert reply == CRTPPacket(13, 1, b"\x00\x0c")
    assert peer.received == [b"\xd1\x00"]


class SteppingClock(ManualClock):
    """A clock that advances ``step`` s per reading: the request loop's schedule, free of the host's load."""

    def __init__(self, step: float):
        super().__init__()
        self.step = step

    def now(self) -> float:
        return self.advance(self.step)


@pytest.mark.parametrize("safelink, sends", [
    pytest.param(False, 5, id="plain acks: first send + one per 50 ms (0.05, 0.10, 0.15, 0.20)"),
    pytest.param(True, 1, id="safelink: sent (and delivered) once"),
])
def test_request_timeout_names_uri_and_what_and_resends_only_without_safelink(safelink, sends):
    clock = SteppingClock(0.001)
    peer = NrfPeer(safelink_capable=safelink)
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager, clock=clock)
    assert link.safelink == safelink
    with pytest.raises(LinkTimeout) as info:
        link.request(CRTPPacket(2, 0, b"\x03"), lambda p: False, timeout=0.25, resend_interval=0.05,
                     what="param TOC info")
    assert "radio://0/80/2M/E7E7E7E701" in str(info.value) and "param TOC info" in str(info.value)
    assert "within 0.25 s" in str(info.value)            # gave up after 0.25 s of silence, on the clock it reads
    handshake = b"\xf3\x05\x01"                         # the safelink greetings a plain peer hears
    assert [r for r in peer.received if r != handshake] == [b"\x20\x03"] * sends


def test_request_timeout_is_counted_on_the_links_clock_not_the_wall_clock():
    """A world running at a tenth of real time: 1 s of its time is 10 s of wall time. The request waits
    for the world's second (1 ms of world time per reading here), not for one wall second."""
    world = SteppingClock(0.0001)
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager, clock=world)
    with pytest.raises(LinkTimeout) as info:
        link.request(CRTPPacket(2, 0, b"\x03"), lambda p: False, timeout=0.05, what="param TOC info")
    assert "within 0.05 s" in str(info.value)
    assert 0.05 <= world.now() < 0.06               # it gave up once 50 ms of the world had passed
    # and an answer that takes longer than the timeout in wall time still arrives within the world's
    peer.on_packet = lambda data: (time.sleep(0.1), peer.queue.append(bytes([0xDD, 0x00, 0x0C])))
    started = time.monotonic()
    reply = link.request(CRTPPacket(13, 1, b"\x00"), lambda p: p.port == 13, timeout=0.05, what="version")
    assert reply == CRTPPacket(13, 1, b"\x00\x0c") and time.monotonic() - started >= 0.1


class SlowAir(Air):
    """Each radio round trip takes ``delay`` s (a busy shared dongle)."""

    def __init__(self, delay, *peers):
        super().__init__(*peers)
        self.delay = delay

    def __call__(self, tx):
        time.sleep(self.delay)
        return super().__call__(tx)


LOG_DATA = bytes([0x52, 0x01, 0, 0, 0]) + b"\x00" * 4      # port 5 channel 2: a log packet


def test_an_answer_queued_behind_log_data_is_waited_for_while_packets_keep_coming():
    peer = NrfPeer(safelink_capable=False)
    medium = ScriptedMedium(SlowAir(0.002, peer))
    manager = RadioManager(FakeUsbBackend(medium, timing=DongleTiming.instant()))
    link = open_link(URI, manager)
    answered = []

    def on_packet(data):
        # the answer joins the queue behind 150 log packets
        if (data[0] & 0xF0) == 0x20 and data[1:] == b"\x03" and not answered:
            answered.append(1)
            peer.queue.extend([LOG_DATA] * 150 + [bytes([0x20, 0x03, 0x2A])])
    peer.on_packet = on_packet
    t0 = time.monotonic()
    reply = link.request(CRTPPacket(2, 0, b"\x03"), lambda p: p.port == 2 and p.data[:1] == b"\x03",
                         timeout=0.1, resend_interval=10.0, what="param TOC info")
    assert reply.data == b"\x03\x2a"
    assert time.monotonic() - t0 > 0.2          # far beyond the 0.1 s of silence allowed
    assert link.downlink_packets >= 151


def test_a_crazyflie_that_streams_but_never_answers_times_out_after_the_queue_drained():
    peer = NrfPeer(safelink_capable=False)
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    peer.on_packet = lambda data: peer.queue.extend([LOG_DATA] * 5000)
    with pytest.raises(LinkTimeout) as info:
        link.request(CRTPPacket(2, 0, b"\x03"), lambda p: False, timeout=0.05, resend_interval=10.0,
                     what="param TOC info")
    text = str(info.value)
    assert "param TOC info" in text and "other packets received" in text
    assert "another program" in text            # every packet acked: the likely cause is named
    assert link.downlink_packets > 2 * 200


def test_request_match_error_is_raised_in_the_requesting_thread():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    peer.queue.append(b"\x00x")
    with pytest.raises(ZeroDivisionError):
        link.request(CRTPPacket(0, 0, b""), lambda p: 1 / 0, timeout=0.5)


def test_statistics_window_and_link_lost():
    stats = LinkStatistics(lost_threshold=5, window=4)
    assert stats.ack_ratio == 0.0 and stats.retries == 0.0
    assert stats.samples == 0
    for acked, retries in [(True, 2), (False, 0), (True, 4), (True, 0)]:
        stats.record(acked, retries)
    assert stats.ack_ratio == 0.75 and stats.retries == 2.0
    stats.record(False, 3)        # pushes out (True, 2)
    assert stats.ack_ratio == 0.5 and stats.retries == 2.0
    assert stats.samples == 4               # the window is full: the oldest round trip left it
    for _ in range(3):
        stats.record(False, 3)
    assert stats.ack_ratio == 0.0 and stats.consecutive_failures == 4 and not stats.link_lost
    stats.record(False, 3)
    assert stats.link_lost and stats.sent == 9 and stats.acked == 3
    stats.record(True, 1)
    assert not stats.link_lost and stats.consecutive_failures == 0


def test_loss_statistics_on_a_link():
    peer = NrfPeer(safelink_capable=False)
    medium, backend, manager = setup(peer)
    link = RadioLink(URI, manager, lost_threshold=20)
    link.open()
    start = peer.count
    peer.lose_uplink = {start + i for i in range(100) if i % 4 == 0}    # every 4th packet lost
    results = [link.poll() for _ in range(100)]
    assert results.count(False) == 25
    assert link.stats.ack_ratio == pytest.approx(0.75)
    peer.lose_uplink = set(range(peer.count, peer.count + 1000))
    for _ in range(19):
        link.poll()
    assert not link.stats.link_lost
    link.poll()
    assert link.stats.link_lost and link.stats.consecutive_failures == 20


def test_safelink_gives_up_then_resynchronises():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = RadioLink(URI, manager, safelink_resends=2)
    link.open()
    peer.lose_uplink = set(range(peer.count, peer.count + 3))
    assert not link.send(CRTPPacket(3, 0, b"\x01"))
    assert peer.received == []
    assert link.send(CRTPPacket(3, 0, b"\x02"))
    assert [t.data for t in medium.transmits[-2:]] == [b"\xff\x05\x01", b"\x30\x02"]
    assert peer.received == [b"\x30\x02"]


def test_two_links_on_one_dongle_reconfigure_only_when_needed():
    a = NrfPeer(channel=80, address=b"\xe7\xe7\xe7\xe7\x01")
    b = NrfPeer(channel=90, address=b"\xe7\xe7\xe7\xe7\x01")
    c = NrfPeer(channel=90, address=b"\xe7\xe7\xe7\xe7\x02")
    medium, backend, manager = setup(a, b, c)
    la = open_link("radio://0/80/2M/E7E7E7E701", manager)
    lb = open_link("radio://0/90/2M/E7E7E7E701", manager)
    lc = open_link("radio://0/90/2M/E7E7E7E702", manager)
    assert manager.users(0) == 3
    dongle = backend.dongles[0]

    def vendor_after(fn):
        before = len(dongle.vendor_requests)
        fn()
        return [(r[1], r[2], r[4]) for r in list(dongle.vendor_requests)[before:]]

    assert vendor_after(lambda: [lc.poll() for _ in range(5)]) == []
    assert vendor_after(lb.poll) == [(0x02, 0, b"\xe7\xe7\xe7\xe7\x01")]   # address only
    assert vendor_after(la.poll) == [(0x01, 80, b"")]                       # channel only
    assert vendor_after(lc.poll) == [(0x01, 90, b""), (0x02, 0, b"\xe7\xe7\xe7\xe7\x02")]
    assert vendor_after(lambda: (lc.poll(), lc.poll())) == []
    assert len(a.received) == len(b.received) == len(c.received) == 0      # polls only


def test_reference_counting_closes_the_dongle_with_the_last_link():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    l1 = open_link(URI, manager)
    l2 = open_link(URI, manager)
    dongle = backend.dongles[0]
    assert dongle.claimed_by is not None
    l1.close()
    l1.close()                                            # idempotent
    assert manager.users(0) == 1 and dongle.claimed_by is not None
    assert l2.poll()
    with pytest.raises(CrazyflieError, match="not open"):
        l1.poll()
    l2.close()
    assert manager.users(0) == 0 and dongle.claimed_by is None
    l3 = open_link(URI, manager)                           # re-opened from scratch
    assert l3.poll()
    l3.close()


def test_two_dongles():
    p0 = NrfPeer(channel=80)
    p1 = NrfPeer(channel=81)
    medium, backend, manager = setup(p0, p1, dongles=2)
    l0 = open_link("radio://0/80/2M/E7E7E7E701", manager)
    l1 = open_link("radio://1/81/2M/E7E7E7E701", manager)
    l0.send(CRTPPacket(3, 0, b"\x00"))
    l1.send(CRTPPacket(3, 0, b"\x01"))
    assert {(t.dongle, t.channel) for t in medium.transmits if t.data[0] & 0xF3 == 0x30} == {(0, 80), (1, 81)}
    assert manager.users(0) == manager.users(1) == 1


def test_unplug_raises_from_send():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    backend.unplug(0)
    with pytest.raises(RadioUnplugged):
        link.send(CRTPPacket(3, 0, b""))
    link.close()
    assert manager.users(0) == 0


def test_link_carries_on_after_the_dongle_is_plugged_back_in():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    shared = manager.acquire(0)
    shared._reopen_interval = 0.0
    backend.unplug(0)
    with pytest.raises(RadioUnplugged):
        link.send(CRTPPacket(3, 0, b""))
    with pytest.raises(RadioUnplugged, match="unplugged"):   # still out: reopening fails cleanly
        link.send(CRTPPacket(3, 0, b""))
    backend.replug(0)
    before = len(medium.transmits)
    assert link.send(CRTPPacket(3, 0, b"\x01")) or link.send(CRTPPacket(3, 0, b"\x01"))
    after = [t for t in medium.transmits[before:]]
    assert after and after[-1].channel == 80 and after[-1].address == bytes.fromhex("E7E7E7E701")
    manager.release(shared)
    link.close()
    assert manager.users(0) == 0


def test_several_threads_share_one_safelink_link():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    got = []
    link.subscribe(0, None, got.append)
    peer.on_packet = lambda data: peer.queue.append(b"\x00" + data[1:])   # echo on port 0
    peer.lose_ack = set(range(peer.count, peer.count + 2000, 7))

    def worker(k):
        for i in range(100):
            assert link.send(CRTPPacket(3, 0, bytes([k, i])))

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    for _ in range(20):
        link.poll()
    expected = sorted(bytes([0x30, k, i]) for k in range(4) for i in range(100))
    assert sorted(peer.received) == expected                       # each exactly once
    assert sorted(p.data for p in got) == sorted(r[1:] for r in expected)
    for k in range(4):                                              # per-thread order kept
        mine = [r for r in peer.received if r[1] == k]
        assert mine == [bytes([0x30, k, i]) for i in range(100)]


@pytest.mark.parametrize("urgent, order", [
    pytest.param((False, False, False, False), [0, 1, 2, 3], id="arrival order"),
    pytest.param((False, False, True, True), [2, 3, 0, 1], id="urgent first, each kind in arrival order"),
])
def test_fair_lock_serves_waiters_in_arrival_order_urgent_ones_first(urgent, order):
    lock = FairLock()
    served = []
    lock.acquire()
    threads = []
    for k, u in enumerate(urgent):
        t = threading.Thread(target=lambda k=k, u=u: (lock.acquire(urgent=u), served.append(k), lock.release()))
        t.start()
        threads.append(t)
        while len(lock._waiters) + len(lock._urgent) < k + 1:
            time.sleep(0.001)
    lock.release()
    for t in threads:
        t.join(5)
    assert served == order
    assert not lock.locked()


def test_fair_lock_times_out_while_held():
    lock = FairLock()
    assert lock.acquire(timeout=0.01)
    assert not FairLock.acquire(lock, timeout=0.01)    # held: times out
    lock.release()
    assert not lock.locked()


def test_setpoints_and_stops_go_first_polls_and_log_traffic_do_not():
    from crazyflie_driver.crtp.packet import is_motor_command
    from crazyflie_driver.protocol.commander import emergency_stop_packet, rpyt_packet, stop_packet
    assert is_motor_command(rpyt_packet(1.0, 2.0, 0.0, 30000).to_bytes())
    assert is_motor_command(stop_packet(12).to_bytes())
    assert is_motor_command(emergency_stop_packet(12).to_bytes())
    assert is_motor_command(emergency_stop_packet(4).to_bytes())     # localization channel 1, older firmware
    assert not is_motor_command(bytes([0xFF]))                       # null packet (poll)
    assert not is_motor_command(bytes([0x5C, 0x03]))                 # log port, safelink bits set
    assert not is_motor_command(bytes([0x20, 0x00, 0x01]))           # param read
    assert not is_motor_command(b"")


def test_safelink_drops_a_downlink_packet_with_the_old_sequence_bit():
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    got = []
    link.subscribe(0, None, got.append)
    # Host expects down = 0: a payload with bit 2 set is a repeat of an earlier one.
    medium.push(AirReply(True, b"\x04repeat"), AirReply(True, b"\x00fresh"), AirReply(True, b"\x04next"))
    assert link.poll() and link.poll() and link.poll()
    assert [p.data for p in got] == [b"fresh", b"next"]
    downs = [t.data[0] & 0x04 for t in medium.transmits[-3:]]
    assert downs == [0x00, 0x00, 0x04]      # flipped only by the fresh packet


@pytest.mark.parametrize("raw", [b"", bytes(32)])
def test_a_packet_that_cannot_exist_is_refused_by_name_and_not_sent(raw):
    peer = NrfPeer()
    medium, backend, manager = setup(peer)
    link = RadioLink(URI, manager)
    link.open()
    before = len(medium.transmits)
    with pytest.raises(CommandValueError, match="header byte and 0..30 payload bytes, got %d bytes" % len(raw)):
        link.send_bytes(raw)
    assert len(medium.transmits) == before
    assert link.send_bytes(b"\xff")         # the link still works


def test_a_request_timeout_counts_what_was_acknowledged_and_names_the_likely_cause():
    # acked, never answered: another program takes the answers; "switched on?" would mislead
    peer = NrfPeer(safelink_capable=False)
    medium, backend, manager = setup(peer)
    link = open_link(URI, manager)
    with pytest.raises(LinkTimeout) as info:
        link.request(CRTPPacket(2, 0, b"\x03"), lambda p: False, timeout=0.05, resend_interval=0.01,
                     what="param TOC info")
    assert info.value.acked > 0 and "switched on" not in str(info.value)
    assert "another program" in str(info.value) and "packets acknowledged" in str(info.value)
    # the Crazyflie went silent after the greeting: nothing acknowledged, the only case for "switched on?"
    peer.lose_uplink = set(range(peer.count, peer.count + 100000))
    with pytest.raises(LinkTimeout) as info:
        link.request(CRTPPacket(2, 0, b"\x03"), lambda p: False, timeout=0.05, resend_interval=0.01,
                     what="param TOC info")
    assert info.value.acked == 0 and "0 of " in str(info.value) and "switched on" in str(info.value)
    link.close()


def test_a_greeting_nobody_acks_is_a_timeout_with_nothing_acknowledged():
    medium, backend, manager = setup(NrfPeer(address=b"\xe7\xe7\xe7\xe7\x09"))
    with pytest.raises(LinkTimeout) as info:
        open_link(URI, manager, safelink_attempts=3)
    assert info.value.acked == 0 and "switched on" in str(info.value)


def test_links_to_crazyflies_on_two_channels_share_a_crazyradio_2_without_vendor_requests():
    one, two = NrfPeer(channel=80), NrfPeer(channel=20, address=b"\xe7\xe7\xe7\xe7\x02")
    medium = ScriptedMedium(Air(one, two))
    backend = FakeUsbBackend(medium, model="2.0", timing=DongleTiming.instant())
    manager = RadioManager(backend)
    links = [RadioLink(URI, manager), RadioLink("radio://0/20/2M/E7E7E7E702", manager)]
    for link in links:
        link.open()
    backend.dongles[0].vendor_requests.clear()
    for i in range(3):
        for link in links:
            assert link.send(CRTPPacket(3, 0, bytes([i])))
    assert list(backend.dongles[0].vendor_requests) == []
    assert [p[1:] for p in one.received[-3:]] == [bytes([i]) for i in range(3)]
    assert [p[1:] for p in two.received[-3:]] == [bytes([i]) for i in range(3)]
    for link in links:
        link.close()
