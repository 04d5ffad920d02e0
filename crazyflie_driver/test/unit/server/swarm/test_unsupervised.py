"""A Crazyflie of the swarm file that was not added, but listens on a channel the swarm broadcasts on,
is locked on the ground before the first broadcast: on the wire, in the policy's start, and in the
simulated world (where the broadcast takeoff then leaves it on the floor)."""
from __future__ import annotations

import logging
from typing import List, Tuple

import numpy as np
from test_swarm_policy import Port, broadcasts, policy

from crazyflie_driver.crtp.packet import PORT_LOCALIZATION, PORT_SUPERVISOR
from crazyflie_driver.protocol.high_level import takeoff_packet
from crazyflie_driver.protocol.localization import packed_position_packets
from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS, BroadcastLink
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server.swarm.unsupervised import LeftOut, hearing_broadcasts, lock_on_ground, unicast
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from crazyflie_driver.sim.room.world import World
from support.radio_doubles import AirReply

CF2 = "radio://0/80/2M/E7E7E7E702"
CF2_ADDRESS = bytes.fromhex("E7E7E7E702")


def left(name: str, uri: str) -> LeftOut:
    return LeftOut(name, uri, "a fault")


def test_only_the_left_out_on_a_broadcast_channel_and_rate_and_not_a_member_twice():
    members = ["radio://0/80/2M/E7E7E7E701", "radio://1/90/250K/E7E7E7E7E7"]
    cases = [left("a", "radio://0/80/2M/E7E7E7E702"),        # a member's channel and rate: hears them
             left("b", "radio://2/80/2M/E7E7E7E703"),        # ... on another dongle: still on the air there
             left("c", "radio://0/80/250K/E7E7E7E704"),      # another data rate: hears nothing
             left("d", "radio://0/81/2M/E7E7E7E705"),        # another channel
             left("e", "radio://0/80/2M/E7E7E7E701"),        # the member itself, listed twice
             left("f", "radio://1/90/250K"),                 # default address: the second member itself
             left("g", "usb://0"),                           # on a cable
             left("h", "radio://0/80/2M/nonsense")]          # a malformed URI reached nothing
    assert [c.name for c in hearing_broadcasts(cases, members)] == ["a", "b"]


def test_both_emergency_stops_are_sent_and_one_ack_is_enough():
    sent: List[Tuple[int, int, bytes]] = []

    def send(packet):
        sent.append((packet.port, packet.channel, packet.data))
        return packet.port == PORT_SUPERVISOR
    assert lock_on_ground(send) is True
    assert sent == [(PORT_SUPERVISOR, 1, b"\x03"), (PORT_LOCALIZATION, 1, b"\x03")]
    assert lock_on_ground(lambda packet: False) is False


def acks_for(address: bytes):
    """A medium that acks unicast packets to ``address`` only."""
    return lambda tx: AirReply(tx.address == address, retries=0 if tx.address == address else tx.arc)


def estops_to(port: Port, address: bytes) -> List[int]:
    """Indices in the air's transmit log of the emergency stops sent to ``address``."""
    return [i for i, tx in enumerate(port.medium.transmits)
            if tx.address == address and len(tx.data) == 2 and tx.data[1] == 3
            and tx.data[0] >> 4 in (PORT_SUPERVISOR, PORT_LOCALIZATION)]


def test_start_locks_a_left_out_crazyflie_on_the_swarms_channel_before_any_broadcast(caplog):
    port = Port(refuse={"cf2"})
    port.medium.responder = acks_for(CF2_ADDRESS)
    p = policy(port)
    with caplog.at_level(logging.ERROR):
        assert p.start() is True
    assert p.locked == {"cf2": CF2}
    stops = estops_to(port, CF2_ADDRESS)
    assert len(stops) == 2
    assert p.takeoff(0, 0.5, 2.0) > 0
    first_broadcast = port.medium.transmits.index(broadcasts(port)[0])
    assert max(stops) < first_broadcast
    assert "cf2 (%s) was not added" % CF2 in caplog.text and "motors are locked" in caplog.text


def test_one_that_does_not_answer_is_named_and_the_others_still_fly(caplog):
    port = Port(refuse={"cf2"})                 # the default medium acks nothing
    p = policy(port)
    with caplog.at_level(logging.ERROR):
        assert p.start() is True
    assert p.locked == {}
    assert "did not answer an emergency stop" in caplog.text and "switch it off" in caplog.text
    assert p.takeoff(0, 0.5, 2.0) > 0


def test_one_on_a_channel_the_swarm_does_not_broadcast_on_is_left_alone():
    port = Port(refuse={"cf3"})                 # cf3 is alone on channel 90
    port.medium.responder = lambda tx: AirReply(True)
    p = policy(port)
    assert p.start() is True
    assert p.locked == {}
    assert [tx for tx in port.medium.transmits if tx.channel == 90] == []


def test_in_the_world_a_locked_crazyflie_stays_on_the_floor_through_the_broadcast_takeoff():
    world = World(speed=0, seed=5)
    medium = LocalMedium(dongles=1, seed=5)
    for ident in (1, 2):
        v = world.add_vehicle("cf%d" % ident, position=(0.5 * ident, 0.0, 0.0))
        v.write_param("stabilizer.estimator", 2)
        medium.add_crazyflie(SimulatedCrazyflie(bytes([0xE7] * 4 + [ident]), v), 80, 2)
    manager = RadioManager(FakeUsbBackend(medium, dongles=1, timing=DongleTiming.instant()))
    with unicast(CF2, manager) as send:
        assert lock_on_ground(send) is True
    with BroadcastLink(0, 80, manager=manager) as bc:
        bc.send(takeoff_packet(0.5, 2.0, 12))

        def mocap(now):
            names, pos, _ = world.poses()
            bc.send_all(packed_position_packets([(int(n[2:]), *p) for n, p in zip(names, pos)]))
        world.add_tick_listener(mocap, 0.01)
        world.step(3000)
    heights = [world.vehicle(n).pose()[0][2] for n in ("cf1", "cf2")]
    assert np.isclose(heights[0], 0.5, atol=0.1) and heights[1] == 0.0
    assert max(world.vehicle("cf2").read("motor.m%d" % k) for k in range(1, 5)) == 0
    assert BROADCAST_ADDRESS != CF2_ADDRESS
