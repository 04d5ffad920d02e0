"""cflib 0.1.34 as the peer for the memories: its connect reads the decks' one-wire memories, its
I2CElement reads and writes the EEPROM's configuration block of the simulated Crazyflie, and our own
MemoryClient reads what cflib wrote (and the other way round)."""
from __future__ import annotations

import json
import os
import pathlib
import subprocess

import pytest

from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.sim.world_server import WorldServer
from support.cflib_python import cflib_python

TEST = pathlib.Path(__file__).resolve().parents[2]
SRC = TEST.parent / "src"
SCRIPT = TEST / "support" / "cflib_memories.py"
URI = "radio://0/80/2M/E7E7E7E705"


@pytest.fixture(scope="module")
def python():
    return cflib_python()


def test_cflib_reads_decks_and_reads_and_writes_the_config_block(python):
    from crazyflie_driver.sim.room.world import World
    world = World(speed=1.0, seed=3)
    server = WorldServer(world, dongles=1, port=0, seed=3)
    cf = server.add_crazyflie(URI, "cf5", (0.0, 0.0, 0.0), "current", decks=("bcFlow2", "bcMultiranger"))
    server.start()
    world.start()
    try:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join((str(SRC), str(TEST))),
                   CRAZYFLIE_SIM_ADDRESS=server.address, PYTHONUNBUFFERED="1")
        env.pop("CRAZYFLIE_BACKEND", None)
        proc = subprocess.run([python, str(SCRIPT), "--uri", URI, "--channel", "42", "--roll-trim", "-1.25"],
                              env=env, capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0, proc.stderr[-3000:]
        out = json.loads(proc.stdout.strip().splitlines()[-1])
    finally:
        server.stop()
        world.stop()
    assert out["memories"] == [[0, 1, 112], [1, 1, 112], [2, 0, 8192], [3, 0x12, 4096]]
    assert out["decks"] == [[0xBC, 0x0F, "bcFlow2", "A", True], [0xBC, 0x0C, "bcMultiranger", "A", True]]
    before = out["before"]
    assert before["valid"] and before["version"] == 1
    assert (before["radio_channel"], before["radio_speed"], before["radio_address"]) == (80, 2, 0xE7E7E7E705)
    after = out["after"]
    assert after["valid"] and (after["radio_channel"], after["roll_trim"]) == (42, -1.25)
    # the firmware's view: the block cflib wrote, in force at the next boot only
    assert cf.config_block() == cb.ConfigBlock(42, 2, 0.0, -1.25, 0xE7E7E7E705)
    assert cf.radio_channel == 80
