"""The xacro models expand to URDF with the real mass and inertia, an X-layout rotor set in the
firmware's motor order, one tree rooted at base_link, and tf_prefix applied to every name.
The launch files run xacro by name and start robot_state_publisher (and rviz only with gui)."""
from __future__ import annotations

import functools
import math
import os
import shutil
import subprocess
import xml.etree.ElementTree as ET
from typing import Dict, List, Optional, Tuple

import pytest

PKG = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
REPO = os.path.dirname(PKG)
URDF = os.path.join(PKG, "urdf")
LAUNCH = os.path.join(PKG, "launch")


def find_xacro() -> Optional[str]:
    """xacro on PATH, else the one tools/bootstrap.sh puts in the workspace's venv."""
    found = shutil.which("xacro")
    if found:
        return found
    venv = os.path.join(REPO, ".ws", "venv", "bin", "xacro")
    return venv if os.access(venv, os.X_OK) else None


XACRO = find_xacro()
needs_xacro = pytest.mark.skipif(XACRO is None, reason="xacro is not installed (tools/bootstrap.sh installs "
                                                        "xacro==1.13.3 into .ws/venv; or apt install ros-noetic-xacro)")


def ros_env() -> Dict[str, str]:
    """ROS_PACKAGE_PATH with this repository first, so that $(find crazyflie_description) resolves here."""
    env = dict(os.environ)
    others = [p for p in env.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    env["ROS_PACKAGE_PATH"] = os.pathsep.join([REPO] + others)
    return env


@functools.lru_cache(maxsize=None)
def _expanded_text(model: str, args: Tuple[str, ...]) -> str:
    out = subprocess.run([XACRO, os.path.join(URDF, model + ".urdf.xacro")] + list(args), env=ros_env(),
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, "xacro %s failed:\n%s" % (model, out.stderr)
    return out.stdout


def expand(model: str, *args: str) -> ET.Element:
    return ET.fromstring(_expanded_text(model, tuple(args)))


def links(robot: ET.Element) -> Dict[str, ET.Element]:
    return {link.get("name"): link for link in robot.findall("link")}


def joints(robot: ET.Element) -> Dict[str, ET.Element]:
    return {j.get("name"): j for j in robot.findall("joint")}


def xyz(element: ET.Element) -> List[float]:
    return [float(v) for v in element.find("origin").get("xyz").split()]


def inertial_links(robot: ET.Element) -> List[ET.Element]:
    return [link for link in robot.findall("link") if link.find("inertial") is not None]


EXPECTED_LINKS = {"base_link", "center_of_mass", "m1", "m2", "m3", "m4", "prop1", "prop2", "prop3", "prop4"}


@needs_xacro
def test_crazyflie2_mass_and_foerster_inertia():
    robot = expand("crazyflie2")
    assert robot.get("name") == "crazyflie2"
    (body,) = inertial_links(robot)                  # the whole vehicle's mass is on one link
    inertial = body.find("inertial")
    assert float(inertial.find("mass").get("value")) == pytest.approx(0.027, abs=1e-9)
    i = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
    assert i["ixx"] == pytest.approx(1.6571710e-5, rel=1e-9)
    assert i["iyy"] == pytest.approx(1.6655602e-5, rel=1e-9)
    assert i["izz"] == pytest.approx(2.9261652e-5, rel=1e-9)
    assert i["ixy"] == i["ixz"] == i["iyz"] == 0.0
    assert xyz(inertial) == [0.0, 0.0, 0.0]


@needs_xacro
def test_crazyflie1_is_lighter_with_inertia_scaled_by_mass():
    robot = expand("crazyflie")
    (body,) = inertial_links(robot)
    inertial = body.find("inertial")
    assert float(inertial.find("mass").get("value")) == pytest.approx(0.019, abs=1e-9)
    ixx = float(inertial.find("inertia").get("ixx"))
    izz = float(inertial.find("inertia").get("izz"))
    assert ixx == pytest.approx(1.6571710e-5 * 19 / 27, rel=1e-9)
    assert izz == pytest.approx(2.9261652e-5 * 19 / 27, rel=1e-9)
    assert izz < ixx + float(inertial.find("inertia").get("iyy"))   # a physical inertia tensor


@pytest.mark.parametrize("model,arm", [("crazyflie2", 0.046), ("crazyflie", 0.045)])
@needs_xacro
def test_one_fixed_tree_with_motors_in_x_layout_and_firmware_order(model, arm):
    robot = expand(model)
    ls, js = links(robot), joints(robot)
    assert set(ls) == EXPECTED_LINKS
    children = {j.find("child").get("link") for j in js.values()}
    parents = {j.find("parent").get("link") for j in js.values()}
    assert set(ls) - children == {"base_link"}      # one root
    assert parents | children <= set(ls) and len(js) == len(ls) - 1
    assert {j.get("type") for j in js.values()} == {"fixed"}
    d = arm / math.sqrt(2)
    signs = {1: (1, -1), 2: (-1, -1), 3: (-1, 1), 4: (1, 1)}     # m1 front-right ... m4 front-left
    for n, (sx, sy) in signs.items():
        joint = js["m%d_joint" % n]
        assert joint.find("parent").get("link") == "base_link"
        x, y, z = xyz(joint)
        assert (x, y, z) == (pytest.approx(sx * d), pytest.approx(sy * d), 0.0)
        assert math.hypot(x, y) == pytest.approx(arm)
        prop = js["prop%d_joint" % n]
        assert prop.find("parent").get("link") == "m%d" % n and xyz(prop)[2] > 0   # disc above the motor
        radius = float(ls["prop%d" % n].find("visual/geometry/cylinder").get("radius"))
        assert radius == pytest.approx(0.0225) and radius < d   # 45 mm propellers that do not overlap


@needs_xacro
def test_front_is_marked_in_red_on_the_plus_x_edge():
    robot = expand("crazyflie2")
    colours = {m.get("name"): [float(c) for c in m.find("color").get("rgba").split()]
               for m in robot.findall("material") if m.find("color") is not None}
    base = links(robot)["base_link"]
    marks = [v for v in base.findall("visual") if v.find("material").get("name") == "crazyflie_front"]
    assert len(marks) == 1 and xyz(marks[0])[0] > 0.01
    r, g, b, _ = colours["crazyflie_front"]
    assert r > 0.8 and g < 0.3 and b < 0.3
    front_props = {link.get("name") for link in robot.findall("link")
                   if link.find("visual/material") is not None
                   and link.find("visual/material").get("name") == "crazyflie_prop_front"}
    assert front_props == {"prop1", "prop4"}


@pytest.mark.parametrize("arg,prefix", [("tf_prefix:=crazyflie1", "crazyflie1/"),
                                        ("tf_prefix:=/cf2/", "cf2/"), ("tf_prefix:=", "")])
@needs_xacro
def test_tf_prefix_is_applied_to_every_link_and_joint(arg, prefix):
    robot = expand("crazyflie2", arg)
    ls, js = links(robot), joints(robot)
    assert set(ls) == {prefix + n for n in EXPECTED_LINKS}
    assert all(n.startswith(prefix) for n in js)
    for j in js.values():
        assert j.find("parent").get("link") in ls and j.find("child").get("link") in ls


def load_launch(name: str, *args: str):
    roslaunch_config = pytest.importorskip("roslaunch.config")
    old = dict(os.environ)
    os.environ.update(ros_env())
    os.environ["PATH"] = os.environ.get("PATH", "") + os.pathsep + os.path.dirname(XACRO)
    try:
        return roslaunch_config.load_config_default([(os.path.join(LAUNCH, name), list(args))], None,
                                                    verbose=False)
    finally:
        os.environ.clear()
        os.environ.update(old)


@pytest.mark.parametrize("launch,model", [("crazyflie2_rviz.launch", "crazyflie2"),
                                          ("crazyflie_rviz.launch", "crazyflie")])
@needs_xacro
def test_launch_files_load_the_model_and_start_robot_state_publisher(launch, model):
    cfg = load_launch(launch, "tf_prefix:=cf7")
    robot = ET.fromstring(cfg.params["/robot_description"].value)
    assert robot.get("name") == model and "cf7/base_link" in links(robot)
    nodes = {n.name: n for n in cfg.nodes}
    assert nodes["robot_state_publisher"].type == "robot_state_publisher"
    assert nodes["robot_state_publisher"].package == "robot_state_publisher"
    assert "-f cf7/base_link" in nodes["rviz"].args
    headless = load_launch(launch, "gui:=false")
    assert {n.name for n in headless.nodes} == {"robot_state_publisher"}
    plain = {n.name: n for n in load_launch(launch).nodes}
    assert plain["rviz"].args.endswith("-f base_link")


def test_launch_files_run_xacro_by_name():
    """Noetic and Debian have neither xacro.py nor $(find xacro)/xacro, nor state_publisher."""
    commands, types = [], []
    for name in sorted(os.listdir(LAUNCH)):
        if name.endswith(".launch"):
            root = ET.parse(os.path.join(LAUNCH, name)).getroot()
            commands += [p.get("command") for p in root.iter("param") if p.get("command")]
            types += [(n.get("pkg"), n.get("type")) for n in root.iter("node")]
    assert commands and all(c.split()[0] == "xacro" for c in commands), commands
    assert ("robot_state_publisher", "robot_state_publisher") in types
    assert all(t != "state_publisher" for _, t in types)
