"""The world server's vehicle_state control op: the true body state of a simulated Crazyflie."""
from __future__ import annotations

import pytest

from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.sim.air.medium import RemoteMedium
from crazyflie_driver.sim.room.world import World
from crazyflie_driver.sim.world_server import WorldServer


def test_vehicle_state_by_uri_and_name():
    world = World(speed=0.0, seed=1)
    server = WorldServer(world, port=0, seed=1)
    server.add_crazyflie("radio://0/80/2M/E7E7E7E701", "cf1", (0.5, -0.25, 0.0))
    host, port = server.start()
    try:
        world.step(100)
        medium = RemoteMedium(host, port)
        by_uri = medium.control("vehicle_state", uri="radio://0/80/2M/E7E7E7E701")
        by_name = medium.control("vehicle_state", uri="cf1")
        assert by_uri["name"] == by_name["name"] == "cf1"
        assert by_uri["position"][:2] == pytest.approx([0.5, -0.25], abs=1e-6)
        assert by_uri["motors"] == [0, 0, 0, 0] and by_uri["on_ground"]
        with pytest.raises(CrazyflieError, match="E7E7E7E7AA"):
            medium.control("vehicle_state", uri="radio://0/80/2M/E7E7E7E7AA")
    finally:
        server.stop()


def test_poses_of_every_body_at_one_instant():
    world = World(speed=0.0, seed=1)
    server = WorldServer(world, port=0, seed=1)
    server.add_crazyflie("radio://0/80/2M/E7E7E7E701", "cf1", (0.5, -0.25, 0.0))
    server.add_crazyflie("radio://0/90/2M/E7E7E7E702", "cf2", (-1.0, 2.0, 0.0))
    host, port = server.start()
    try:
        world.step(250)
        medium = RemoteMedium(host, port)
        poses = medium.control("poses")
        assert poses["time"] == pytest.approx(0.25)
        assert poses["names"] == ["cf1", "cf2"]
        assert poses["positions"][1][:2] == pytest.approx([-1.0, 2.0], abs=1e-6)
        medium.close()
    finally:
        server.stop()
