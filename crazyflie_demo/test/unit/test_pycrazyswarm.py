"""pycrazyswarm without ROS: Crazyswarm's options, where the YAML is found, and what each call hands
the swarm (units, defaults, checks) through a recording backend."""
from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from crazyflie_driver.errors import CommandValueError, NotSupported, SwarmConfigError, TrajectoryError
from crazyflie_driver.server.swarm.config import parse_swarm
from pycrazyswarm import args as arguments
from pycrazyswarm import config
from pycrazyswarm.crazyflie import Crazyflie, CrazyflieServer, TimeHelper
from pycrazyswarm.sim_world import swarm_file_text
from uav_trajectory.examples import figure8

YAML = """
crazyflies:
  - id: 1
    channel: 100
    initialPosition: [1.5, 1.5, 0.0]
    type: medium
  - id: 7
    channel: 100
    initialPosition: [0.0, -1.0, 0.0]
    type: medium
"""


# -- options -----------------------------------------------------------------------------------------
def test_the_options_and_defaults_are_crazyswarms():
    o, unknown = arguments.parse(args=[])
    assert (o.sim, o.vis, o.dt, o.writecsv, o.disturbance, o.maxvel, o.video) == (
        False, "mpl", 0.1, False, 0.0, math.inf, None)
    assert unknown == [] and arguments.ignored(o) == []


def test_a_string_is_split_and_unknown_arguments_pass_through():
    o, unknown = arguments.parse(args="--sim --vis null --dt 0.05 __name:=x --foo")
    assert o.sim and o.vis == "null" and o.dt == 0.05
    assert unknown == ["__name:=x", "--foo"]


def test_the_scripts_own_options_come_from_the_parent_parser():
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument("--height", type=float, default=0.5)
    o, _ = arguments.parse(parent, ["--height", "1.2", "--sim"])
    assert o.height == 1.2 and o.sim


def test_each_simulation_only_option_given_is_named_as_ignored():
    o, _ = arguments.parse(args="--sim --writecsv --maxvel 2 --disturbance 0.1 --video out.mp4")
    notes = arguments.ignored(o)
    assert [n.split()[0] for n in notes] == ["--writecsv", "--disturbance", "--maxvel", "--video"]
    assert all("ignored" in n for n in notes)
    o, _ = arguments.parse(args="--writecsv")
    assert "this run is not --sim" in arguments.ignored(o)[0]


def test_vis_takes_only_crazyswarms_choices():
    with pytest.raises(SystemExit):
        arguments.parse(args="--vis opengl")


# -- the YAML ----------------------------------------------------------------------------------------
def test_the_yaml_is_found_beside_the_scripts_directory(tmp_path, monkeypatch):
    (tmp_path / "launch").mkdir()
    (tmp_path / "scripts").mkdir()
    (tmp_path / "launch" / "crazyflies.yaml").write_text(YAML)
    monkeypatch.chdir(tmp_path / "scripts")                            # as Crazyswarm's users run them
    assert config.find().path == str(tmp_path / "launch" / "crazyflies.yaml")
    monkeypatch.chdir(tmp_path)                                         # elsewhere: next to the script
    s = config.find(None, str(tmp_path / "scripts"))
    assert [e.id for e in config.entries(s)] == [1, 7]


def test_a_yaml_string_and_a_path_are_taken(tmp_path):
    e = config.entries(config.find(YAML))
    assert [(x.id, x.initial_position, x.tf_prefix) for x in e] == [(1, (1.5, 1.5, 0.0), "cf1"),
                                                                    (7, (0.0, -1.0, 0.0), "cf7")]
    p = tmp_path / "mine.yaml"
    p.write_text(YAML)
    assert config.find(str(p)).path == str(p)


@pytest.mark.parametrize("text, message", [
    ("crazyflies: []", "non-empty 'crazyflies'"),
    ("crazyflies: [{channel: 100}]", "integer 'id'"),
    ("crazyflies: [{id: 1, initialPosition: [0, 0]}]", "initialPosition"),
    ("crazyflies: [{id: 1}, {id: 1}]", "more than once"),
    ("crazyflies: [", "not valid YAML"),
])
def test_bad_yaml_says_what_to_change(text, message):
    with pytest.raises(SwarmConfigError, match=message):
        config.entries(config.find(text))


