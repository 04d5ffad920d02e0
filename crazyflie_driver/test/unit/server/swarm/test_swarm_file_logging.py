"""Custom log topics of a Crazyswarm2 swarm file: the all < type < robot merge, Hz to ms, faults per Crazyflie."""
from __future__ import annotations

import textwrap
from typing import Dict

import pytest

from crazyflie_driver.server.log_plan import LogBlockSpec
from crazyflie_driver.server.swarm.config import SwarmConfig, parse_swarm

ROBOTS = """\
robots:
  cf1:
    uri: radio://0/80/2M/E7E7E7E701
    type: t
  cf2:
    uri: radio://0/80/2M/E7E7E7E702
    type: t
    firmware_logging:
      enabled: true
      custom_topics:
        zlog: {frequency: 50}
  cf3:
    uri: radio://0/80/2M/E7E7E7E703
    type: u
"""
LAYERS = ROBOTS + """\
robot_types:
  t:
    firmware_logging:
      enabled: false
      custom_topics:
        vbat: {frequency: 1, vars: [pm.vbat]}
  u: {}
all:
  firmware_logging:
    enabled: true
    custom_topics:
      zlog: {frequency: 10, vars: [stateEstimate.z]}
"""


def parse(text: str) -> SwarmConfig:
    """``text``, with types t and u saying nothing unless it defines them."""
    if "robot_types:" not in text:
        text += "robot_types:\n  t: {}\n  u: {}\n"
    return parse_swarm(textwrap.dedent(text), "crazyflies.yaml")


def blocks(config: SwarmConfig) -> Dict[str, tuple]:
    return {cf.tf_prefix: cf.log_blocks for cf in config.crazyflies}


def test_levels_merge_key_by_key_robot_over_type_over_all():
    c = parse(LAYERS)
    assert blocks(c) == {
        # the type turns logging off for cf1; cf2 turns it back on and changes only zlog's frequency
        "cf1": (),
        "cf2": (LogBlockSpec("zlog", 20, ("stateEstimate.z",)), LogBlockSpec("vbat", 1000, ("pm.vbat",))),
        # type u says nothing: all's topic and all's enabled
        "cf3": (LogBlockSpec("zlog", 100, ("stateEstimate.z",)),),
    }
    assert all(cf.log_error == "" for cf in c.crazyflies)
    assert c.notes == ("firmware_logging.custom_topics vbat, zlog given but firmware_logging.enabled is false: not "
                       "published, as in Crazyswarm2 (set enabled: true under all, the type or the robot)",)


def test_no_firmware_logging_or_not_enabled_means_no_custom_topics():
    assert set(blocks(parse(ROBOTS.replace("enabled: true", "enabled: false"))).values()) == {()}
    # Crazyswarm2's default: enabled false unless given
    no_switch = ROBOTS.replace("zlog: {frequency: 50}", "zlog: {frequency: 50, vars: [pm.vbat]}") + \
        "all:\n  firmware_logging:\n    custom_topics:\n      a: {frequency: 1, vars: [pm.vbat]}\n"
    c = parse(no_switch)
    assert blocks(c)["cf1"] == blocks(c)["cf3"] == ()
    assert [b.topic_name for b in blocks(c)["cf2"]] == ["a", "zlog"]
    assert c.notes == ("firmware_logging.custom_topics a given but firmware_logging.enabled is not given: not "
                       "published, as in Crazyswarm2 (set enabled: true under all, the type or the robot)",)


@pytest.mark.parametrize("hz, period", [(100, 10), (10, 100), (0.5, 2000), (1000 / 2550, 2550), (8, 125)])
def test_frequency_in_hz_is_the_log_period_in_ms(hz, period):
    c = parse(ROBOTS.replace("zlog: {frequency: 50}", "zlog: {frequency: %r, vars: [pm.vbat]}" % hz))
    assert blocks(c)["cf2"] == (LogBlockSpec("zlog", period, ("pm.vbat",)),)
    assert c.notes == ()


