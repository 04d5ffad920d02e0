"""Every rostest has loopback ports of its own, so tools/run_tests.sh can run rostests side by side.

rostest gives each test its own master on a free port; everything else a test listens on is fixed
in its ``.test`` file: the simulated world's address (``sim_address``), a VRPN server's port
(``vrpn_port``, ``port``), a range of masters and worlds (``*_port_base``: one port per launch file
of the package, as launch_files_test.py starts them), and ports its test node passes to launch
files (``vrpn_port:=N`` in the ``*_test.py``). Two tests sharing one would meet on the same world
or VRPN stream when they run at the same time. The ports also stay out of the defaults a user's own
run takes (world 19840, cflib's UDP scan 19850..19859, VRPN 3883, master 11311) and below Linux's
ephemeral range (from 32768), where a client socket could be handed one of them.
"""
from __future__ import annotations

import ast
import pathlib
import re
import xml.etree.ElementTree as ET
from typing import Dict, List, Set

import pytest

from crazyflie_driver.mocap.vrpn_protocol import DEFAULT_PORT as VRPN_DEFAULT_PORT
from crazyflie_driver.sim.air.medium import DEFAULT_PORT as WORLD_DEFAULT_PORT
from crazyflie_driver.sim.world_server import UDP_BASE_PORT

SRC = pathlib.Path(__file__).resolve().parents[3]
TEST_FILES = sorted(SRC.glob("crazyflie_*/test/rostest/*.test"))
CFLIB_UDP_SCAN = 10                 # cflib's UDP scan probes UDP_BASE_PORT .. UDP_BASE_PORT + 9
ROS_MASTER_DEFAULT = 11311
EPHEMERAL_START = 32768             # Linux's default net.ipv4.ip_local_port_range starts here
RESERVED = ({WORLD_DEFAULT_PORT, VRPN_DEFAULT_PORT, ROS_MASTER_DEFAULT}
            | set(range(UDP_BASE_PORT, UDP_BASE_PORT + CFLIB_UDP_SCAN)))
PORT_NAME = re.compile(r"(^|_)(port|address)$")
BASE_NAME = re.compile(r"_port_base$")
PASSED_PORT = re.compile(r"\b\w*port:=(\d+)")
# launch-file arguments that open a listening port: a .test including a launch file that declares one must set it
# (vrpn_port only where the launch file serves VRPN: its ``vrpn`` argument, if it has one, is not false)
LISTENING_ARGS = ("sim_address", "vrpn_port")


def _port(text: str) -> int:
    """``127.0.0.1:19861`` or ``19861`` -> 19861."""
    return int(text.rsplit(":", 1)[-1])


def _launch_files(package_dir: pathlib.Path) -> List[pathlib.Path]:
    return sorted((package_dir / "launch").glob("*.launch"))


def _resolve(include: str) -> pathlib.Path:
    """``$(find crazyflie_demo)/launch/x.launch`` -> the file in this source tree."""
    m = re.fullmatch(r"\$\(find (\w+)\)/(.+)", include.strip())
    assert m, "cannot resolve include %r" % include
    return SRC / m.group(1) / m.group(2)


def claimed_ports(test_file: pathlib.Path) -> Set[int]:
    """The loopback ports the rostest listens on, besides its master's."""
    root = ET.parse(str(test_file)).getroot()
    ports: Set[int] = set()
    for el in root.iter():
        if el.tag not in ("arg", "param"):
            continue
        name, value = el.get("name", ""), el.get("default", el.get("value", ""))
        if not value or "$(" in value:
            continue
        if BASE_NAME.search(name):
            count = len(_launch_files(test_file.parents[2]))
            ports.update(range(int(value), int(value) + count))
        elif PORT_NAME.search(name):
            ports.add(_port(value))
    for test in root.iter("test"):
        script = test_file.parent / test.get("type", "")
        if script.is_file():
            ports.update(int(p) for p in PASSED_PORT.findall(script.read_text()))
    return ports


CLAIMS: Dict[str, Set[int]] = {"%s/%s" % (p.parts[-4], p.name): claimed_ports(p) for p in TEST_FILES}


def test_the_rostests_are_found_and_the_port_base_range_is_one_port_per_launch_file():
    assert len(TEST_FILES) >= 30
    [launch_files_test] = [p for p in TEST_FILES if p.name == "launch_files.test"]
    script = ast.parse((launch_files_test.parent / "launch_files_test.py").read_text())
    [expected] = [n.value for n in ast.walk(script) if isinstance(n, ast.AnnAssign)
                  and getattr(n.target, "id", "") == "EXPECTED"]
    assert len(expected.keys) == len(_launch_files(launch_files_test.parents[2]))
    assert 19936 in CLAIMS["crazyflie_demo/launch_files.test"]       # swarm.launch's vrpn_port:=19936 from the script


def test_no_two_rostests_share_a_port():
    owners: Dict[int, List[str]] = {}
    for test, ports in CLAIMS.items():
        for port in ports:
            owners.setdefault(port, []).append(test)
    shared = {port: tests for port, tests in sorted(owners.items()) if len(tests) > 1}
    assert not shared, "rostests sharing a loopback port (give each its own in its .test file): %s" % shared


@pytest.mark.parametrize("test", sorted(CLAIMS))
def test_ports_avoid_the_defaults_and_the_ephemeral_range(test):
    bad = sorted(p for p in CLAIMS[test] if p in RESERVED or not 1024 <= p < EPHEMERAL_START)
    assert not bad, "%s uses %s: a default port or one outside 1024..%d" % (test, bad, EPHEMERAL_START - 1)


@pytest.mark.parametrize("test_file", TEST_FILES, ids=lambda p: p.name)
def test_every_listening_argument_of_an_included_launch_file_is_set(test_file):
    """A .test that left sim_address or vrpn_port at the launch file's default would share it."""
    missing = []
    for include in ET.parse(str(test_file)).getroot().iter("include"):
        # the launch file's own arguments: its top-level <arg>s (those inside its <include>s are passed on)
        declared = {a.get("name"): a.get("default") for a in
                    ET.parse(str(_resolve(include.get("file", "")))).getroot().findall("arg")}
        passed = {a.get("name"): a.get("value") for a in include.findall("arg")}
        serves_vrpn = str(passed.get("vrpn", declared.get("vrpn", "true"))).lower() != "false"
        missing += ["%s in %s" % (a, include.get("file")) for a in LISTENING_ARGS
                    if a in declared and a not in passed and (a != "vrpn_port" or serves_vrpn)]
    assert not missing, "%s leaves at the default: %s" % (test_file.name, missing)
