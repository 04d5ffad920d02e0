"""The swarm file: radios assigned by channel, parameters layered, every fault named with its line."""
from __future__ import annotations

import dataclasses
import os
import textwrap

import pytest

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import SwarmConfigError
from crazyflie_driver.server.swarm.config import dongle_per_channel, load_swarm_file, parse_swarm

EXAMPLE = os.path.join(os.path.dirname(__file__), "..", "..", "..", "..", "config", "swarm_example.yaml")

TYPES = """
crazyflieTypes:
  default:
    firmwareParams: {stabilizer: {estimator: 2, controller: 1}}
    batteryVoltageWarning: 3.8
    batteryVoltageCritical: 3.7
"""


def swarm(entries: str, extra: str = TYPES, **kw):
    body = textwrap.indent(textwrap.dedent(entries).lstrip("\n"), "  ")
    return parse_swarm("crazyflies:\n" + body + extra, "s.yaml", **kw)


def refused(entries: str, extra: str = TYPES, **kw) -> str:
    with pytest.raises(SwarmConfigError) as e:
        swarm(entries, extra, **kw)
    return str(e.value)


def test_example_file_loads_with_radios_by_channel():
    config = load_swarm_file(EXAMPLE)
    assert [(cf.tf_prefix, cf.uri) for cf in config.crazyflies] == [
        ("cf1", "radio://0/80/2M/E7E7E7E701"), ("cf2", "radio://0/80/2M/E7E7E7E702"),
        ("cf3", "radio://1/90/2M/E7E7E7E703")]
    assert config.dongles_needed == 2
    assert [cf.tf_prefix for cf in config.radios()[0]] == ["cf1", "cf2"]
    cf3 = config.crazyflies[2]
    # swarm-wide, then type, then own
    assert dict(cf3.params) == {"commander.enHighLevel": 1, "locSrv.extQuatStdDev": 0.05,
                                "stabilizer.estimator": 2, "stabilizer.controller": 2, "locSrv.extPosStdDev": 0.001}
    assert config.crazyflies[1].group_mask == 1


def test_channels_take_dongles_in_order_of_first_appearance():
    config = swarm("""
        - {id: 1, channel: 90}
        - {id: 2, channel: 80}
        - {id: 3, channel: 90}
        - {id: 4, channel: 100}
        """)
    assert [cf.uri for cf in config.crazyflies] == [
        "radio://0/90/2M/E7E7E7E701", "radio://1/80/2M/E7E7E7E702", "radio://0/90/2M/E7E7E7E703",
        "radio://2/100/2M/E7E7E7E704"]


def test_explicit_uri_pins_its_dongle_and_others_skip_it():
    config = swarm("""
        - {id: 1, channel: 80}
        - {uri: "radio://0/90/2M/E7E7E7E70A"}
        - {id: 2, channel: 90}
        """)
    assert [(cf.id, cf.uri) for cf in config.crazyflies] == [
        (1, "radio://1/80/2M/E7E7E7E701"), (10, "radio://0/90/2M/E7E7E7E70A"), (2, "radio://0/90/2M/E7E7E7E702")]
    assert config.crazyflies[1].tf_prefix == "cf10"


def test_own_params_win_over_type_and_defaults_without_types():
    config = parse_swarm("crazyflies:\n  - {id: 5, channel: 80, params: {stabilizer: {controller: 2}}}\n")
    assert dict(config.crazyflies[0].params) == {"stabilizer.estimator": 2, "stabilizer.controller": 2}
    assert config.crazyflies[0].initial_position == (0.0, 0.0, 0.0)


def test_types_in_a_second_file(tmp_path):
    main = tmp_path / "all.yaml"
    main.write_text("crazyflies:\n  - {id: 1, channel: 80, type: big}\n")
    types = tmp_path / "types.yaml"
    types.write_text("crazyflieTypes:\n  big:\n    firmwareParams: {stabilizer: {controller: 2}}\n"
                     "    batteryVoltateCritical: 3.6\n    markerConfiguration: 0\n")
    config = load_swarm_file(str(main), str(types))
    assert dict(config.crazyflies[0].params) == {"stabilizer.controller": 2}
    assert config.types["big"].battery_voltage_critical == 3.6


