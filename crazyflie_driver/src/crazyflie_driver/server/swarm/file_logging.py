"""Custom log topics of a Crazyswarm2 swarm file (``firmware_logging``), merged and checked, without ROS.

Crazyswarm2's ``crazyflies.yaml`` may give ``firmware_logging`` under ``all``, under a ``robot_types``
entry and under a ``robots`` entry::

    firmware_logging:
      enabled: true                              # the custom topics are published only when true
      custom_topics:
        zlog: {frequency: 10, vars: [stateEstimate.z]}    # Hz; published as /<name>/zlog
      default_topics: {pose: {frequency: 10}}    # Crazyswarm2's fixed topics: not served from the file here

The levels merge key by key, the robot's over its type's over ``all``'s (Crazyswarm2's
``crazyflie_server.cpp`` reads them that way): ``enabled`` is the most specific one given (false when
none is), a custom topic is the union over the levels, and a robot may change one field of a topic
``all`` defines (its ``frequency`` alone, say). Checks that need no Crazyflie are made here, per
Crazyflie: a fault is kept with that Crazyflie, which then connects without its custom topics (the
policy logs why; left out it would still hear the broadcasts), and the others keep theirs. Whether a
variable is in the Crazyflie's log TOC is checked when it connects (``server.log_plan``).
"""
from __future__ import annotations

import math
import numbers
from typing import AbstractSet, Any, Dict, List, Optional, Protocol, Sequence, Tuple

from crazyflie_driver.crtp.firmware_limits import LOG_PERIOD_MAX_MS, LOG_PERIOD_MIN_MS, LOG_PERIOD_UNIT_MS
from crazyflie_driver.errors import SwarmConfigError
from crazyflie_driver.server.log_plan import LogBlockSpec, check_custom_log_limits, validate_log_block_specs

LOGGING_KEYS = frozenset({"enabled", "default_topics", "custom_topics"})
TOPIC_KEYS = frozenset({"frequency", "vars"})
#: Hz the Crazyflie's log timer can give: one packet every 10 .. 2550 ms.
MAX_FREQUENCY_HZ = 1000.0 / LOG_PERIOD_MIN_MS
MIN_FREQUENCY_HZ = 1000.0 / LOG_PERIOD_MAX_MS

#: One level's ``firmware_logging`` flattened: key -> (value, its path in the file, its name in messages).
#: Keys: ``("enabled",)``, ``("custom_topics", topic, "frequency" | "vars")``.
Layer = Dict[Tuple[str, ...], Tuple[Any, List[Any], str]]
#: One level as the reader found it: (path of its firmware_logging, its name in messages, the raw value).
Level = Tuple[List[Any], str, Any]


class SwarmDoc(Protocol):
    """The swarm file being read (``config._Doc``): errors that name its line, checked mappings."""

    def error(self, path: Sequence[Any], what: str) -> SwarmConfigError:
        ...

    def mapping(self, path: Sequence[Any], where: str, value: Any, known: AbstractSet[str]) -> Dict[str, Any]:
        ...


def logging_layer(doc: SwarmDoc, path: List[Any], where: str, raw: Any) -> Layer:
    """One level's ``firmware_logging`` as flat keys; SwarmConfigError naming a key of the wrong shape."""
    body = doc.mapping(path, where, raw, LOGGING_KEYS)
    layer: Layer = {}
    if "enabled" in body:
        if not isinstance(body["enabled"], bool):
            raise doc.error(path + ["enabled"], "%s.enabled must be true or false, got %r"
                            % (where, body["enabled"]))
        layer[("enabled",)] = (body["enabled"], path + ["enabled"], where + ".enabled")
    topics_path = path + ["custom_topics"]
    topics = body.get("custom_topics")
    if topics is not None and not isinstance(topics, dict):
        raise doc.error(topics_path, "%s.custom_topics must be a mapping {topic: {frequency: Hz, vars: "
                                     "[group.name, ...]}}, got %r" % (where, topics))
    for name, spec in (topics or {}).items():
        here = topics_path + [name]
        label = "%s.custom_topics.%s" % (where, name)
        for key, value in doc.mapping(here, label, spec, TOPIC_KEYS).items():
            layer[("custom_topics", str(name), key)] = (value, here + [key], "%s.%s" % (label, key))
    return layer


def default_topics_note(where: str, raw: Any) -> Optional[str]:
    """What a level's ``default_topics`` asks that is served from elsewhere here, or None."""
    if isinstance(raw, dict) and raw.get("default_topics"):
        return ("%s.firmware_logging.default_topics: Crazyswarm2's fixed log topics (%s) come from the server's "
                "parameters in swarm mode (~pose_period_ms, ~enable_logging); custom_topics are served"
                % (where, ", ".join(map(str, raw["default_topics"]))))
    return None


