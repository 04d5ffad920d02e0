"""Broadcasts in the simulated air: packets to 0xFFE7E7E7E7 with acks off reach every simulated
Crazyflie on that channel and data rate, are never acked, count in radio.numRxBc; the fake
Crazyradio PA with the 99.55 firmware and every 2.0 send an OUT of two equal packets as two radio
packets; a 2.0 in inline mode sends them inline, without a control transfer."""
from __future__ import annotations

import numpy as np
import pytest

from crazyflie_driver.protocol.high_level import takeoff_packet
from crazyflie_driver.protocol.localization import packed_position_packets
from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS, BroadcastLink
from crazyflie_driver.radio.crazyradio import Crazyradio
from crazyflie_driver.radio.link import open_link
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from crazyflie_driver.sim.room.world import World

CHANNEL = 80
SETTLED_MS = 6000      # ms: the 2 s take-off to 0.5 m overshoots by 4-5 cm 1 s after it ends (the PID
                       # chain's z integrator making up the hover thrust above posCtlPid.thrustBase) and
                       # is within 2.5 cm at 6 s


def swarm(model):
    """Four Crazyflies on channel 80 (ids 1-4) and one on channel 90 (id 5), estimator 2."""
    world = World(speed=0, seed=2)
    medium = LocalMedium(dongles=1, seed=2)
    cfs = {}
    for ident in range(1, 6):
        v = world.add_vehicle("cf%d" % ident, position=(0.5 * ident, 0.0, 0.0))
        cf = SimulatedCrazyflie(bytes([0xE7] * 4 + [ident]), v)
        v.write_param("stabilizer.estimator", 2)
        medium.add_crazyflie(cf, CHANNEL if ident < 5 else 90, 2)
        cfs[ident] = cf
    backend = FakeUsbBackend(medium, dongles=1, model=model, timing=DongleTiming.instant())
    return world, medium, backend, RadioManager(backend), cfs


@pytest.mark.parametrize("model,transfers", [("PA", 3), ("PA-99.55", 2), ("2.0", 2), ("2.0-5.0", 2)])
def test_broadcast_reaches_every_crazyflie_on_the_channel_never_acked(model, transfers):
    world, medium, backend, manager, cfs = swarm(model)
    positions = [(ident, 0.5 * ident, 0.0, 0.0) for ident in range(1, 6)]
    packets = packed_position_packets(positions[:4]) * 2           # two full packets: one transfer on 99.55
    with BroadcastLink(0, CHANNEL, manager=manager) as bc:
        dongle = backend.dongles[0]
        bulk_in = dongle.bulk_in
        bc.send_all(packets)
        bc.send(takeoff_packet(0.5, 2.0, 12))
        assert dongle.bulk_in == bulk_in                          # no IN transaction: nothing acked
        assert bc.stats.as_dict() == {"packets": 3, "transfers": transfers, "failed_transfers": 0}
        for ident in range(1, 5):
            assert cfs[ident].state.rx_broadcast == 3
        # motion capture for all of them, broadcast at 100 Hz as swarm servers send it
        def mocap(now):
            names, pos, _ = world.poses()
            bc.send_all(packed_position_packets([(int(n[2:]), *p) for n, p in zip(names, pos)]))
        world.add_tick_listener(mocap, 0.01)
        world.step(SETTLED_MS)
        world.remove_tick_listener(mocap)
    heights = [world.vehicle("cf%d" % i).pose()[0][2] for i in range(1, 6)]
    assert np.allclose(heights[:4], 0.5, atol=0.05) and heights[4] == 0.0    # the takeoff flew on ch 80 only
    for ident in range(1, 5):
        n = cfs[ident].state.rx_broadcast
        assert n > 300 and cfs[ident].read_value("radio.numRxBc") == n
        assert cfs[ident].state.external_measurements > 300 and cfs[ident].read_value("radio.numRxUc") == 0
    assert cfs[5].state.rx_broadcast == 0 and cfs[5].state.external_measurements == 0      # channel 90


def test_broadcast_with_acks_on_is_still_not_acked():
    world, medium, backend, manager, cfs = swarm("PA")
    reply = medium.transmit(0, CHANNEL, 2, BROADCAST_ADDRESS, takeoff_packet(0.5, 2.0, 12).to_bytes(), True, 3)
    assert not reply.acked and reply.retries == 3
    assert all(cfs[i].state.rx_broadcast == 1 for i in range(1, 5))


def test_pa_9955_splits_only_transfers_longer_than_32_bytes():
    """The 99.55 image halves an unacked OUT of more than 32 bytes; one of 32 bytes or less is one packet."""
    world, medium, backend, manager, cfs = swarm("PA-99.55")
    heard = []
    original = cfs[1].handle_broadcast
    cfs[1].handle_broadcast = lambda data: (heard.append(bytes(data)), original(data))
    pair = packed_position_packets([(1, 0.5, 0.0, 0.0)] * 4)[0].to_bytes()           # 30 bytes
    short = takeoff_packet(0.5, 2.0, 12).to_bytes()                                    # 16 bytes
    assert backend.dongles[0].model.bcd_device == 0x9955
    dongle = Crazyradio(0, backend=backend)
    try:
        dongle.set_address(BROADCAST_ADDRESS)
        dongle.set_channel(CHANNEL)
        dongle.send_no_ack(pair + pair)
        dongle.send_no_ack(short + short)
    finally:
        dongle.close()
    assert heard == [pair, pair, short + short]


def test_crazyradio_2_in_inline_mode_broadcasts_inline_without_control_transfers():
    """Once a unicast packet went inline, a burst carries the broadcast address and acks off in each
    packet's header: every Crazyflie on the channel takes it, none acks it, the firmware answers each
    OUT, and no vendor request leaves or re-enters inline mode."""
    world, medium, backend, manager, cfs = swarm("2.0")
    link = open_link("radio://0/%d/2M/E7E7E7E701" % CHANNEL, manager)
    try:
        assert link.poll()
        dongle = backend.dongles[0]
        controls, bulk_in = dongle.control_transfers, dongle.bulk_in
        packets = packed_position_packets([(ident, 0.5 * ident, 0.0, 0.0) for ident in range(1, 5)]) * 2
        with BroadcastLink(0, CHANNEL, manager=manager) as bc:
            assert bc.sends_inline
            assert bc.send_all(packets) == 2
        assert link.poll()
        assert dongle.control_transfers == controls                 # no address, ack or inline request
        assert dongle.bulk_in == bulk_in + 3                        # two inline replies + the poll's
        assert dongle.inline_mode == 1
        for ident in range(1, 5):
            assert cfs[ident].state.rx_broadcast == 2 and cfs[ident].state.external_measurements == 2
        assert cfs[5].state.rx_broadcast == 0
    finally:
        link.close()


def test_crazyradio_2_pairs_only_below_its_64_byte_endpoint():
    """The 2.0 waits for more data after an OUT of exactly 64 bytes: two full 32-byte packets go alone."""
    world, medium, backend, manager, cfs = swarm("2.0")
    dongle = Crazyradio(0, backend=backend)
    try:
        assert dongle.two_per_transfer and dongle.max_pair_bytes == 63
        with pytest.raises(ValueError):
            dongle.send_no_ack(bytes(64))
    finally:
        dongle.close()
