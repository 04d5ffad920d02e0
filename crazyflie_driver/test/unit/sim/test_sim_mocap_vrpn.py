"""The world's motion capture as a VRPN server: the stack's own VRPN client reads one tracker per
vehicle with the mocap model's poses; a body the model loses is not sent."""
from __future__ import annotations

import threading
import time

import numpy as np

from crazyflie_driver.mocap.vrpn_client import VrpnClient
from crazyflie_driver.sim.world.mocap import MocapModel
from crazyflie_driver.sim.world.mocap_vrpn import WorldVrpnServer, port_is_free
from crazyflie_driver.sim.world.world import World


def wait_until(cond, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def test_one_tracker_per_vehicle_with_the_mocap_model_poses():
    world = World(speed=1.0, seed=4)
    world.add_vehicle("cf1", position=(0.5, -0.25, 0.0))
    world.add_vehicle("cf2", position=(-1.0, 2.0, 0.0), yaw=1.0)
    mocap = MocapModel(world, rate=100.0, seed=4).attach()
    poses, lock = [], threading.Lock()

    def on_pose(report):
        with lock:
            poses.append(report)

    def of(name):
        with lock:
            return [p for p in poses if p.tracker == name]

    server = WorldVrpnServer(world, mocap, port=0)
    world.start()
    try:
        server.start()
        assert server.port > 0
        with VrpnClient("127.0.0.1", server.port, on_pose=on_pose, retry_min=0.1, retry_max=0.4):
            assert wait_until(lambda: len(of("cf1")) > 20 and len(of("cf2")) > 20)
            p2 = of("cf2")[-1]
            assert np.allclose(p2.position, (-1.0, 2.0, 0.0), atol=0.003)
            assert abs(p2.orientation[2] - np.sin(0.5)) < 0.01              # yaw 1 rad
            mocap.set_visible("cf1", False)                                   # the body is lost
            mark = len(of("cf2"))
            assert wait_until(lambda: len(of("cf2")) > mark + 10)            # the hiding has taken effect
            before, mark = len(of("cf1")), len(of("cf2"))
            assert wait_until(lambda: len(of("cf2")) > mark + 30)
            assert len(of("cf1")) == before                                  # nothing for the lost body
    finally:
        server.stop()
        world.stop()


def test_default_port_is_3883_when_free_else_another():
    world = World(speed=0)
    mocap = MocapModel(world)
    free = port_is_free("127.0.0.1", 3883)
    first = WorldVrpnServer(world, mocap)
    first.start()
    try:
        second = WorldVrpnServer(world, mocap)
        second.start()
        try:
            assert (first.port == 3883) == free                      # the VRPN default when nobody has it
            assert second.port not in (first.port, 3883)
        finally:
            second.stop()
    finally:
        first.stop()