def _period_ms(doc: SwarmDoc, field: Tuple[Any, List[Any], str], notes: List[str]) -> int:
    """The log period of a ``frequency`` [Hz]: whole milliseconds within what the firmware's timer does."""
    value, path, where = field
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)) \
            or value <= 0:
        raise doc.error(path, "%s must be a number of Hz > 0, got %r" % (where, value))
    exact = 1000.0 / float(value)
    period = int(round(exact))
    if not LOG_PERIOD_MIN_MS <= period <= LOG_PERIOD_MAX_MS:
        raise doc.error(path, "%s: the Crazyflie's log timer cannot do %g Hz; give %.2f .. %g Hz (one packet every "
                              "%d .. %d ms)" % (where, value, MIN_FREQUENCY_HZ, MAX_FREQUENCY_HZ, LOG_PERIOD_MAX_MS,
                                                LOG_PERIOD_MIN_MS))
    if abs(exact - period) > 1e-6:
        notes.append("%s: %g Hz is logged every %d ms (%.2f Hz): the Crazyflie's log timer counts whole "
                     "milliseconds (firmware before protocol version 8 in %d ms units: every %d ms)"
                     % (where, value, period, 1000.0 / period, LOG_PERIOD_UNIT_MS,
                        max(LOG_PERIOD_MIN_MS, period - period % LOG_PERIOD_UNIT_MS)))
    return period


def _variables(doc: SwarmDoc, field: Tuple[Any, List[Any], str]) -> Tuple[str, ...]:
    value, path, where = field
    if not isinstance(value, (list, tuple)) or not value or not all(isinstance(v, str) for v in value):
        raise doc.error(path, "%s must be a non-empty list of log variables [group.name, ...], got %r"
                        % (where, value))
    return tuple(v.strip() for v in value)


def _topic(doc: SwarmDoc, name: str, merged: Layer, levels: Sequence[Level], notes: List[str]) -> LogBlockSpec:
    """One merged custom topic as a log block; SwarmConfigError naming the field at fault."""
    frequency = merged.get(("custom_topics", name, "frequency"))
    variables = merged.get(("custom_topics", name, "vars"))
    if frequency is None or variables is None:
        given, missing = (variables, "frequency") if frequency is None else (frequency, "vars")
        assert given is not None        # the topic's name came from one of its fields
        raise doc.error(given[1][:-1], "custom log topic %r: no '%s' given at any level (%s); give it beside %s"
                        % (name, missing, ", ".join(w for _, w, _ in levels), given[2]))
    block = LogBlockSpec(name, _period_ms(doc, frequency, notes), _variables(doc, variables))
    try:
        validate_log_block_specs([block])
    except ValueError as e:
        raise doc.error(variables[1], "%s: %s" % (variables[2], e)) from None
    return block


def _blocks(doc: SwarmDoc, merged: Layer, levels: Sequence[Level], notes: List[str]) -> Tuple[LogBlockSpec, ...]:
    """Every custom topic of the merged levels, in the order they first appear."""
    names: List[str] = []
    for key in merged:
        if key[0] == "custom_topics" and key[1] not in names:
            names.append(key[1])
    return tuple(_topic(doc, name, merged, levels, notes) for name in names)


def crazyflie_log_topics(doc: SwarmDoc, levels: Sequence[Level],
                         notes: List[str]) -> Tuple[Tuple[LogBlockSpec, ...], str]:
    """One Crazyflie's custom log topics from its levels (``all``, its type, itself; least specific first):
    (blocks, "") or ((), the first fault, naming the file, line and key). ``notes`` gets what is served
    differently from what was asked (a frequency rounded to whole milliseconds)."""
    try:
        merged: Layer = {}
        for path, where, raw in levels:
            merged.update(logging_layer(doc, path, where + ".firmware_logging", raw))
        enabled = merged.get(("enabled",))
        if enabled is None or not enabled[0]:
            names = sorted({k[1] for k in merged if k[0] == "custom_topics"})
            if names:
                notes.append("firmware_logging.custom_topics %s given but firmware_logging.enabled is %s: not "
                             "published, as in Crazyswarm2 (set enabled: true under all, the type or the robot)"
                             % (", ".join(names), "false" if enabled else "not given"))
            return (), ""
        blocks = _blocks(doc, merged, levels, notes)
        try:
            check_custom_log_limits(blocks, enable_logging=False)
        except ValueError as e:
            raise doc.error(levels[-1][0], "%s: %s" % (levels[-1][1] + ".firmware_logging", e)) from None
        return blocks, ""
    except SwarmConfigError as e:
        return (), str(e)
