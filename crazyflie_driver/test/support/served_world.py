"""A world server in this process, served the way a user runs ``crazyflie_world_server``: the tests of
the tools that talk to a running world, and the benchmarks that measure it, start one here."""
from __future__ import annotations

import contextlib
from typing import Iterator, Sequence, Tuple


@contextlib.contextmanager
def served_world(vehicles: Sequence[Tuple], world=None, dongles: int = 1) -> Iterator[Tuple[object, str]]:
    """A ``WorldServer`` on an ephemeral loopback port with ``vehicles`` as (uri, name[, position[,
    firmware]]) tuples, its world started when it can be; yields (server, "host:port"), stops both."""
    from crazyflie_driver.sim.world_server import WorldServer
    if world is None:
        from crazyflie_driver.sim.room.world import World
        world = World(speed=1.0, seed=3)
    server = WorldServer(world, dongles=dongles, port=0)
    for v in vehicles:
        uri, name = v[0], v[1]
        position = v[2] if len(v) > 2 else (0.0, 0.0, 0.0)
        firmware = v[3] if len(v) > 3 else "current"
        server.add_crazyflie(uri, name, position, firmware, 0.0)
    host, port = server.start()
    if hasattr(world, "start"):
        world.start()
    try:
        yield server, "%s:%d" % (host, port)
    finally:
        server.stop()
        if hasattr(world, "stop"):
            world.stop()
