"""crazyflie_server started before the simulated world: the first add waits for the world instead of failing."""
from __future__ import annotations

import threading
import time

from crazyflie_driver import usb_choice
from crazyflie_driver.nodes.crazyflie_server import make_factory
from crazyflie_driver.server.registry import CrazyflieRegistry
from crazyflie_driver.server.worker import WorkerConfig, WorkerListener, WorkerState
from crazyflie_driver.sim.room.world import World
from crazyflie_driver.sim.world_server import WorldServer
from support.ports import free_port

URI = "radio://0/80/2M/E7E7E7E701"


def test_a_world_that_starts_after_the_server_is_waited_for(monkeypatch):
    port = free_port()
    monkeypatch.setenv("CRAZYFLIE_BACKEND", "sim")
    monkeypatch.setenv("CRAZYFLIE_SIM_ADDRESS", "127.0.0.1:%d" % port)
    monkeypatch.setattr(usb_choice, "_sim_backends", {})
    registry = CrazyflieRegistry(make_factory(1.0))        # no world yet: must not fail
    world = World(seed=1)
    server = WorldServer(world, dongles=1, host="127.0.0.1", port=port)
    server.add_crazyflie(URI, "cf1", (0.0, 0.0, 0.0))

    def start_late() -> None:
        time.sleep(1.0)
        server.start()
        world.start()
    threading.Thread(target=start_late, daemon=True).start()
    try:
        worker = registry.add(WorkerConfig(uri=URI, enable_logging=False, enable_parameters=False),
                              WorkerListener(), timeout=20.0)
        assert worker.state == WorkerState.RUNNING
    finally:
        registry.shutdown()
        server.stop()
        world.stop()
