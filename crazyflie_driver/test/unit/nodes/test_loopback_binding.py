"""A simulated run listens on loopback only (unless the user chose an address): every launch file
with ``sim:=true`` and ``tools/env.sh`` set ``ROS_IP``, which rosgraph turns into a 127.0.0.1 bind."""
from __future__ import annotations

import glob
import os
import subprocess

import pytest

roslaunch_config = pytest.importorskip("roslaunch.config")
roslaunch_xmlloader = pytest.importorskip("roslaunch.xmlloader")
rosgraph_network = pytest.importorskip("rosgraph.network")

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "..", ".."))


def sim_launch_files():
    """Every launch file that can run a simulation: it has a ``sim`` argument or starts the world."""
    out = []
    for path in sorted(glob.glob(os.path.join(REPO, "*", "launch", "*.launch"))):
        text = open(path).read()
        if '<arg name="sim"' in text or 'type="crazyflie_sim_node"' in text:
            out.append(path)
    return out


def load(path, *argv):
    config = roslaunch_config.ROSLaunchConfig()
    roslaunch_xmlloader.XmlLoader().load(path, config, argv=list(argv), verbose=False)
    return config.nodes


@pytest.fixture
def no_address(monkeypatch):
    monkeypatch.delenv("ROS_IP", raising=False)
    monkeypatch.delenv("ROS_HOSTNAME", raising=False)


def test_the_sim_launch_files_are_found():
    names = [os.path.basename(p) for p in sim_launch_files()]
    assert {"sim.launch", "crazyflie_server.launch", "hover_vicon.launch", "sim_mission.launch"} <= set(names)


@pytest.mark.parametrize("path", sim_launch_files(), ids=os.path.basename)
def test_every_node_of_a_simulation_binds_to_loopback(path, no_address):
    nodes = load(path, "sim:=true", "gui:=false")
    assert nodes
    for node in nodes:
        ip = dict(node.env_args).get("ROS_IP")
        assert ip == "127.0.0.1", (node.name, path)
        assert rosgraph_network.get_bind_address(ip) == "127.0.0.1"


@pytest.mark.parametrize("path", sim_launch_files(), ids=os.path.basename)
def test_an_address_the_user_set_is_kept(path, monkeypatch):
    monkeypatch.setenv("ROS_IP", "10.1.2.3")
    for node in load(path, "sim:=true", "gui:=false"):
        assert dict(node.env_args).get("ROS_IP") == "10.1.2.3", node.name


def test_real_hardware_launches_keep_ros_defaults(no_address):
    path = os.path.join(REPO, "crazyflie_driver", "launch", "crazyflie_server.launch")
    assert all("ROS_IP" not in dict(n.env_args) for n in load(path, "sim:=false"))


def env_sh(**env):
    base = {k: v for k, v in os.environ.items() if k not in ("ROS_IP", "ROS_HOSTNAME", "ROS_MASTER_URI")}
    base.update(env)
    out = subprocess.run(["bash", "-c", 'source tools/env.sh >/dev/null 2>&1; echo "ip=${ROS_IP:-}"'],
                         cwd=REPO, env=base, capture_output=True, text=True, timeout=60)
    return out.stdout.strip().splitlines()[-1]


def test_env_sh_binds_to_loopback_unless_told_otherwise():
    assert env_sh() == "ip=127.0.0.1"
    assert env_sh(ROS_MASTER_URI="http://localhost:11311") == "ip=127.0.0.1"
    assert env_sh(ROS_IP="192.168.1.7") == "ip=192.168.1.7"
    assert env_sh(ROS_HOSTNAME="groundstation") == "ip="
    assert env_sh(ROS_MASTER_URI="http://groundstation:11311") == "ip="
