"""crazyflie_add's parameters: defaults, the custom log block lists and their errors."""
from __future__ import annotations

import pytest

from crazyflie_driver.server.add_config import (
    AddConfigError,
    apply_topic_switches,
    check_config,
    check_tf_prefix,
    config_from_params,
    topic_switches_from_params,
)
from crazyflie_driver.server.log_plan import LogBlockSpec
from crazyflie_driver.server.onboard_pose import is_pose_block
from crazyflie_driver.server.worker import WorkerConfig


def test_defaults_like_the_original():
    c = config_from_params({"uri": "radio://0/80/2M"})
    assert (c.tf_prefix, c.roll_trim, c.pitch_trim, c.enable_logging, c.enable_parameters, c.log_blocks) == \
        ("", 0.0, 0.0, True, True, ())


def test_topic_switches_of_the_original_driver():
    c = config_from_params({"uri": "radio://0/80/2M"})
    assert c.disabled_topics == frozenset()
    c = config_from_params({"uri": "radio://0/80/2M", "enable_logging_imu": False,
                            "enable_logging_pressure": "false", "use_ros_time": False,
                            "enable_logging_packets": False})
    assert c.disabled_topics == frozenset({"imu", "pressure"})
    switches = topic_switches_from_params({"enable_logging_battery": 0})
    assert switches["enable_logging_battery"] is False and switches["use_ros_time"] is True
    assert apply_topic_switches(c, {}).disabled_topics == frozenset()
    c = config_from_params({"uri": "radio://0/80/2M", "enable_logging_pose": True})
    assert [(b.topic_name, b.period_ms) for b in c.log_blocks] == [("pose", 10)] and is_pose_block(c.log_blocks[0])
    with pytest.raises(AddConfigError, match="enable_logging_imu"):
        config_from_params({"uri": "radio://0/80/2M", "enable_logging_imu": "maybe"})


def test_custom_log_blocks_period_in_ms():
    c = config_from_params({
        "uri": "radio://0/80/2M/E7E7E7E701", "tf_prefix": "/crazyflie1/", "roll_trim": 1, "pitch_trim": "-0.5",
        "enable_logging": "False",
        "genericLogTopics": ["log1", "log2"], "genericLogTopicFrequencies": [10, 100],
        "genericLogTopic_log1_Variables": ["pm.vbat"],
        "genericLogTopic_log2_Variables": ["acc.x", "acc.y", "acc.z"]})
    assert c.tf_prefix == "crazyflie1" and c.roll_trim == 1.0 and c.pitch_trim == -0.5
    assert c.enable_logging is False
    assert c.log_blocks == (LogBlockSpec("log1", 10, ("pm.vbat",)),
                            LogBlockSpec("log2", 100, ("acc.x", "acc.y", "acc.z")))


@pytest.mark.parametrize("params,message", [
    ({}, "~uri is required"),
    ({"uri": "radio://0/300/2M"}, "channel 300"),
    ({"uri": "radio://0/80/2M", "roll_trim": "left"}, "~roll_trim"),
    ({"uri": "radio://0/80/2M", "enable_logging": "maybe"}, "~enable_logging"),
    ({"uri": "radio://0/80/2M", "genericLogTopics": ["a", "b"], "genericLogTopicFrequencies": [10],
      "genericLogTopic_a_Variables": ["pm.vbat"], "genericLogTopic_b_Variables": ["pm.vbat"]},
     "2 entries but ~genericLogTopicFrequencies has 1"),
    ({"uri": "radio://0/80/2M", "genericLogTopics": ["a"], "genericLogTopicFrequencies": [10]},
     "~genericLogTopic_a_Variables is not set"),
    ({"uri": "radio://0/80/2M", "genericLogTopics": ["a"], "genericLogTopicFrequencies": [2.5],
      "genericLogTopic_a_Variables": ["pm.vbat"]}, "whole number"),
    ({"uri": "radio://0/80/2M", "genericLogTopics": ["a"], "genericLogTopicFrequencies": [10],
      "genericLogTopic_a_Variables": ["vbat"]}, "group.name"),
    ({"uri": "radio://0/80/2M", "genericLogTopics": ["a"], "genericLogTopicFrequencies": [10],
      "genericLogTopic_a_Variables": "pm.vbat"}, "must be a list"),
])
def test_errors_name_the_parameter(params, message):
    with pytest.raises(AddConfigError, match=message.replace("~", "~").replace(".", r"\.")):
        config_from_params(params)


@pytest.mark.parametrize("prefix", ["bad prefix!", "a-b", "~priv", "ns/../x", "\u00fc", "x" * 65, "1cf", "a//b",
                                    "cf 1", "cf.1"])
def test_tf_prefixes_ros_refuses_are_refused_by_name(prefix):
    with pytest.raises(AddConfigError, match="tf_prefix"):
        check_tf_prefix(prefix)
    with pytest.raises(AddConfigError, match="tf_prefix"):
        check_config(WorkerConfig(uri="radio://0/80/2M/E7E7E7E701", tf_prefix=prefix))


@pytest.mark.parametrize("prefix, name", [("cf1", "cf1"), ("/swarm/cf_2/", "swarm/cf_2"), ("x" * 64, "x" * 64)])
def test_valid_tf_prefixes_are_normalised(prefix, name):
    assert check_tf_prefix(prefix) == name


def test_empty_tf_prefix_only_when_allowed():
    with pytest.raises(AddConfigError, match="allow_empty_tf_prefix"):
        check_tf_prefix(" / ")
    assert check_tf_prefix("", allow_empty=True) == ""


@pytest.mark.parametrize("field, value", [("roll_trim", float("nan")), ("pitch_trim", float("inf")),
                                          ("roll_trim", 1e9), ("pitch_trim", -1e39)])
def test_bad_trims_refuse_the_add(field, value):
    config = WorkerConfig(uri="radio://0/80/2M/E7E7E7E701", tf_prefix="cf1", **{field: value})
    with pytest.raises(AddConfigError, match=field):
        check_config(config)


def test_twenty_custom_log_blocks_are_refused_where_the_request_enters():
    names = ["log%d" % i for i in range(20)]
    params = {"uri": "radio://0/80/2M/E7E7E7E701", "tf_prefix": "cf1", "genericLogTopics": names,
              "genericLogTopicFrequencies": [100] * 20}
    params.update({"genericLogTopic_%s_Variables" % n: ["pm.vbat"] for n in names})
    with pytest.raises(AddConfigError, match="20 custom log topics need 20 log blocks .* at most 16"):
        config_from_params(params)
    cfg = WorkerConfig(uri="radio://0/80/2M/E7E7E7E701", tf_prefix="cf1",
                       log_blocks=tuple(LogBlockSpec(n, 100, ("pm.vbat",)) for n in names))
    with pytest.raises(AddConfigError, match="remove at least 4 custom topics"):
        check_config(cfg)
