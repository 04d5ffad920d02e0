"""``crazyflie_add``'s private parameters turned into a checked request, without ROS.

Parameter names and defaults are the original driver's, including the custom log blocks:
``genericLogTopics`` (topic names), ``genericLogTopicFrequencies`` (one per topic; despite the
name each value is a PERIOD in milliseconds: 10 means every 10 ms, 100 means 10 Hz) and
``genericLogTopic_<name>_Variables`` (``group.name`` log variables of that topic).
Whether a variable exists and whether a block fits in 26 bytes can only be checked against the
Crazyflie's log TOC, so the server checks those and its error comes back through the service.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Dict, List, Mapping, Tuple

from crazyflie_driver.crtp.uri import parse_link_uri
from crazyflie_driver.errors import UriError
from crazyflie_driver.server.log_plan import (
    PACKETS_SWITCH,
    POSE_SWITCH,
    TOPIC_SWITCHES,
    LogBlockSpec,
    check_custom_log_limits,
    validate_log_block_specs,
)
from crazyflie_driver.server.onboard_pose import pose_block
from crazyflie_driver.server.setpoint import check_trim
from crazyflie_driver.server.worker import WorkerConfig


class AddConfigError(ValueError):
    """A crazyflie_add parameter that is missing or wrong; the message names it."""


#: Longest tf_prefix we accept (our choice: it prefixes every topic, service and frame id).
TF_PREFIX_MAX_CHARS = 64


def check_tf_prefix(tf_prefix: Any, allow_empty: bool = False) -> str:
    """``tf_prefix`` as a namespace by ROS's name rules (without leading/trailing ``/``).

    Each ``/``-separated part starts with an ASCII letter and holds only ASCII letters, digits and
    ``_``; no ``~``, ``..``, ``-``, spaces or empty parts. Empty (every name global) only with
    ``allow_empty``. AddConfigError naming the rule otherwise.
    """
    if not isinstance(tf_prefix, str):
        raise AddConfigError("tf_prefix must be a string, got %r" % (tf_prefix,))
    name = tf_prefix.strip().strip("/")
    if not name:
        if allow_empty:
            return ""
        raise AddConfigError("tf_prefix is empty: every topic and service of the Crazyflie would be global "
                             "(set crazyflie_server's ~allow_empty_tf_prefix to allow it)")
    if len(name) > TF_PREFIX_MAX_CHARS:
        raise AddConfigError("tf_prefix %r has %d characters, at most %d are accepted"
                             % (name, len(name), TF_PREFIX_MAX_CHARS))
    for part in name.split("/"):
        if not part or not (part[0].isascii() and part[0].isalpha()) or \
                not all(c.isascii() and (c.isalnum() or c == "_") for c in part):
            raise AddConfigError("tf_prefix %r is not a valid ROS namespace: each '/'-separated part must start "
                                 "with a letter and hold only letters, digits and '_' (part %r)" % (name, part))
    return name


def check_config(config: WorkerConfig, allow_empty_tf_prefix: bool = False) -> WorkerConfig:
    """An add request checked where it enters the server: tf_prefix, trims, log blocks.

    Returns it with the tf_prefix normalised; AddConfigError naming the first fault."""
    tf_prefix = check_tf_prefix(config.tf_prefix, allow_empty_tf_prefix)
    try:
        trims = [check_trim(name, getattr(config, name)) for name in ("roll_trim", "pitch_trim")]
        validate_log_block_specs(config.log_blocks)
        check_custom_log_limits(config.log_blocks, config.enable_logging)
    except ValueError as e:
        raise AddConfigError(str(e)) from None
    return replace(config, tf_prefix=tf_prefix, roll_trim=trims[0], pitch_trim=trims[1])


def _as_bool(name: str, value: Any) -> bool:
    if isinstance(value, bool):
        return value
    if isinstance(value, int) and value in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.strip().lower() in ("true", "false", "1", "0"):
        return value.strip().lower() in ("true", "1")
    raise AddConfigError("parameter ~%s must be true or false, got %r" % (name, value))


def _as_float(name: str, value: Any) -> float:
    if isinstance(value, bool):
        raise AddConfigError("parameter ~%s must be a number (degrees), got %r" % (name, value))
    try:
        return float(value)
    except (TypeError, ValueError):
        raise AddConfigError("parameter ~%s must be a number (degrees), got %r" % (name, value)) from None


def _as_list(name: str, value: Any) -> List[Any]:
    if isinstance(value, (list, tuple)):
        return list(value)
    raise AddConfigError("parameter ~%s must be a list, got %r" % (name, value))


def log_blocks_from_params(params: Mapping[str, Any]) -> Tuple[LogBlockSpec, ...]:
    """The custom log blocks; raises AddConfigError naming the faulty parameter."""
    topics = _as_list("genericLogTopics", params.get("genericLogTopics", []))
    periods = _as_list("genericLogTopicFrequencies", params.get("genericLogTopicFrequencies", []))
    if len(topics) != len(periods):
        raise AddConfigError(
            "~genericLogTopics has %d entries but ~genericLogTopicFrequencies has %d: give one period "
            "(in milliseconds, despite the name) per topic" % (len(topics), len(periods)))
    blocks = []
    for topic, period in zip(topics, periods):
        if not isinstance(topic, str) or not topic:
            raise AddConfigError("~genericLogTopics: entry %r is not a topic name" % (topic,))
        if isinstance(period, bool) or not isinstance(period, (int, float)) or period != int(period):
            raise AddConfigError("~genericLogTopicFrequencies: entry %r for topic %r is not a whole "
                                 "number of milliseconds" % (period, topic))
        key = "genericLogTopic_%s_Variables" % topic
        if key not in params:
            raise AddConfigError("topic %r is listed in ~genericLogTopics but ~%s is not set" % (topic, key))
        variables = _as_list(key, params[key])
        if not all(isinstance(v, str) for v in variables):
            raise AddConfigError("~%s must be a list of group.name strings, got %r" % (key, variables))
        blocks.append(LogBlockSpec(topic, int(period), tuple(v.strip() for v in variables)))
    try:
        validate_log_block_specs(blocks)
    except ValueError as e:
        raise AddConfigError(str(e)) from None
    return tuple(blocks)


#: ms between the ``pose`` topic's log packets with ``enable_logging_pose`` (the original driver's period).
HEAD_POSE_PERIOD_MS = 10

#: The original driver's switches read beside the topic switches: the ``packets`` topic's, and
#: ``use_ros_time``, accepted but changing nothing (every stamp is already ROS time; the reason is in
#: docs/coming_from_crazyswarm.md).
ACCEPTED_SWITCHES = (PACKETS_SWITCH, "use_ros_time")


def topic_switches_from_params(params: Mapping[str, Any]) -> Dict[str, bool]:
    """The original driver's per-topic switches (each default true), checked; AddConfigError naming a
    value that is not a boolean. These travel beside the chapter's AddCrazyflie request as parameters
    under the Crazyflie's namespace (:func:`apply_topic_switches` reads them back in the server)."""
    names = [n for n, _ in TOPIC_SWITCHES] + list(ACCEPTED_SWITCHES)
    return {n: _as_bool(n, params.get(n, True)) for n in names}


