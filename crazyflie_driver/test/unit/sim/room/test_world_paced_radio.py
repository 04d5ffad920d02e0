"""The fake radio in world time: the world server's replies carry its speed, the dongle's waits scale by it."""
from __future__ import annotations

import time

import pytest
import usb.core

from crazyflie_driver.sim.air.dongle_timing import DongleClock, DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import RemoteMedium
from crazyflie_driver.sim.world_server import WorldServer
from support.sim_doubles import FakeWorld

URI = "radio://0/80/2M/E7E7E7E701"
ADDRESS = bytes.fromhex("E7E7E7E701")


@pytest.fixture
def served():
    world = FakeWorld()
    server = WorldServer(world, dongles=1, host="127.0.0.1", port=0)
    server.add_crazyflie(URI, "cf1")
    server.start()
    medium = RemoteMedium("127.0.0.1", server.port)
    yield world, medium
    medium.close()
    server.stop()


def test_every_radio_reply_carries_the_world_speed(served):
    world, medium = served
    assert medium.speed == 1.0
    world.speed = 0.25
    assert medium.transmit(0, 80, 2, ADDRESS, b"\xff").acked
    assert medium.speed == 0.25
    world.speed = 1.0
    medium.transmit(0, 80, 2, ADDRESS, b"\xff")
    assert medium.speed == 1.0


def round_trips(medium, n: int) -> float:
    """Wall seconds of ``n`` bulk OUT + IN round trips through a world-paced fake dongle."""
    backend = FakeUsbBackend(medium, timing=DongleTiming(), clock=DongleClock.world_paced(medium))
    dev = usb.core.find(idVendor=0x1915, idProduct=0x7777, backend=backend)
    dev.set_configuration(1)
    dev.ctrl_transfer(0x40, 0x01, 80, 0, b"")            # channel 80
    dev.ctrl_transfer(0x40, 0x03, 2, 0, b"")             # 2M
    dev.ctrl_transfer(0x40, 0x02, 0, 0, ADDRESS)         # address
    dev.write(1, b"\xff")
    dev.read(0x81, 64)                                    # the first reply brings the speed
    t0 = time.monotonic()
    for _ in range(n):
        dev.write(1, b"\xff")
        dev.read(0x81, 64)
    return time.monotonic() - t0


def test_a_round_trip_takes_its_air_time_in_world_time(served):
    """0.8 ms of world time per round trip: at a quarter of real time each takes 3.2 ms of wall time."""
    world, medium = served
    world.speed = 0.25
    n = 40
    wall = round_trips(medium, n)
    assert wall >= n * DongleTiming().bulk_round_trip_s / 0.25
    world.speed = 1.0
    assert round_trips(medium, n) < wall                 # back at real time: a quarter of that, plus overhead
