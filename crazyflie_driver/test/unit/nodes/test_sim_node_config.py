"""The sim node's parameters, without ROS (its mocap frames are sim.room.mocap.MocapModel's, tested with the world)."""
from __future__ import annotations

import pytest

from crazyflie_driver.sim.node_config import (
    MocapConfig,
    SimConfigError,
    dongles_needed,
    mocap_from_params,
    vehicles_from_params,
    vrpn_port_from_params,
)


def test_vehicle_list_and_single_vehicle():
    v = vehicles_from_params({"vehicles": [{"uri": "radio://0/80/2M/E7E7E7E701", "name": "cf1", "x": 1, "y": 2},
                                           {"uri": "radio://1/80/2M/E7E7E7E702", "name": "cf2",
                                            "position": [0, -0.75, 0]}]})
    assert [(x.name, x.position) for x in v] == [("cf1", (1.0, 2.0, 0.0)), ("cf2", (0.0, -0.75, 0.0))]
    assert dongles_needed(v, None) == 2
    with pytest.raises(SimConfigError, match="radio index 1"):
        dongles_needed(v, 1)
    assert [x.platform for x in v] == ["cf2", "cf2"]
    assert vehicles_from_params({"vehicles": [{"uri": "radio://0/80/2M", "platform": "brushless"}]})[0].platform \
        == "brushless"
    single = vehicles_from_params({"uri": "radio://0/80/2M", "name": "crazyflie"})
    assert single[0].uri == "radio://0/80/2M/E7E7E7E7E7" and single[0].name == "crazyflie"


def test_vehicle_names_default_by_place_and_a_mapping_holds_its_list():
    v = vehicles_from_params({"vehicles": {"vehicles": [{"uri": "radio://0/80/2M/E7E7E7E701"},
                                                        {"uri": "radio://0/80/2M/E7E7E7E702", "name": ""}]}})
    assert [x.name for x in v] == ["crazyflie1", "crazyflie2"]


@pytest.mark.parametrize("params,message", [
    ({}, "no vehicles"),
    ({"vehicles": [{"name": "a"}]}, "needs at least a 'uri'"),
    ({"vehicles": [{"uri": "radio://0/999/2M"}]}, "channel 999"),
    ({"vehicles": [{"uri": "radio://0/80/2M", "name": "cf-1"}]}, "not a valid ROS name"),
    ({"vehicles": [{"uri": "radio://0/80/2M", "name": "a"}, {"uri": "radio://0/80/2M", "name": "b"}]}, "twice"),
    ({"vehicles": [{"uri": "radio://0/80/2M", "colour": "red"}]}, "unknown keys colour"),
    ({"vehicles": [{"uri": "radio://0/80/2M", "platform": "quad"}]}, "platform must be one of cf2, brushless"),
    ({"vehicles": [{"uri": "radio://0/80/2M/E7E7E7E701", "name": "a"},
                   {"uri": "radio://0/80/2M/E7E7E7E702", "name": "a"}]},
     r"~vehicles\[1\]: name 'a' is used twice"),
    ({"vehicles": [{"uri": "radio://0/80/2M"}, {"uri": "radio://0/80/2m/e7e7e7e7e7/"}]},
     r"~vehicles\[1\]: URI radio://0/80/2M/E7E7E7E7E7 is used twice"),     # one Crazyflie, two spellings
    ({"vehicles": [{"uri": "radio://0/80/2M", "position": [0, 1]}]}, r"position must be \[x, y, z\]"),
    ({"vehicles": [{"uri": "radio://0/80/2M", "position": [0, "a", 1]}]}, r"\.position must be a number"),
    ({"vehicles": [{"uri": "radio://0/80/2M", "y": "north"}]}, r"~vehicles\[0\]\.y must be a number"),
    ({"vehicles": {"uri": "radio://0/80/2M"}}, "must be a list"),
])
def test_vehicle_errors(params, message):
    with pytest.raises(SimConfigError, match=message):
        vehicles_from_params(params)


def test_mocap_params():
    assert mocap_from_params({}) == MocapConfig()
    with pytest.raises(SimConfigError, match="vicon|vrpn|both|none"):
        mocap_from_params({"mocap": "optitrack"})
    with pytest.raises(SimConfigError, match="mocap_dropout"):
        mocap_from_params({"mocap_dropout": 1.5})