@pytest.mark.parametrize("entries, says", [
    pytest.param("""
        - {id: 1, channel: 80}
        - {id: 2, channel: 80}
        - {id: 1, channel: 90}
        """, "s.yaml:4: crazyflies[2] (id 1): id 1 is already used by crazyflies[0] (line 2)", id="same id"),
    pytest.param("""
        - {uri: "radio://0/80/2M/E7E7E7E701", tf_prefix: a}
        - {uri: "radio://0/80/2M/E7E7E7E701", id: 1, tf_prefix: b}
        """, "s.yaml:3: crazyflies[1] (id 1): id 1 is already used", id="same uri"),
    # packed motion capture reaches a Crazyflie by the last address byte: on any radio, one per swarm
    pytest.param("""
        - {uri: "radio://0/80/2M/E7E7E7E701"}
        - {uri: "radio://1/90/2M/E7E7E7E801", tf_prefix: other}
        """, "s.yaml:3: crazyflies[1]: id 1 is already used by crazyflies[0] (line 2)", id="same last address byte"),
])
def test_an_id_used_twice_is_refused_naming_both_lines(entries, says):
    msg = refused(entries)
    assert msg.startswith(says), msg


def test_unknown_type_names_the_defined_ones():
    msg = refused("""
        - {id: 1, channel: 80, type: heavy}
        """)
    assert msg == ("s.yaml:2: crazyflies[0] (id 1): unknown type 'heavy'; defined types: default "
                   "(add it under crazyflieTypes)")


@pytest.mark.parametrize("position", ["[0, 0]", "[0, .nan, 0]", "[0, x, 0]", "5"])
def test_bad_initial_position(position):
    msg = refused("- {id: 1, channel: 80, initialPosition: %s}\n" % position)
    assert "initialPosition" in msg and msg.startswith("s.yaml:2:"), msg


@pytest.mark.parametrize("entry, words", [
    ("{id: 300, channel: 80}", "id must be an integer 0..255"),
    ("{id: 1, channel: 126}", "channel must be an integer 0..125"),
    ("{id: 1}", "channel must be an integer"),
    ("{channel: 80}", "give an 'id'"),
    ("{id: 1, channel: 80, colour: red}", "unknown key(s) colour"),
    ("{id: 1, channel: 80, uri: 'radio://0/80/2M/E7E7E7E702'}", "ends in 0x02 but id is 1"),
    ("{id: 1, channel: 90, uri: 'radio://0/80/2M/E7E7E7E701'}", "channel 90 but uri"),
    ("{id: 1, channel: 80, uri: 'usb://0'}", "usb://"),
    ("{id: 1, channel: 80, tf_prefix: '1cf'}", "not a ROS namespace"),
    ("{id: 1, channel: 80, groupMask: 256}", "groupMask must be an integer 0..255"),
    ("{id: 1, channel: 80, params: {stabilizer: {estimator: .inf}}}", "stabilizer.estimator must be a finite"),
    ("{id: 1, channel: 80, params: {stabilizer: 2}}", "must be a mapping {name: value}"),
])
def test_bad_entries_named(entry, words):
    msg = refused("- %s\n" % entry)
    assert words in msg and msg.startswith("s.yaml:2: crazyflies[0]"), msg


def test_too_many_channels_for_the_dongles_present():
    msg = refused("""
        - {id: 1, channel: 80}
        - {id: 2, channel: 90}
        - {id: 3, channel: 100}
        """, dongles=2)
    assert msg.startswith("s.yaml:4: crazyflies[2] (id 3): needs Crazyradio 2 (channel 100) but 2 are present"), msg
    assert "plug in more Crazyradios or put these Crazyflies on fewer channels" in msg


