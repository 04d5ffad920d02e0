"""The simulator extension that feeds the world's motion capture straight into a vehicle's estimator:
off by default, per vehicle, from the world server's config and its control op; a Crazyflie with it
holds a position setpoint with no host streaming motion capture."""
from __future__ import annotations

import struct

import numpy as np
import pytest

from crazyflie_driver.sim.air.medium import RemoteMedium
from crazyflie_driver.sim.crtp import tables as T
from crazyflie_driver.sim.room.mocap import MocapModel
from crazyflie_driver.sim.room.world import World
from crazyflie_driver.sim.world_server import WorldServer, load_vehicle_config

FED, PLAIN = "radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702"


def set_param(cf, name, value):
    entry = cf.params.entries[cf.params.ident(name)]
    cf.handle_crtp(bytes([0x2E]) + struct.pack("<H", cf.params.ident(name)) + T.pack(value, T.CTYPES[entry.ctype]))


def estimate(cf):
    return np.array([cf.read_value("stateEstimate." + a) for a in "xyz"])


def test_feed_per_vehicle_from_config_and_control_op(tmp_path):
    world = World(speed=0.0, seed=2)
    server = WorldServer(world, port=0, seed=2)
    server.add_crazyflie(FED, "fed", (0.0, 0.0, 0.0), mocap_to_estimator=True)
    server.add_crazyflie(PLAIN, "plain", (1.0, 0.0, 0.0))
    fed, plain = server.crazyflie(FED), server.crazyflie(PLAIN)
    for cf in (fed, plain):
        set_param(cf, "stabilizer.estimator", 2)
    host, port = server.start()
    try:
        world.step(300)
        world.vehicle("fed").place((0.4, -0.3, 0.0))
        world.vehicle("plain").place((1.4, -0.3, 0.0))
        # a jump no accelerometer saw: the filter is reset, as after carrying a Crazyflie elsewhere
        set_param(fed, "kalman.resetEstimation", 1)
        world.step(1000)
        assert np.linalg.norm(estimate(fed) - (0.4, -0.3, 0.0)) < 0.01        # follows the mocap
        # no mocap: the estimate starts at kalman.initialX/Y/Z (0) and only dead-reckons from there
        assert np.linalg.norm(estimate(plain) - (1.4, -0.3, 0.0)) > 0.9
        assert fed.snapshot()["external_measurements"] == 0                    # nothing came over the radio
        medium = RemoteMedium(host, port)
        assert medium.control("set_mocap_to_estimator", uri=PLAIN, on=True)["mocap_to_estimator"] is True
        assert medium.control("set_mocap_to_estimator", uri="fed", on=False)["mocap_to_estimator"] is False
        fed_ticks = world.flight.estimator.s.ext_tick[0].copy()
        world.step(1000)
        assert np.linalg.norm(estimate(plain) - (1.4, -0.3, 0.0)) < 0.01
        assert world.flight.estimator.s.ext_tick[0] == fed_ticks                # switched off: no more frames
        medium.close()
    finally:
        server.stop()
    path = tmp_path / "vehicles.yaml"
    path.write_text("- {uri: %s, mocap_to_estimator: true}\n- {uri: %s}\n" % (FED, PLAIN))
    assert [v.get("mocap_to_estimator", False) for v in load_vehicle_config(str(path))] == [True, False]
    path.write_text("- {uri: %s, mocap_to_estimator: sometimes}\n" % FED)
    with pytest.raises(ValueError, match="mocap_to_estimator must be true or false"):
        load_vehicle_config(str(path))


def test_fed_crazyflie_holds_a_position_setpoint_and_a_shared_model():
    world = World(speed=0.0, seed=3)
    server = WorldServer(world, port=0, seed=3)
    model = MocapModel(world, rate=100.0, seed=3).attach()
    server.use_mocap(model)                       # e.g. the model the VRPN server serves
    cf = server.add_crazyflie(FED, "fed", (0.2, 0.1, 0.0), mocap_to_estimator=True)
    set_param(cf, "stabilizer.estimator", 2)
    world.step(200)
    setpoint = bytes([0x7C, 7]) + struct.pack("<ffff", 0.2, 0.1, 0.5, 0.0)
    for _ in range(600):                          # 6 s: the climb settles
        cf.handle_crtp(setpoint)
        world.step(10)
    truth = world.vehicle("fed").pose()[0]
    assert np.linalg.norm(truth - (0.2, 0.1, 0.5)) < 0.03
    cf.halt("test", b"")                          # a halted STM takes nothing
    before = world.flight.estimator.s.ext_tick[0].copy()
    world.step(100)
    assert world.flight.estimator.s.ext_tick[0] == before