def test_a_missing_yaml_names_where_it_looked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SwarmConfigError, match="crazyflies.yaml not found"):
        config.find()


def test_sim_swarm_file_takes_the_types_beside_it_and_crazyswarms_server_params(tmp_path):
    (tmp_path / "crazyflies.yaml").write_text(YAML)
    with pytest.raises(SwarmConfigError, match="unknown type 'medium'"):
        swarm_file_text(config.find(str(tmp_path / "crazyflies.yaml")))
    (tmp_path / "crazyflieTypes.yaml").write_text(
        "crazyflieTypes:\n  medium:\n    bigQuad: False\n    firmwareParams: {ctrlMel: {mass: 0.032}}\n"
        "numMarkerConfigurations: 0\n")
    swarm = parse_swarm(swarm_file_text(config.find(str(tmp_path / "crazyflies.yaml"))))
    params = dict(swarm.crazyflies[1].params)
    assert swarm.crazyflies[1].uri == "radio://0/100/2M/E7E7E7E707"
    assert params["stabilizer.estimator"] == 2 and params["stabilizer.controller"] == 2
    assert params["commander.enHighLevel"] == 1 and params["ctrlMel.mass"] == 0.032


CRAZYSWARM2_YAML = """
robots:
  cf231:
    enabled: true
    uri: radio://0/80/2M/E7E7E7E7E7
    initial_position: [0.0, 0.5, 0.0]
    type: cf21
  cf2:
    enabled: false
    uri: radio://0/80/2M/E7E7E7E702
    type: cf21
robot_types:
  cf21:
    battery: {voltage_warning: 3.8, voltage_critical: 3.7}
all:
  firmware_params:
    stabilizer: {estimator: 2, controller: 2}
"""


def test_a_crazyswarm2_yaml_gives_the_enabled_robots_by_name_and_is_the_sim_swarm_file_itself():
    source = config.find(CRAZYSWARM2_YAML)
    assert config.entries(source) == [config.Entry(0xE7, (0.0, 0.5, 0.0), "cf231")]
    assert swarm_file_text(source) == CRAZYSWARM2_YAML
    params = dict(parse_swarm(swarm_file_text(source)).crazyflies[0].params)
    assert params["stabilizer.controller"] == 2


# -- the calls -----------------------------------------------------------------------------------------
class Recorder:
    def __init__(self):
        self.calls = []
        self.params = {}

    def __getattr__(self, name):
        return lambda *a: self.calls.append((name,) + a)

    def set_param(self, name, value):
        self.params[name] = value

    def get_param(self, name):
        return self.params[name]

    def position(self, ns):
        return (1.0, 2.0, 3.0)


@pytest.fixture
def swarm():
    b = Recorder()
    cfs = [Crazyflie(1, [0, 0, 0], b), Crazyflie(7, [1, 0, 0], b)]
    return b, CrazyflieServer(cfs, b)


def test_high_level_calls_keep_crazyswarms_defaults_and_units(swarm):
    b, allcfs = swarm
    cf = allcfs.crazyfliesById[7]
    assert cf.prefix == "/cf7" and list(cf.initialPosition) == [1, 0, 0]
    cf.takeoff(targetHeight=1.0, duration=2.5)
    cf.land(0.04, 2.5)
    cf.goTo(np.array([1, 2, 1.0]), 0.5, 2.0)
    cf.startTrajectory(3)
    cf.notifySetpointsStop()
    cf.stop()
    cf.setGroupMask(3)
    assert b.calls == [("takeoff", "/cf7", 0, 1.0, 2.5), ("land", "/cf7", 0, 0.04, 2.5),
                       ("go_to", "/cf7", 0, False, (1.0, 2.0, 1.0), 0.5, 2.0),
                       ("start_trajectory", "/cf7", 0, 3, 1.0, False, True),
                       ("notify_setpoints_stop", "/cf7", 0, 100), ("stop", "/cf7", 0), ("set_group_mask", "/cf7", 3)]