def test_bad_types_and_file_level_faults(tmp_path):
    assert "batteryVoltageCritical 3.90 V is above" in refused(
        "- {id: 1, channel: 80}\n", "crazyflieTypes:\n  default:\n    batteryVoltageCritical: 3.9\n")
    assert "unknown top-level key(s) crazyflie" in refused("- {id: 1, channel: 80}\n", "crazyflie: []\n")
    with pytest.raises(SwarmConfigError, match="'crazyflies' list"):
        parse_swarm("- 1\n", "s.yaml")
    with pytest.raises(SwarmConfigError, match=r"^s.yaml:3: not valid YAML"):
        parse_swarm("crazyflies:\n  - {id: 1\n", "s.yaml")
    with pytest.raises(SwarmConfigError, match="cannot be read"):
        load_swarm_file(str(tmp_path / "missing.yaml"))
    with pytest.raises(SwarmConfigError, match="non-empty list"):
        parse_swarm("crazyflies: []\n", "s.yaml")


CRAZYSWARM2 = """
robots:
  cf231:
    enabled: true
    uri: radio://0/80/2M/E7E7E7E7E7
    initial_position: [0.5, -0.5, 0.0]
    type: cf21
    firmware_params:
      ring: {effect: 7}
  cf5:
    enabled: false
    uri: radio://0/80/2M/E7E7E7E705
    initial_position: [0.0, 0.0, 0.0]
    type: cf21
  cf6:
    uri: radio://0/90/2M/E7E7E7E706
    type: cf21
robot_types:
  cf21:
    motion_capture: {enabled: true, marker: default_single_marker, dynamics: default}
    big_quad: false
    battery: {voltage_warning: 3.9, voltage_critical: 3.6}
    firmware_params:
      stabilizer: {controller: 2}
all:
  firmware_logging:
    enabled: true
    default_topics:
      pose: {frequency: 10}
  firmware_params:
    commander: {enHighLevel: 1}
    stabilizer: {estimator: 2, controller: 1}
  broadcasts: {num_repeats: 15, delay_between_repeats_ms: 1}
"""


def test_a_crazyswarm2_file_gives_the_same_swarm_its_names_and_layers_and_says_what_it_takes_elsewhere():
    config = parse_swarm(CRAZYSWARM2, "crazyflies.yaml")
    assert [(cf.tf_prefix, cf.uri, cf.id, cf.dongle, cf.initial_position) for cf in config.crazyflies] == [
        ("cf231", "radio://0/80/2M/E7E7E7E7E7", 0xE7, 0, (0.5, -0.5, 0.0)),
        ("cf6", "radio://0/90/2M/E7E7E7E706", 6, 0, (0.0, 0.0, 0.0))]          # cf5 is not enabled
    params = dict(config.crazyflies[0].params)
    assert params == {"commander.enHighLevel": 1, "stabilizer.estimator": 2, "stabilizer.controller": 2,
                      "ring.effect": 7}                     # all, then the type, then the robot's own
    t = config.type_of(config.crazyflies[0])
    assert (t.battery_voltage_warning, t.battery_voltage_critical) == (3.9, 3.6)
    assert [n.split(":")[0] for n in config.notes] == ["all.firmware_logging.default_topics", "all.broadcasts"]


@pytest.mark.parametrize("text, says", [
    ("robots:\n  cf1:\n    enabled: true\n    initial_position: [0, 0, 0]\n",
     "crazyflies.yaml:2: robots.cf1: give its 'uri'"),
    ("robots:\n  cf1:\n    uri: radio://0/80/2M/E7E7E7E701\n    colour: red\n",
     "crazyflies.yaml:4: robots.cf1: unknown key(s) colour"),
    ("robots:\n  cf1:\n    uri: radio://0/80/2M/E7E7E7E701\n    enabled: false\n",
     "crazyflies.yaml:1: no robot is enabled"),
    ("robots:\n  cf1:\n    uri: radio://0/80/2M/E7E7E7E701\n  cf2:\n    uri: radio://0/80/2M/E7E7E7E701\n",
     "crazyflies.yaml:4: robots.cf2: id 1 is already used by robots.cf1 (line 2)"),
    ("robots:\n  cf1:\n    uri: radio://0/80/2M/E7E7E7E701\n    type: cf21\n",
     "crazyflies.yaml:4: robots.cf1: unknown type 'cf21'; defined types: default (add it under robot_types)"),
    ("robots:\n  cf1:\n    uri: radio://0/80/2M/E7E7E7E701\nrobot_types:\n  t:\n    battery: {voltage_warning: 3.5, "
     "voltage_critical: 3.7}\n", "crazyflies.yaml:6: robot_types.t: voltage_critical 3.70 V is above"),
])
def test_a_crazyswarm2_file_fault_is_named_with_its_line(text, says):
    with pytest.raises(SwarmConfigError) as e:
        parse_swarm(text, "crazyflies.yaml")
    assert str(e.value).startswith(says), str(e.value)


