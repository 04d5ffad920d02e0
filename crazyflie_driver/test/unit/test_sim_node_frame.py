"""A vehicle's optional ``frame``: the tf frame the simulated Vicon publishes its pose under."""
import pytest

from crazyflie_driver.sim.node_config import SimConfigError, vehicles_from_params


def test_frame_as_a_launch_file_passes_it():
    v = vehicles_from_params({"vehicles": "[{uri: 'radio://0/90/2M', name: crazyflie, frame: '/crazyflie1'},"
                                          " {uri: 'radio://0/80/2M', name: cf2}]"})
    assert [(x.name, x.frame) for x in v] == [("crazyflie", "crazyflie1"), ("cf2", "")]


def test_default_vicon_frame_is_kept_as_given():
    v = vehicles_from_params({"vehicles": [{"uri": "radio://0/90/2M", "frame": "/vicon/crazyflie/crazyflie"}]})
    assert v[0].frame == "vicon/crazyflie/crazyflie"


@pytest.mark.parametrize("frame", ["", "/", "a b", "cf1:pose"])
def test_bad_frame_is_named(frame):
    with pytest.raises(SimConfigError, match=r"~vehicles\[0\]: frame"):
        vehicles_from_params({"vehicles": [{"uri": "radio://0/90/2M", "frame": frame}]})
