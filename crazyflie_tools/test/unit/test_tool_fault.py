"""``rosrun crazyflie_tools fault``: the script as a separate process against a world server in this
process (the channel crazyflie_world_server and the sim node both serve)."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from crazyflie_driver.sim.room.world import World
from crazyflie_driver.sim.world_server import WorldServer
from support.ports import free_port

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(os.path.dirname(HERE)))
SCRIPT = os.path.join(REPO, "crazyflie_tools", "scripts", "fault")
URI1 = "radio://0/80/2M/E7E7E7E701"
A1 = bytes.fromhex("E7E7E7E701")


@pytest.fixture(scope="module")
def served():
    world = World(speed=0, seed=3)
    srv = WorldServer(world, dongles=2, port=0)
    srv.add_crazyflie(URI1, "cf1", (0.0, 0.0, 0.0))
    host, port = srv.start()
    yield srv, "%s:%d" % (host, port)
    srv.stop()


def fault(address, *words):
    env = dict(os.environ)
    env.update(CRAZYFLIE_SIM_ADDRESS=address,
               PYTHONPATH=os.pathsep.join([os.path.join(REPO, "crazyflie_driver", "src"),
                                           os.path.join(REPO, "crazyflie_tools", "src")]))
    return subprocess.run([sys.executable, SCRIPT] + list(words), env=env, capture_output=True,
                          text=True, timeout=60)


def test_unplug_and_replug_a_dongle(served):
    srv, address = served
    r = fault(address, "unplug", "0")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("dongle 0: unplugged")
    assert srv.medium.transmit(0, 80, 2, A1, b"\xff").unplugged
    assert fault(address, "list").stdout.split() == ["dongle", "0", "unplugged"]
    r = fault(address, "replug", "0")
    assert r.returncode == 0 and r.stdout.startswith("dongle 0: plugged in"), r.stderr
    assert srv.medium.transmit(0, 80, 2, A1, b"\xff").acked


def test_power_battery_and_loss(served):
    srv, address = served
    assert fault(address, "power", "cf1", "off").stdout.strip() == "cf1: switched off"
    assert not srv.crazyflie("cf1").powered
    assert fault(address, "power", URI1, "on").returncode == 0
    assert srv.crazyflie("cf1").powered
    r = fault(address, "battery", "cf1", "3.5V")
    assert r.returncode == 0 and r.stdout.startswith("cf1: battery 3.50 V"), r.stderr
    assert fault(address, "battery", "cf1", "100%").returncode == 0
    r = fault(address, "loss", "1", "--packet", "30%", "--ack", "0.1")
    assert "packet loss 30 %, ack loss 10 %" in r.stdout
    f = srv.medium.dongle_faults(1)
    assert (f.packet_loss, f.ack_loss) == (30.0, 10.0)
    assert fault(address, "clear", "1").returncode == 0
    assert srv.medium.dongle_faults(1).packet_loss == 0.0


@pytest.mark.parametrize("words, says", [
    (["unplug", "7"], "no simulated dongle 7 (this world has 2: 0..1)"),
    (["unplug", "one"], "dongle must be a number"),
    (["latency", "0", "50"], "give a unit, e.g. 50ms"),
    (["power", "cf9", "off"], "no simulated Crazyflie called 'cf9'"),
    (["battery", "cf1", "9"], "battery voltage must be within"),
    (["mocap", "cf1", "--freeze", "2"], "no motion-capture system"),
    (["teleport", "cf1"], "invalid choice: 'teleport'"),
])
def test_bad_input_is_one_line_and_exit_1_and_changes_nothing(served, words, says):
    srv, address = served
    r = fault(address, *words)
    assert r.returncode == 1
    assert r.stdout == ""
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fault: error: ") and says in lines[0], r.stderr
    assert srv.control("faults", {}) == []


def test_no_world_is_one_line_and_exit_1(served):
    port = free_port()                      # a port nobody listens on
    r = fault("127.0.0.1:%d" % port, "unplug", "0")
    assert r.returncode == 1 and len(r.stderr.splitlines()) == 1
    assert "no simulated world at 127.0.0.1:%d" % port in r.stderr


def test_address_option_and_usage(served):
    srv, address = served
    r = fault("127.0.0.1:1", "--address", address, "list")
    assert (r.returncode, r.stdout.strip()) == (0, "no faults injected"), r.stderr
    usage = fault(address)
    assert usage.returncode == 1 and "unplug DONGLE" in usage.stdout
    assert fault(address, "--help").returncode == 0