def apply_topic_switches(config: WorkerConfig, switches: Mapping[str, Any]) -> WorkerConfig:
    """``config`` with the fixed topics whose switch is false left out of the log plan, and the ``packets``
    topic as its switch says."""
    checked = topic_switches_from_params(switches)
    disabled = frozenset(topic for name, topic in TOPIC_SWITCHES if not checked[name])
    return replace(config, disabled_topics=disabled, log_packets=checked[PACKETS_SWITCH])


def config_from_params(params: Mapping[str, Any]) -> WorkerConfig:
    """A full add request from crazyflie_add's private parameters (names without the ``~``)."""
    if "uri" not in params or params["uri"] in ("", None):
        raise AddConfigError("parameter ~uri is required (e.g. radio://0/80/2M/E7E7E7E7E7)")
    uri = params["uri"]
    try:
        parse_link_uri(uri)
    except UriError as e:
        raise AddConfigError("parameter ~uri: %s" % e) from None
    try:
        tf_prefix = check_tf_prefix(params.get("tf_prefix", ""), allow_empty=True)   # the server decides
    except AddConfigError as e:
        raise AddConfigError("parameter ~%s" % e) from None
    config = WorkerConfig(
        uri=uri,
        tf_prefix=tf_prefix,
        roll_trim=_as_float("roll_trim", params.get("roll_trim", 0.0)),
        pitch_trim=_as_float("pitch_trim", params.get("pitch_trim", 0.0)),
        enable_logging=_as_bool("enable_logging", params.get("enable_logging", True)),
        enable_parameters=_as_bool("enable_parameters", params.get("enable_parameters", True)),
        log_blocks=log_blocks_from_params(params),
    )
    config = apply_topic_switches(config, params)
    if _as_bool(POSE_SWITCH, params.get(POSE_SWITCH, False)):
        # the original's onboard pose topic rides in the chapter's request as a custom block the server knows
        config = replace(config, log_blocks=config.log_blocks + (pose_block(HEAD_POSE_PERIOD_MS),))
    return check_config(config, allow_empty_tf_prefix=True)