def test_vrpn_params():
    assert vrpn_port_from_params({}) == (False, None)
    assert vrpn_port_from_params({"vrpn": True}) == (True, None)          # 3883 when free
    assert vrpn_port_from_params({"vrpn": "true", "vrpn_port": 0}) == (True, 0)
    assert vrpn_port_from_params({"vrpn": True, "vrpn_port": 3884}) == (True, 3884)
    for bad in (-1, 70000, "x", 1.5, True):
        with pytest.raises(SimConfigError, match="~vrpn_port"):
            vrpn_port_from_params({"vrpn": True, "vrpn_port": bad})


def test_vehicles_from_the_servers_swarm_file(tmp_path):
    import pathlib

    from crazyflie_driver.errors import SwarmConfigError
    from crazyflie_driver.nodes.sim_node import vehicles_from_swarm_file

    example = pathlib.Path(__file__).resolve().parents[3] / "config" / "swarm_example.yaml"
    vehicles, dongles = vehicles_from_swarm_file(str(example))
    assert dongles == 2                                              # channels 80 and 90
    assert [(v.name, v.uri, v.position) for v in vehicles] == [
        ("cf1", "radio://0/80/2M/E7E7E7E701", (0.0, 0.0, 0.0)),
        ("cf2", "radio://0/80/2M/E7E7E7E702", (0.5, 0.0, 0.0)),
        ("cf3", "radio://1/90/2M/E7E7E7E703", (0.0, 0.5, 0.0))]
    nested = tmp_path / "nested.yaml"
    nested.write_text("crazyflies:\n  - {id: 4, channel: 80, tf_prefix: team/cf4}\n")
    with pytest.raises(SimConfigError, match="has a '/'"):
        vehicles_from_swarm_file(str(nested))
    with pytest.raises(SwarmConfigError, match="cannot be read"):
        vehicles_from_swarm_file(str(tmp_path / "missing.yaml"))


def test_plan_holds_every_start_up_decision():
    from crazyflie_driver.sim.node_config import plan_from_params

    plan = plan_from_params({"vehicles": [{"uri": "radio://1/80/2M/E7E7E7E701", "name": "cf1", "frame": "body1"},
                                          {"uri": "radio://0/80/2M/E7E7E7E702", "name": "cf2"}],
                             "speed": "auto", "seed": "7", "usb": "cf1, cf2", "mocap": "vrpn", "vrpn": True,
                             "packet_loss": 0.25, "faults": "unplug 1", "publish_clock": False})
    assert plan.names == ["cf1", "cf2"] and plan.dongles == 2 and plan.seed == 7
    assert plan.pacing.auto and plan.usb == ("cf1", "cf2") and plan.mocap.style == "vrpn"
    assert plan.vicon_frames == {"cf1": "body1"} and (plan.vrpn_on, plan.vrpn_port) == (True, None)
    assert [op for op, _ in plan.start_faults] == ["set_dongle_faults"] * 3            # loss on both, then unplug 1
    assert plan.address == "127.0.0.1:19840" and plan.dongle_model == "PA" and plan.publish_clock is False
    assert plan.priority_boost == 5


def test_plan_reads_the_swarm_file_through_the_loader_it_is_given():
    from crazyflie_driver.sim.node_config import VehicleSpec, plan_from_params

    asked = []

    def load(path):
        asked.append(path)
        return [VehicleSpec("radio://0/80/2M/E7E7E7E701", "cf1", (0.0, 0.0, 0.0))], 3

    plan = plan_from_params({"swarm_file": "/x/swarm.yaml"}, load)
    assert asked == ["/x/swarm.yaml"] and plan.dongles == 3           # the swarm file's dongle count
    with pytest.raises(SimConfigError, match="~swarm_file"):
        plan_from_params({"swarm_file": "/x/swarm.yaml"})
    with pytest.raises(SimConfigError, match="~priority_boost"):
        plan_from_params({"uri": "radio://0/80/2M", "priority_boost": "high"})
    with pytest.raises(SimConfigError, match="no vehicles"):
        plan_from_params({})


def test_vehicles_name_their_decks_and_unknown_decks_are_refused():
    spec = vehicles_from_params({"vehicles": [{"uri": "radio://0/80/2M/E7E7E7E701",
                                               "decks": ["bcFlow2", "bcLighthouse4"]}]})[0]
    assert spec.decks == ("bcFlow2", "bcLighthouse4")
    assert vehicles_from_params({"uri": "radio://0/80/2M/E7E7E7E701", "name": "cf1"})[0].decks == ()
    with pytest.raises(SimConfigError, match="decks must be a list of deck names out of bcDWM1000"):
        vehicles_from_params({"vehicles": [{"uri": "radio://0/80/2M/E7E7E7E701", "decks": ["bcFlow3"]}]})