def test_a_frequency_that_is_not_whole_milliseconds_is_rounded_and_said():
    c = parse(ROBOTS.replace("zlog: {frequency: 50}", "zlog: {frequency: 30, vars: [pm.vbat]}"))
    assert blocks(c)["cf2"][0].period_ms == 33
    assert len(c.notes) == 1 and c.notes[0].startswith(
        "robots.cf2.firmware_logging.custom_topics.zlog.frequency: 30 Hz is logged every 33 ms (30.30 Hz)")


@pytest.mark.parametrize("topic, says", [
    ("zlog: {frequency: 200, vars: [pm.vbat]}",
     "crazyflies.yaml:11: robots.cf2.firmware_logging.custom_topics.zlog.frequency: the Crazyflie's log timer "
     "cannot do 200 Hz; give 0.39 .. 100 Hz"),
    ("zlog: {frequency: 0.1, vars: [pm.vbat]}", "cannot do 0.1 Hz; give 0.39 .. 100 Hz"),
    ("zlog: {frequency: 0, vars: [pm.vbat]}", "zlog.frequency must be a number of Hz > 0, got 0"),
    ("zlog: {frequency: fast, vars: [pm.vbat]}", "zlog.frequency must be a number of Hz > 0, got 'fast'"),
    ("zlog: {frequency: 10, vars: pm.vbat}", "zlog.vars must be a non-empty list of log variables"),
    ("zlog: {frequency: 10, vars: [vbat]}", "zlog.vars: custom log topic 'zlog': variable 'vbat' is not of the "
                                            "form group.name"),
    ("zlog: {frequency: 10}", "crazyflies.yaml:11: custom log topic 'zlog': no 'vars' given at any level (all, "
                              "robots.cf2); give it beside robots.cf2.firmware_logging.custom_topics.zlog.frequency"),
    ("zlog: {rate: 10, vars: [pm.vbat]}", "zlog: unknown key(s) rate; known: frequency, vars"),
    ("imu: {frequency: 10, vars: [pm.vbat]}", "custom log topic 'imu' clashes with the driver's own topic"),
])
def test_a_fault_leaves_that_crazyflie_out_naming_the_key_and_the_others_keep_theirs(topic, says):
    c = parse(ROBOTS.replace("zlog: {frequency: 50}", topic) + "all:\n  firmware_logging:\n    enabled: true\n"
              "    custom_topics:\n      a: {frequency: 1, vars: [pm.vbat]}\n")
    cf1, cf2, cf3 = c.crazyflies
    assert cf2.log_blocks == () and says in cf2.log_error, cf2.log_error
    assert cf2.log_error.startswith("crazyflies.yaml:")
    assert cf1.log_error == cf3.log_error == ""
    assert cf1.log_blocks == cf3.log_blocks == (LogBlockSpec("a", 1000, ("pm.vbat",)),)


def test_shape_faults_of_a_level_are_named():
    c = parse(ROBOTS.replace("enabled: true", "enabled: yes please"))
    assert "robots.cf2.firmware_logging.enabled must be true or false" in c.crazyflies[1].log_error
    c = parse(ROBOTS.replace("      custom_topics:\n        zlog: {frequency: 50}", "      custom_topics: [zlog]"))
    assert "custom_topics must be a mapping {topic: {frequency: Hz" in c.crazyflies[1].log_error
    c = parse(ROBOTS.replace("      enabled: true", "      enabled: true\n      topics: {}"))
    assert "robots.cf2.firmware_logging: unknown key(s) topics" in c.crazyflies[1].log_error


def test_more_topics_than_the_firmware_has_log_blocks():
    topics = "".join("        t%d: {frequency: 1, vars: [pm.vbat]}\n" % i for i in range(17))
    c = parse(ROBOTS.replace("        zlog: {frequency: 50}\n", topics))
    assert "17 custom log topics need 17 log blocks" in c.crazyflies[1].log_error
    assert c.crazyflies[1].log_error.startswith("crazyflies.yaml:8: robots.cf2.firmware_logging: ")


def test_a_crazyswarm1_file_has_no_custom_topics():
    c = parse_swarm("crazyflies:\n  - {id: 1, channel: 80}\n", "s.yaml")
    assert c.crazyflies[0].log_blocks == () and c.crazyflies[0].log_error == ""
