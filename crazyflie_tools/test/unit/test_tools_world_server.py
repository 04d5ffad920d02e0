"""The installed-style scripts as separate processes with CRAZYFLIE_BACKEND=sim, against a world
server in this process (``support.served_world``, as the benchmarks start one): the path
a user takes with a running ``crazyflie_world_server``.
"""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from support.ports import free_port
from support.served_world import served_world

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(os.path.dirname(HERE)))
SCRIPTS = os.path.join(REPO, "crazyflie_tools", "scripts")
URI1 = "radio://0/80/2M/E7E7E7E701"
URI2 = "radio://0/80/2M/E7E7E7E702"


SERVERS = {}


@pytest.fixture(scope="module")
def server():
    with served_world([(URI1, "cf1", (0.0, 0.0, 0.0), "current"),
                       (URI2, "cf2", (0.5, 0.0, 0.0), "2016.02")]) as (srv, server_address):
        SERVERS[server_address] = srv
        yield server_address


def run_tool(sim_address, tmp_path, name, *args, sim_backend=True):
    """The tool ``name`` as a process against the world at ``sim_address``; ``sim_backend=False``: as the
    chapter types it, without CRAZYFLIE_BACKEND, so it looks for a real Crazyradio."""
    env = {k: v for k, v in os.environ.items() if k != "CRAZYFLIE_BACKEND"}
    if sim_backend:
        env["CRAZYFLIE_BACKEND"] = "sim"
    env.update(CRAZYFLIE_SIM_ADDRESS=sim_address, CRAZYFLIE_TOC_CACHE=str(tmp_path / "toc"),
               PYTHONPATH=os.pathsep.join([os.path.join(REPO, "crazyflie_driver", "src"),
                                           os.path.join(REPO, "crazyflie_tools", "src")]))
    return subprocess.run([sys.executable, os.path.join(SCRIPTS, name)] + list(args), env=env,
                          capture_output=True, text=True,
                          timeout=60)


def test_scan_finds_both(server, tmp_path):
    a = run_tool(server, tmp_path, "scan", "--address", "E7E7E7E701")
    b = run_tool(server, tmp_path, "scan", "--address", "E7E7E7E702")
    assert (a.returncode, b.returncode) == (0, 0), a.stderr + b.stderr
    dongle = "Configured Dongle with version 0.53"
    assert a.stdout.splitlines() == [dongle, URI1] and b.stdout.splitlines() == [dongle, URI2]


def test_scan_default_address_prints_the_chapter_s_uri(tmp_path):
    """As the chapter shows it: the dongle line, then radio://0/100/2M (no address when it is the default)."""
    with served_world([("radio://0/100/2M", "cf")]) as (_, address):
        r = run_tool(address, tmp_path, "scan")
    assert (r.returncode, r.stdout) == (0, "Configured Dongle with version 0.53\nradio://0/100/2M\n"), r.stderr


def test_scan_without_dongle_points_at_running_world(server, tmp_path):
    r = run_tool(server, tmp_path, "scan", sim_backend=False)
    assert r.returncode == 1 and "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert lines[0].startswith("scan: error: no Crazyradio found")
    assert lines[1] == ("scan: a simulated world is listening at %s: to use its fake Crazyradio, run "
                        "CRAZYFLIE_BACKEND=sim rosrun crazyflie_tools scan" % server)


def test_scan_without_dongle_or_world_says_only_that(tmp_path):
    r = run_tool("127.0.0.1:%d" % free_port(), tmp_path, "scan", sim_backend=False)
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert r.stderr.startswith("scan: error: no Crazyradio found") and r.stderr.count("\n") == 1


@pytest.mark.parametrize("uri", [URI1, URI2])
def test_params_and_log_variables(server, tmp_path, uri):
    p = run_tool(server, tmp_path, "listParams", "--uri", uri)
    assert p.returncode == 0, p.stderr
    assert "ring.effect (uint8_t)" in p.stdout.splitlines()
    assert "cpu.flash (uint16_t, readonly)" in p.stdout.splitlines()
    v = run_tool(server, tmp_path, "listLogVariables", "--uri", uri)
    assert v.returncode == 0, v.stderr
    assert "pm.vbat (float)" in v.stdout.splitlines()


def test_set_then_get(server, tmp_path):
    s = run_tool(server, tmp_path, "setParam", "--uri", URI2, "--name", "ring.headlightEnable",
                 "--value", "1")
    assert (s.returncode, s.stdout) == (0, "ring.headlightEnable = 1\n"), s.stderr
    g = run_tool(server, tmp_path, "getParam", "--uri", URI2, "--name", "ring.headlightEnable")
    assert (g.returncode, g.stdout) == (0, "1\n"), g.stderr


def test_battery_version_console(server, tmp_path):
    b = run_tool(server, tmp_path, "battery", "--uri", URI1)
    assert b.returncode == 0, b.stderr
    assert b.stdout.endswith(" V\n") and 3.0 < float(b.stdout.split()[0]) < 4.3
    v = run_tool(server, tmp_path, "version", "--uri", URI1)
    assert v.returncode == 0, v.stderr
    assert v.stdout.splitlines()[0].startswith("Crazyradio 0: firmware 0.53, serial ")
    # the boot text went to earlier tools; new text waits in the firmware's queue
    entry = [e for e in SERVERS[server].entries() if e.uri == URI2][0]
    entry.crazyflie.console.write("TEST: hello from the firmware\n")
    c = run_tool(server, tmp_path, "console", "--uri", URI2, "--seconds", "0.3")
    assert c.returncode == 0, c.stderr
    assert "TEST: hello from the firmware\n" in c.stdout


def test_absent_crazyflie_is_one_line(server, tmp_path):
    r = run_tool(server, tmp_path, "getParam", "--uri", "radio://0/80/2M/E7E7E7E703",
                 "--name", "ring.effect", "--timeout", "0.3")
    assert r.returncode == 1
    assert r.stderr.startswith("getParam: error: radio://0/80/2M/E7E7E7E703")
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
