"""Joy axes -> cmd_vel with hector_quadrotor_teleop's parameters and the chapter's mappings."""
from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET

import pytest

from crazyflie_demo.teleop import AxisMapping, TeleopConfig, TeleopConfigError, TwistCommand

LAUNCH = os.path.join(os.path.dirname(__file__), "..", "..", "launch")


def launch_params(name: str) -> dict:
    """The quadrotor_teleop params of one of our launch files, typed as roslaunch would."""
    root = ET.parse(os.path.join(LAUNCH, name)).getroot()
    node = next(n for n in root.iter("node") if n.get("name") == "quadrotor_teleop")
    out = {}
    for p in node.iter("param"):
        text = p.get("value")
        out[p.get("name")] = int(text) if text.lstrip("-").isdigit() else float(text)
    return out


def config_from(params: dict) -> TeleopConfig:
    return TeleopConfig.from_params(lambda name, default: params.get(name, default))


def unit_axis(n: int, index: int, value: float = 1.0):
    axes = [0.0] * n
    axes[index] = value
    return axes


def test_each_axis_drives_its_output_and_nothing_else():
    cfg = config_from({"x_axis": 1, "y_axis": 2, "z_axis": 3, "yaw_axis": 4, "x_velocity_max": 10,
                       "y_velocity_max": 20, "z_velocity_max": 30, "yaw_velocity_max": 40})
    assert cfg.command(unit_axis(4, 0, 0.5)) == TwistCommand(linear_x=5.0)
    assert cfg.command(unit_axis(4, 1, 0.5)) == TwistCommand(linear_y=10.0)
    assert cfg.command(unit_axis(4, 2, 0.5)) == TwistCommand(linear_z=15.0)
    assert cfg.command(unit_axis(4, 3, 0.5)) == TwistCommand(angular_z=20.0)


def test_negative_axis_number_inverts_and_zero_disables():
    axes = [0.25, -0.5, 1.0]
    assert AxisMapping(-2, 4.0).value(axes) == pytest.approx(2.0)
    assert AxisMapping(2, 4.0).value(axes) == pytest.approx(-2.0)
    assert AxisMapping(0, 4.0).value(axes) == 0.0
    assert AxisMapping(4, 4.0).value(axes) == 0.0      # the Joy message has no 4th axis
    assert AxisMapping(-4, 4.0).value(axes) == 0.0


def test_defaults_are_hector_quadrotor_teleops():
    cfg = config_from({})
    assert (cfg.x.axis, cfg.y.axis, cfg.z.axis, cfg.yaw.axis) == (4, 3, 2, 1)
    assert cfg.x.maximum == cfg.y.maximum == cfg.z.maximum == 2.0
    assert cfg.yaw.maximum == pytest.approx(math.pi / 2)
    assert cfg.z_min is None
    assert cfg.command([0.0, -1.0, 0.0, 0.0]).linear_z == -2.0   # no bound: a velocity may be negative


def test_xbox360_launch_maps_sticks_to_attitude_thrust_and_yaw_rate():
    cfg = config_from(launch_params("xbox360.launch"))
    # xpad axes: 0 left x, 1 left y, 2 LT, 3 right x, 4 right y, 5 RT (joy: up/left positive)
    assert cfg.command(unit_axis(8, 4, 1.0)).linear_x == pytest.approx(30.0)     # right stick up
    assert cfg.command(unit_axis(8, 3, 1.0)).linear_y == pytest.approx(-30.0)    # right stick left
    assert cfg.command(unit_axis(8, 1, 1.0)).linear_z == pytest.approx(60000.0)  # left stick up
    assert cfg.command(unit_axis(8, 1, 0.5)).linear_z == pytest.approx(30000.0)
    assert cfg.command(unit_axis(8, 0, 1.0)).angular_z == pytest.approx(-200.0)  # left stick left
    assert cfg.command(unit_axis(8, 2, 1.0)) == TwistCommand()                   # trigger: unused


def test_thrust_is_zero_at_the_centre_and_with_the_stick_fully_down():
    for launch in ("xbox360.launch", "ps3.launch"):
        cfg = config_from(launch_params(launch))
        assert cfg.command([0.0] * 8).linear_z == 0.0
        assert cfg.command(unit_axis(8, 1, -1.0)).linear_z == 0.0
        assert cfg.command(unit_axis(8, 1, -0.3)).linear_z == 0.0
        assert cfg.command([]) == TwistCommand()      # a Joy without axes commands nothing


def test_ps3_launch_uses_the_sixaxis_axes():
    cfg = config_from(launch_params("ps3.launch"))
    # sixaxis: 0 left x, 1 left y, 2 right x, 3 right y
    assert cfg.command(unit_axis(4, 3, -1.0)).linear_x == pytest.approx(-30.0)   # right stick down
    assert cfg.command(unit_axis(4, 2, -1.0)).linear_y == pytest.approx(30.0)    # right stick right
    assert cfg.command(unit_axis(4, 1, 1.0)).linear_z == pytest.approx(60000.0)
    assert cfg.command(unit_axis(4, 0, -1.0)).angular_z == pytest.approx(200.0)  # left stick right


def test_maxima_scale_linearly_and_full_deflection_reaches_them():
    cfg = config_from({"x_axis": 1, "x_velocity_max": 30.0})
    for v in (-1.0, -0.5, 0.0, 0.2, 1.0):
        assert cfg.command([v]).linear_x == pytest.approx(30.0 * v)


@pytest.mark.parametrize("name,value", [("x_axis", 1.5), ("y_axis", "two"), ("z_axis", True),
                                        ("yaw_axis", float("nan")), ("x_velocity_max", "fast"),
                                        ("z_velocity_max", float("inf")), ("z_min", "zero")])
def test_bad_parameters_are_refused_naming_the_parameter(name, value):
    with pytest.raises(TeleopConfigError, match=name):
        config_from({name: value})


def test_whole_float_axis_numbers_are_accepted():
    assert config_from({"x_axis": 5.0, "y_axis": -3.0}).x.axis == 5
    assert config_from({"y_axis": -3.0}).y.axis == -3