def test_broadcasts_are_relative(swarm):
    b, allcfs = swarm
    allcfs.takeoff(1.0, 2.0, groupMask=2)
    allcfs.goTo([0, 0, 0.5], 0, 1.0)
    allcfs.startTrajectory(0, timescale=2.0, reverse=True)
    assert b.calls == [("takeoff", "", 2, 1.0, 2.0), ("go_to", "", 0, True, (0.0, 0.0, 0.5), 0.0, 1.0),
                       ("start_trajectory", "", 0, 0, 2.0, True, True)]
    with pytest.raises(NotSupported, match="always relative"):
        allcfs.startTrajectory(0, relative=False)


def test_streaming_setpoints_convert_what_the_messages_carry(swarm):
    b, allcfs = swarm
    cf = allcfs.crazyflies[0]
    cf.cmdPosition([1, 2, 3], yaw=math.pi / 2)             # rad, as documented; the message is in degrees
    cf.cmdFullState([0, 0, 1], [0.1, 0, 0], [0, 0, 0], math.pi, [0, 0, 0.2])
    cf.cmdVelocityWorld([0.5, 0, 0], yawRate=10.0)
    cf.cmdVel(roll=1.0, pitch=-2.0, yawrate=3.0, thrust=40000)
    cf.cmdStop()
    cf.cmdHover(0.2, -0.1, yawRate=30.0, zDistance=0.8)       # Crazyswarm2's: body frame, deg/s, absolute m
    name, ns, pos, yaw_deg = b.calls[0]
    assert (name, ns, pos) == ("cmd_position", "/cf1", (1.0, 2.0, 3.0)) and yaw_deg == pytest.approx(90.0)
    _, _, pos, vel, acc, quat, omega = b.calls[1]
    assert quat == pytest.approx((0, 0, 1, 0), abs=1e-12) and omega == (0.0, 0.0, 0.2)
    assert b.calls[2:] == [("cmd_velocity_world", "/cf1", (0.5, 0.0, 0.0), 10.0),
                           ("cmd_vel", "/cf1", 1.0, -2.0, 3.0, 40000.0), ("cmd_stop", "/cf1"),
                           ("cmd_hover", "/cf1", 0.2, -0.1, 30.0, 0.8)]


def test_a_trajectory_is_uploaded_as_its_checked_pieces(swarm):
    b, allcfs = swarm
    t = figure8()
    allcfs.crazyflies[0].uploadTrajectory(0, 0, t)
    name, ns, tid, offset, pieces = b.calls[0]
    assert (name, ns, tid, offset, len(pieces)) == ("upload_trajectory", "/cf1", 0, 0, 16)
    assert pieces[5].x == tuple(t.polynomials[5].px.p)
    with pytest.raises(TrajectoryError):
        allcfs.crazyflies[0].uploadTrajectory(31, 0, t)
    with pytest.raises(CommandValueError, match="loadcsv"):
        allcfs.crazyflies[0].uploadTrajectory(0, 0, object())


def test_parameters_go_through_the_ros_names_crazyswarm_uses(swarm):
    b, allcfs = swarm
    cf = allcfs.crazyflies[1]
    cf.setParams({"ring/effect": 7, "stabilizer.controller": True})
    assert b.params == {"/cf7/ring/effect": 7, "/cf7/stabilizer/controller": 1}
    assert b.calls == [("update_params", "/cf7", ["ring/effect", "stabilizer/controller"])]
    assert cf.getParam("ring/effect") == 7
    cf.setLEDColor(1.0, 0.5, 0.0)
    assert (b.params["/cf7/ring/solidRed"], b.params["/cf7/ring/solidGreen"]) == (255, 127)
    allcfs.setParam("commander/enHighLevel", 1)
    assert b.params["/allcfs/commander/enHighLevel"] == 1
    assert b.calls[-1] == ("update_params", "", ["commander/enHighLevel"])
    with pytest.raises(CommandValueError, match="group/name"):
        cf.setParam("effect", 7)


