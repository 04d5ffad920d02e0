"""Parameter names a service receives: one check for the per-Crazyflie and the swarm-wide update_params."""
from __future__ import annotations

from typing import List

import pytest

from crazyflie_driver.errors import UnknownName
from crazyflie_driver.server.param_names import param_values, ros_param_name
from crazyflie_driver.server.swarm.commands import update_param_values

BAD_NAMES = ["ring/eff\x01ect", "ring/effect\x00", "ring/eff ect", "ring/eff.ect", "ring/", "nogroup", "a/b/c", "", 7]


class ParameterServer:
    """The ROS parameter server as the nodes see it: its XML-RPC cannot carry a control character and
    answers with a parse error (rospy raises ``ExpatError``); every name it is asked for is recorded."""

    def __init__(self, values) -> None:
        self.values = dict(values)
        self.asked: List[str] = []

    def lookup(self, name: str):
        self.asked.append(name)
        if any(ord(c) < 0x20 for c in name):
            raise RuntimeError("ExpatError: not well-formed (invalid token)")
        return self.values.get(name)


@pytest.mark.parametrize("name", BAD_NAMES)
def test_a_bad_name_is_refused_by_name_before_the_parameter_server_sees_it(name):
    with pytest.raises(UnknownName) as e:
        ros_param_name(name)
    assert repr(name) in str(e.value)
    server = ParameterServer({"/cf1/ring/effect": 3})
    for values, errors in (update_param_values([name, "ring/effect"], "cf1", server.lookup),     # swarm-wide
                           param_values([name, "ring/effect"], ("/cf1",), server.lookup)):      # per Crazyflie
        assert values == {"ring.effect": 3}         # the good name still goes through
        assert len(errors) == 1 and errors[0].startswith(repr(name)), errors
        assert "ExpatError" not in errors[0]
    assert all(a.endswith("/ring/effect") for a in server.asked), server.asked


def test_good_names_are_read_from_the_first_namespace_that_has_them():
    server = ParameterServer({"/allcfs/stabilizer/controller": 2, "/cf1/stabilizer/controller": 1,
                              "/cf1/locSrv/extPosStdDev": 0.001})
    values, errors = param_values(["/stabilizer/controller/", "locSrv/extPosStdDev", "ring/effect"],
                                  ("/allcfs", "/cf1"), server.lookup)
    assert values == {"stabilizer.controller": 2, "locSrv.extPosStdDev": 0.001}
    assert errors == ["'ring/effect': neither /allcfs/ring/effect nor /cf1/ring/effect is set"]
    values, errors = param_values(["ring/effect"], ("",), server.lookup)       # an empty tf_prefix: global names
    assert server.asked[-1] == "/ring/effect" and errors == ["'ring/effect': ROS parameter /ring/effect is not set"]


def test_a_refusal_of_the_parameter_server_is_named_and_the_others_still_go_through():
    def lookup(name: str):
        if "pid" in name:
            raise OSError("connection refused")
        return 1
    values, errors = param_values(["pid_rate/roll_kp", "ring/effect"], ("/cf1",), lookup)
    assert values == {"ring.effect": 1}
    assert errors == ["'pid_rate/roll_kp': the ROS parameter server refused /cf1/pid_rate/roll_kp: connection refused"]