def test_the_keys_of_crazyswarm2s_own_files_that_change_nothing_load():
    """A robot's ``role`` (a label for the user's scripts) and a top-level ``relative: false``, as in
    Crazyswarm2's crazyflies.yaml; ``relative: true`` is refused by name."""
    text = CRAZYSWARM2.replace("    type: cf21\n    firmware_params:\n      ring",
                               "    type: cf21\n    role: pursuer\n    firmware_params:\n      ring", 1)
    assert "role: pursuer" in text
    def unplaced(config):           # the robots, but for the lines they are on
        return [dataclasses.replace(cf, line=0) for cf in config.crazyflies]
    base = parse_swarm(CRAZYSWARM2, "crazyflies.yaml")
    assert unplaced(parse_swarm(text + "relative: false\n", "crazyflies.yaml")) == unplaced(base)
    with pytest.raises(SwarmConfigError) as e:
        parse_swarm(text + "relative: true\n", "crazyflies.yaml")
    assert "relative: True is not supported: remove it or set it to false" in str(e.value)


def test_dongle_per_channel_keeps_pinned_channels_and_fills_the_lowest_free_dongle():
    pinned = parse_uri("radio://1/90/2M/E7E7E7E701")
    links = [(None, 80), (pinned, 90), (None, 80), (None, 100), (None, 90)]
    assert dongle_per_channel(links) == {90: 1, 80: 0, 100: 2}
    assert dongle_per_channel([]) == {}


def test_logging_switches_per_type_and_per_crazyflie():
    types = TYPES + "    enable_logging_imu: false\n    enable_logging_packets: true\n"
    c = swarm("""
        - {id: 1, channel: 80}
        - {id: 2, channel: 80, enable_logging_imu: true, enable_logging_pose: false}
    """, types)
    assert dict(c.crazyflies[0].switches) == {"enable_logging_imu": False, "enable_logging_packets": True}
    assert dict(c.crazyflies[1].switches) == {"enable_logging_imu": True, "enable_logging_packets": True,
                                              "enable_logging_pose": False}
    message = refused("""
        - {id: 1, channel: 80, enable_logging_battery: maybe}
    """)
    assert message.startswith("s.yaml:2: ") and "enable_logging_battery must be true or false" in message


def test_logging_switches_in_a_crazyswarm2_file():
    c = parse_swarm("robots:\n  cf1:\n    uri: radio://0/80/2M/E7E7E7E701\n    type: t\n"
                    "  cf2:\n    uri: radio://0/80/2M/E7E7E7E702\n    type: t\n    enable_logging_imu: true\n"
                    "robot_types:\n  t:\n    enable_logging_imu: false\n", "crazyflies.yaml")
    assert [dict(cf.switches) for cf in c.crazyflies] == [{"enable_logging_imu": False},
                                                         {"enable_logging_imu": True}]
    with pytest.raises(SwarmConfigError) as e:
        parse_swarm("robots:\n  cf1:\n    uri: radio://0/80/2M/E7E7E7E701\n    enable_logging_pose: 1\n",
                    "crazyflies.yaml")
    assert str(e.value).startswith("crazyflies.yaml:4: robots.cf1") and "true or false" in str(e.value)