@pytest.mark.parametrize("call, message", [
    (lambda cf: cf.takeoff(1.0, 0.0), "duration"),
    (lambda cf: cf.takeoff(float("nan"), 1.0), "targetHeight"),
    (lambda cf: cf.goTo([1, 2], 0, 1.0), "goal"),
    (lambda cf: cf.land(0.0, 1.0, groupMask=256), "group mask"),
    (lambda cf: cf.startTrajectory(0, timescale=0), "timescale"),
    (lambda cf: cf.notifySetpointsStop(-1), "remainValidMillisecs"),
    (lambda cf: cf.cmdVel(0, 0, 0, 70000), "thrust"),
    (lambda cf: cf.cmdHover(0, 0, 0, float("inf")), "zDistance"),
    (lambda cf: cf.cmdHover("fast", 0, 0, 0.5), "vx"),
    (lambda cf: cf.setLEDColor(2, 0, 0), "0..1"),
])
def test_bad_arguments_send_nothing(swarm, call, message):
    b, allcfs = swarm
    with pytest.raises(CommandValueError, match=message):
        call(allcfs.crazyflies[0])
    assert b.calls == []


def test_collision_avoidance_of_crazyswarms_firmware_fork_is_refused_clearly(swarm):
    b, allcfs = swarm
    with pytest.raises(NotSupported, match="firmware fork"):
        allcfs.crazyflies[0].enableCollisionAvoidance(allcfs.crazyflies, [0.12, 0.12, 0.3])
    with pytest.raises(NotSupported):
        allcfs.crazyflies[0].disableCollisionAvoidance()
    assert b.calls == []


def test_position_is_an_array_and_time_helper_checks_its_arguments(swarm):
    b, allcfs = swarm
    assert allcfs.crazyflies[0].position().tolist() == [1.0, 2.0, 3.0]

    class Clock:
        slept = []

        def time(self):
            return 5.0

        def sleep(self, d):
            self.slept.append(d)

        def sleep_for_rate(self, hz):
            self.slept.append(1 / hz)

        def is_shutdown(self):
            return False
    th = TimeHelper(Clock())
    th.sleep(1.5)
    th.sleepForRate(50)
    th.visualizer.update(0.0, [])            # Crazyswarm scripts may draw into it: nothing happens
    assert th.time() == 5.0 and Clock.slept == [1.5, 0.02] and not th.isShutdown()
    with pytest.raises(CommandValueError):
        th.sleepForRate(0)


# -- the operator's go-ahead and Crazyswarm's simulator module ------------------------------------
class _Pipe:
    """stdin that is not a terminal, with the given lines."""

    def __init__(self, *lines):
        self.lines, self.closed = list(lines), False

    def isatty(self):
        return False

    def readline(self):
        return self.lines.pop(0) if self.lines else ""


def test_a_line_on_a_piped_stdin_is_the_go_ahead_even_on_a_real_swarm(monkeypatch):
    from pycrazyswarm.input import Input
    pipe = _Pipe("\n")
    monkeypatch.setattr("sys.stdin", pipe)
    Input(None, simulated=False).waitUntilButtonPressed()
    assert pipe.lines == []


def test_without_a_line_a_simulation_goes_on_and_a_real_swarm_refuses(monkeypatch):
    from crazyflie_driver.errors import CrazyflieError
    from pycrazyswarm.input import Input
    monkeypatch.setattr("sys.stdin", _Pipe())
    Input(None, simulated=True).waitUntilButtonPressed()
    with pytest.raises(CrazyflieError, match="pipe it a line per go-ahead"):
        Input(None, simulated=False).waitUntilButtonPressed()


def test_crazyswarms_firmware_module_imports_and_refuses_any_use():
    import pycrazyswarm.cfsim.cffirmware as firm
    with pytest.raises(NotSupported, match="runs in the simulated world"):
        getattr(firm, "plan_init")  # noqa: B009  (the attribute access is what raises)
    assert not hasattr(firm, "__wrapped__")
