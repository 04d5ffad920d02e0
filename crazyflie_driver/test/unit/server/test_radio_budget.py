"""The radio budget: its cost model against the fake dongle's timing (on a virtual clock), and its verdicts."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.radio.broadcast import BroadcastLink
from crazyflie_driver.radio.link import open_link
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server import radio_budget as rb
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.sim_doubles import FakeVehicle


class VirtualClock:
    """The fake dongle's clock: sleeping only moves the time on."""

    def __init__(self) -> None:
        self.t = 0.0

    def time(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += max(0.0, s)


def dongle_with(uris, model="PA"):
    clock = VirtualClock()
    medium = LocalMedium(dongles=1, seed=3)
    backend = FakeUsbBackend(medium, dongles=1, model=model, timing=DongleTiming(), clock=clock)
    for u in uris:
        p = parse_uri(u)
        medium.add_crazyflie(SimulatedCrazyflie(p.address, FakeVehicle()), p.channel, p.datarate)
    return clock, RadioManager(backend)


def seconds_per_round_trip(uris, rounds=50):
    """Virtual dongle time per round trip, the links' packets interleaved as the server's workers do."""
    clock, manager = dongle_with(uris)
    links = [open_link(u, manager) for u in uris]
    try:
        for link in links:          # settle each link's address once before counting
            link.poll()
        t0 = clock.time()
        for _ in range(rounds):
            for link in links:
                assert link.poll()
        return (clock.time() - t0) / (rounds * len(links))
    finally:
        for link in links:
            link.close()


def test_model_figures_are_the_fake_dongles():
    t = DongleTiming()
    assert rb.BULK_ROUND_TRIP_S == t.bulk_round_trip_s
    assert rb.CONTROL_TRANSFER_S == t.control_transfer_s
    assert rb.NO_ACK_PACKET_S == t.no_ack_packet_s
    assert rb.INLINE_NO_ACK_S == pytest.approx(t.inline_no_ack_s)


@pytest.mark.parametrize("uris", [
    ["radio://0/80/2M/E7E7E7E701"],
    ["radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702"],
    ["radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702", "radio://0/80/2M/E7E7E7E703"],
    ["radio://0/80/2M/E7E7E7E701", "radio://0/90/2M/E7E7E7E702"],
    ["radio://0/80/2M/E7E7E7E701", "radio://0/90/1M/E7E7E7E702"],
])
def test_round_trip_cost_matches_the_fake_dongle(uris):
    measured = seconds_per_round_trip(uris)
    modelled = rb.round_trip_cost_s([parse_uri(u) for u in uris])
    assert measured == pytest.approx(modelled, rel=1e-6)
    assert rb.capacity_per_s([parse_uri(u) for u in uris]) == pytest.approx(1.0 / measured)


def test_capacity_figures():
    one = [parse_uri("radio://0/80/2M/E7E7E7E701")]
    two = one + [parse_uri("radio://0/80/2M/E7E7E7E702")]
    assert rb.capacity_per_s(one) == pytest.approx(1250.0)
    assert rb.capacity_per_s(two) == pytest.approx(1 / 0.0023)       # ~435/s


@pytest.mark.parametrize("model, uris, packets, inline", [
    ("PA", ["radio://0/80/2M/E7E7E7E701"], [bytes([0x60]) + bytes(20)] * 3, False),       # one per transfer
    ("PA", ["radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702"], [bytes([0x60]) + bytes(20)] * 3, False),
    ("PA-99.55", ["radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702"], [bytes([0x60]) + bytes(23)] * 4,
     False),                                                                            # two pairs
    ("2.0", ["radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702"], [bytes([0x60]) + bytes(23)] * 4, True),
])
def test_broadcast_burst_cost_matches_the_fake_dongle(model, uris, packets, inline):
    """A unicast round trip, a burst, the next Crazyflie's round trip: the dongle's time is the burst's
    modelled cost (switches, air time) plus that round trip's, for each kind of dongle."""
    clock, manager = dongle_with(uris, model)
    links = [open_link(u, manager) for u in uris]
    bc = BroadcastLink(0, 80, 2, manager)
    bc.open()
    try:
        for link in links:
            link.poll()
        t0 = clock.time()
        bc.send_all(packets)
        links[0].poll()
        spent = clock.time() - t0
        parsed = [parse_uri(u) for u in uris]
        assert bc.sends_inline == inline
        modelled = rb.burst_s(len(packets), parsed, inline) + rb.round_trip_cost_s(parsed, inline)
        assert spent == pytest.approx(modelled, rel=1e-6)
    finally:
        bc.close()
        for link in links:
            link.close()


def demand(name, uri, setpoint_hz=0.0, pose_hz=0.0, log_hz=0.0):
    return rb.CrazyflieDemand(name, parse_uri(uri), setpoint_hz, pose_hz, log_hz)


def test_one_crazyflie_with_default_logging_fits():
    (b,) = rb.check_budget([demand("cf1", "radio://0/80/2M/E7E7E7E701", 100, 0, rb.log_packets_hz(True))])
    assert b.round_trips_hz == pytest.approx(110.0)             # logs dominate: 110 packets/s
    assert b.load == pytest.approx(110 * 0.0008)
    assert b.level == 0 and b.advice == ()


def test_four_logging_crazyflies_on_one_dongle_warn_with_what_to_change():
    ds = [demand("cf%d" % i, "radio://0/80/2M/E7E7E7E70%d" % i, 50, 0, 110) for i in range(1, 5)]
    (b,) = rb.check_budget(ds)
    # 4 x 110 round trips/s x 2.3 ms = 1.012 s per s: more than the dongle has
    assert b.load == pytest.approx(4 * 110 * 0.0023)
    assert b.level == 2
    text = b.message()
    assert "radio 0: 4 Crazyflie(s) need 440 round trips/s = 101 %" in text
    assert "at most 3 of these Crazyflies" in text
    assert "log less" in text


def test_two_dongles_are_budgeted_apart():
    ds = [demand(n, "radio://%d/80/2M/E7E7E7E70%d" % (i // 2, i), 100, 0, 110) for i, n in enumerate("abcd")]
    budgets = rb.check_budget(ds)
    assert [b.index for b in budgets] == [0, 1]
    assert all(b.load == pytest.approx(2 * 110 * 0.0023) and b.level == 0 for b in budgets)


def test_unicast_mocap_advice_and_broadcast_cost():
    ds = [demand("cf%d" % i, "radio://0/80/2M/E7E7E7E70%d" % i, 100, 100, 0) for i in range(1, 4)]
    (b,) = rb.check_budget(ds)
    assert b.round_trips_hz == pytest.approx(600)
    assert b.level == 2
    assert any("broadcast" in a for a in b.advice)
    assert any("high-level commander" in a for a in b.advice)
    # poses by broadcast instead, flown by the high-level commander: a burst of 2 packets per frame,
    # whose switches (3 x 1.5 ms) dominate its 2 x 0.3 ms of air time: 100 frames/s are 58 % of the
    # dongle, 150 frames/s 83 %
    ds = [demand("cf%d" % i, "radio://0/80/2M/E7E7E7E70%d" % i, 0, 0, 0) for i in range(1, 4)]
    for rate, load, level in ((150.0, 0.834, 1), (100.0, 0.579, 0)):
        bc = rb.mocap_broadcast(0, 3, rate)
        assert bc.packets == 2
        (b,) = rb.check_budget(ds, [bc])
        assert b.broadcast_packets_hz == pytest.approx(2 * rate)
        assert b.load == pytest.approx(3 * rb.KEEPALIVE_FLOOR_HZ * 0.0023 + rate * (3 * 0.0015 + 2 * 0.0003))
        assert b.load == pytest.approx(load, abs=0.001)
        assert b.level == level
        assert bool(b.advice) == bool(level)
    (b,) = rb.check_budget(ds, [rb.mocap_broadcast(0, 3, 150.0)])
    assert "broadcast less often or from a Crazyradio of its own, or a Crazyradio 2.0" in b.message()
    # the same on a Crazyradio 2.0 in inline mode: no switch, 0.6 ms a packet, 0.8 ms a keep-alive
    (b,) = rb.check_budget(ds, [rb.mocap_broadcast(0, 3, 150.0, inline=True)])
    assert b.load == pytest.approx(3 * rb.KEEPALIVE_FLOOR_HZ * 0.0008 + 150 * 2 * 0.0006)
    assert b.level == 0


def test_log_estimate_before_connecting():
    assert rb.log_packets_hz(False) == 0.0
    assert rb.log_packets_hz(True, [10, 100]) == pytest.approx(110 + 100 + 10)


def test_demands_for_refuses_a_bad_uri():
    with pytest.raises(ValueError):
        rb.demands_for([("x", "radio://0/80/9M/E7E7E7E701", 0, 0, 0)])


def grid(n, log_hz=0.0):
    return [demand("cf%d" % i, "radio://0/80/2M/E7E7E7E7%02X" % i, log_hz=log_hz) for i in range(1, n + 1)]


def test_mocap_rate_is_the_wanted_one_where_the_dongle_carries_it():
    assert rb.mocap_rate_hz(grid(1), 100.0) == 100.0
    assert rb.mocap_rate_hz([], 100.0) == 100.0


def test_mocap_rate_leaves_the_keepalives_and_the_unicast_reserve_free():
    """17 Crazyflies on one PA (49 on three): 9 pose packets a frame cost 3 switches x 1.5 ms + 9 x 0.3 ms
    of air time = 7.2 ms, so 100 Hz would need 72 % of the dongle; the rate is what remains beside 17
    keep-alives at the floor rate (2.3 ms each, address switches included) and the reserve kept for
    requests: 50 Hz."""
    members = grid(17)
    rate = rb.mocap_rate_hz(members, 100.0)
    burst = rb.burst_s(9, [m.uri for m in members])
    assert burst == pytest.approx(0.0072)
    keepalives = 17 * rb.KEEPALIVE_FLOOR_HZ * 0.0023
    assert rate == pytest.approx((1.0 - rb.UNICAST_RESERVE - keepalives) / burst)
    assert rate == pytest.approx(49.9, abs=0.1)
    budget = rb.check_budget(members, [rb.mocap_broadcast(0, 17, rate)])[0]
    assert budget.load == pytest.approx(1.0 - rb.UNICAST_RESERVE)
    assert rb.mocap_rate_hz(members, 100.0, full_pose=False) > rate          # 5 position packets a frame


def test_49_on_three_radios():
    """49 Crazyflies on three dongles (17 / 16 / 16): the PA's control transfers hold each radio to
    50-55 Hz; a Crazyradio 2.0 in inline mode carries the room's 100 Hz within the 75 % bursts may take."""
    swarm = [demand("cf%d" % i, "radio://%d/80/2M/E7E7E7E7%02X" % (i % 3, i)) for i in range(49)]
    pa = rb.mocap_plan(swarm, 100.0)
    assert [b.packets for b in pa] == [9, 8, 8]
    assert [round(b.frames_hz, 1) for b in pa] == [49.9, 55.4, 55.4]
    two = rb.mocap_plan(swarm, 100.0, inline_dongles={0, 1, 2})
    assert [b.frames_hz for b in two] == [100.0] * 3 and all(b.inline for b in two)
    for b in rb.check_budget(swarm, two):
        assert b.load <= 1.0 - rb.UNICAST_RESERVE and b.level == 0
    assert rb.check_budget(swarm, two)[0].load == pytest.approx(17 * 10 * 0.0008 + 100 * 9 * 0.0006)


def test_mocap_rate_never_below_its_floor():
    assert rb.mocap_rate_hz(grid(40, log_hz=100.0), 100.0) == rb.MOCAP_FLOOR_HZ
    assert rb.mocap_rate_hz(grid(40, log_hz=100.0), 5.0) == 5.0       # a slower motion capture stays as it is


def test_mocap_plan_gives_each_dongle_its_own_rate():
    members = grid(17) + [demand("far", "radio://1/90/2M/E7E7E7E701")]
    plan = rb.mocap_plan(members, 100.0)
    assert [(b.dongle, b.packets) for b in plan] == [(0, 9), (1, 1)]
    assert plan[0].frames_hz == pytest.approx(rb.mocap_rate_hz(grid(17), 100.0)) and plan[1].frames_hz == 100.0


def test_the_pose_topic_period_keeps_its_log_within_its_share():
    uris = lambda n: [parse_uri("radio://0/80/2M/E7E7E7E7%02X" % i) for i in range(1, n + 1)]   # noqa: E731
    assert [rb.pose_log_period_ms(uris(n)) for n in (1, 3, 4, 5, 16, 17)] == [100, 100, 100, 200, 400, 400]
    for n in (1, 4, 9, 17, 40):
        period = rb.pose_log_period_ms(uris(n))
        assert n * (1000.0 / period) * rb.round_trip_cost_s(uris(n)) <= rb.POSE_LOG_SHARE + 1e-9
    periods = rb.pose_log_periods({"a": "radio://0/80/2M/E7E7E7E701", "b": "radio://0/80/2M/E7E7E7E702",
                                   "c": "radio://1/90/2M/E7E7E7E703"})
    assert periods == {"a": 100, "b": 100, "c": 100}
    many = {"cf%d" % i: "radio://%d/80/2M/E7E7E7E7%02X" % (0 if i <= 17 else 1, i) for i in range(1, 21)}
    assert set(rb.pose_log_periods(many).items()) == {("cf%d" % i, 400 if i <= 17 else 100) for i in range(1, 21)}
