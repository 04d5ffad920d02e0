"""crazyflie_server's swarm parameters: defaults, per-source name patterns, faults named."""
from __future__ import annotations

import pytest

from crazyflie_driver.errors import SwarmConfigError
from crazyflie_driver.server.swarm.options import options_from_params


def test_defaults_and_patterns_by_source():
    o = options_from_params({"swarm_file": "s.yaml"})
    assert (o.mocap, o.stale_after, o.stale_hold, o.broadcast_repeats, o.enable_logging, o.pose_period_ms) == \
        ("none", 0.2, 0.5, 15, False, None)
    assert options_from_params({"pose_period_ms": "auto"}).pose_period_ms is None
    assert options_from_params({"pose_period_ms": 500}).pose_period_ms == 500
    assert options_from_params({"pose_period_ms": 0}).pose_period_ms == 0
    assert options_from_params({"mocap": "topic"}).mocap_pattern == "/vrpn_client_node/{name}/pose"
    assert options_from_params({"mocap": "TF", "mocap_pattern": "vicon/{name}/{name}"}).mocap_pattern == \
        "vicon/{name}/{name}"


@pytest.mark.parametrize("params, words", [
    ({"mocap": "optitrack"}, "~mocap must be one of vrpn, tf, topic, none"),
    ({"mocap": "tf", "mocap_pattern": "cf1"}, "~mocap_pattern must contain {name}"),
    ({"stale_after": 0}, "~stale_after must be a number > 0"),
    ({"stale_hold": "soon"}, "~stale_hold must be a number >= 0"),
    ({"broadcast_repeats": 0}, "~broadcast_repeats must be a number >= 1"),
    ({"broadcast_repeats": 2.5}, "whole number"),
    ({"pose_period_ms": 5}, "~pose_period_ms must be auto"),
    ({"pose_period_ms": "often"}, "~pose_period_ms must be a number"),
    ({"position_only": "maybe"}, "~position_only must be true or false"),
])
def test_faults_named(params, words):
    with pytest.raises(SwarmConfigError) as e:
        options_from_params(params)
    assert words in str(e.value)


def test_logging_switches_as_parameters_and_the_file_winning():
    from crazyflie_driver.server.swarm.config import parse_swarm
    from crazyflie_driver.server.swarm.policy import worker_config

    options = options_from_params({"swarm_file": "s.yaml", "enable_logging": True, "enable_logging_imu": "false",
                                   "enable_logging_battery": False, "enable_logging_packets": True})
    assert dict(options.switches) == {"enable_logging_imu": False, "enable_logging_battery": False,
                                      "enable_logging_packets": True}
    c = parse_swarm("crazyflies:\n  - {id: 1, channel: 80}\n"
                    "  - {id: 2, channel: 80, enable_logging_battery: true, enable_logging_packets: false,"
                    " enable_logging_pose: false}\n")
    first, second = (worker_config(cf, options, pose_period_ms=100) for cf in c.crazyflies)
    assert first.disabled_topics == frozenset({"imu", "battery"}) and first.log_packets
    assert first.battery_watch_ms > 0           # the topic is off, the safety monitor's battery is not
    assert [b.topic_name for b in first.log_blocks] == ["pose"]
    assert second.disabled_topics == frozenset({"imu"}) and not second.log_packets and second.log_blocks == ()
    plain = worker_config(c.crazyflies[0], options_from_params({"swarm_file": "s.yaml"}))
    assert plain.disabled_topics == frozenset() and not plain.log_packets     # packets off by default here
    with pytest.raises(SwarmConfigError, match="enable_logging_pose"):
        options_from_params({"swarm_file": "s.yaml", "enable_logging_pose": "perhaps"})


CRAZYSWARM_LOGS = {"genericLogTopics": ["log1", "zlog"], "genericLogTopicFrequencies": [10, 100],
                   "genericLogTopic_log1_Variables": ["pm.vbat"], "genericLogTopic_zlog_Variables": ["stateEstimate.z"]}


def test_crazyswarm_generic_log_topics_with_enable_logging_periods_in_ms():
    from crazyflie_driver.server.log_plan import LogBlockSpec
    o = options_from_params(dict(CRAZYSWARM_LOGS, enable_logging=True))
    assert o.log_blocks == (LogBlockSpec("log1", 10, ("pm.vbat",)), LogBlockSpec("zlog", 100, ("stateEstimate.z",)))


def test_crazyswarm_generic_log_topics_without_enable_logging_are_not_published_and_said():
    from crazyflie_driver.server.swarm.options import generic_log_note
    # Crazyswarm's shipped launch file lists log1 with its variables commented out: not a fault without logging
    params = {"genericLogTopics": ["log1"], "genericLogTopicFrequencies": [10]}
    assert options_from_params(params).log_blocks == ()
    assert "~enable_logging is false: no generic log topics" in generic_log_note(params, False)
    assert generic_log_note(params, True) is None and generic_log_note({}, False) is None


@pytest.mark.parametrize("change, words", [
    ({"genericLogTopicFrequencies": [10]}, "~genericLogTopics has 2 entries but ~genericLogTopicFrequencies has 1"),
    ({"genericLogTopic_zlog_Variables": None}, "~genericLogTopic_zlog_Variables is not set"),
    ({"genericLogTopicFrequencies": [5, 100]}, "period 5 ms is outside 10..2550 ms"),
    ({"genericLogTopic_log1_Variables": ["vbat"]}, "variable 'vbat' is not of the form group.name"),
])
def test_crazyswarm_generic_log_topic_faults_name_the_parameter(change, words):
    params = dict(CRAZYSWARM_LOGS, enable_logging=True, **change)
    params = {k: v for k, v in params.items() if v is not None}
    with pytest.raises(SwarmConfigError) as e:
        options_from_params(params)
    assert words in str(e.value), str(e.value)
