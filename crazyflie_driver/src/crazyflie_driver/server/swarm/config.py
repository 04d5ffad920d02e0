"""The swarm file: every Crazyflie of a swarm and its type, loaded and checked without ROS.

In the spirit of Crazyswarm's ``allCrazyflies.yaml`` + ``crazyflieTypes.yaml`` (both may sit in one
file, or the types in a second one)::

    crazyflies:
      - id: 1                               # address 0xE7E7E7E7<id as 2 hex digits>, tf_prefix cf<id>
        channel: 80
        initialPosition: [0.0, 0.0, 0.0]    # m, world frame
        type: default
        # optional: uri, tf_prefix, groupMask, params: {group: {name: value}}, enable_logging_<topic>
    crazyflieTypes:
      default:
        firmwareParams: {stabilizer: {estimator: 2, controller: 1}}
        batteryVoltageWarning: 3.8
        batteryVoltageCritical: 3.7
        # optional: enable_logging_<topic> for every Crazyflie of the type
    firmwareParams: {...}                   # optional, for every Crazyflie

Crazyswarm2's ``crazyflies.yaml`` is read too::

    robots:
      cf1:                                  # the name is the tf_prefix
        enabled: true                       # false: left out of the swarm
        uri: radio://0/80/2M/E7E7E7E701
        initial_position: [0.0, 0.0, 0.0]
        type: cf21
        # optional: firmware_params, firmware_logging, enable_logging_<topic>
    robot_types:
      cf21:
        battery: {voltage_warning: 3.8, voltage_critical: 3.7}
        # optional: firmware_params, enable_logging_<topic>; motion_capture, big_quad, firmware_logging
        # (see notes)
    all:
      firmware_params: {...}                # for every Crazyflie
      # optional: firmware_logging, broadcasts (see notes)

Its ``firmware_logging.custom_topics`` (all, type, robot) become each Crazyflie's custom log topics
(``server.swarm.file_logging``: the merge, the units, the checks). What such a file asks that this
server takes from elsewhere (Crazyswarm2's fixed log topics, broadcast repeats, a type without
motion capture) is listed in ``SwarmConfig.notes``, for the node to log: nothing in it is dropped
silently.

Radios: Crazyflies without a ``uri`` go to one Crazyradio per channel, in the order the channels
first appear (``radio://<dongle>/<channel>/2M/E7E7E7E7<id>``); an explicit ``uri`` keeps its dongle,
and its channel then stays on that dongle. Firmware parameters are applied swarm-wide first, then
the type's, then the Crazyflie's own (the last value of a name wins), as Crazyswarm pushes them.
crazyflie_ros HEAD's logging switches (``LOG_SWITCHES``: ``enable_logging_imu`` ... ``_packets``) may
be given per type and per Crazyflie, in either format; the Crazyflie's own value wins over its
type's, and both over crazyflie_server's parameters of the same names
(``server.swarm.policy.worker_config``).
Every fault raises :class:`~crazyflie_driver.errors.SwarmConfigError` naming the file, the line and
entry, and what to change.
"""
from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass, field, replace
from typing import AbstractSet, Any, Dict, List, Mapping, Optional, Sequence, Tuple

import yaml

from crazyflie_driver.crtp.uri import DATARATE_NAMES, MAX_CHANNEL, parse_uri
from crazyflie_driver.errors import SwarmConfigError, UriError
from crazyflie_driver.server.log_plan import PACKETS_SWITCH, POSE_SWITCH, TOPIC_SWITCHES, LogBlockSpec
from crazyflie_driver.server.swarm.file_logging import Level, crazyflie_log_topics, default_topics_note

#: Address of a Crazyflie given by id: these four bytes, then the id.
ADDRESS_PREFIX = "E7E7E7E7"
DEFAULT_DATARATE = 2                     # 2M
DEFAULT_TYPE = "default"
MAX_ID = 0xFF                            # the id is the address's last byte (packed mocap items carry it)
#: The type used when the file defines none named ``default``: the Kalman estimator, the only one
#: that takes motion capture (the complementary one ignores it).
BUILTIN_DEFAULT_PARAMS = (("stabilizer.estimator", 2),)
DEFAULT_BATTERY_WARNING_V = 3.8
DEFAULT_BATTERY_CRITICAL_V = 3.7

#: crazyflie_ros HEAD's logging switches a type or a Crazyflie of the file may set (true or false).
LOG_SWITCHES = tuple(n for n, _ in TOPIC_SWITCHES) + (POSE_SWITCH, PACKETS_SWITCH)
_ENTRY_KEYS = {"id", "channel", "initialPosition", "type", "uri", "tf_prefix", "groupMask", "params",
               "firmwareParams"} | set(LOG_SWITCHES)
# Crazyswarm's type keys this server does not use (marker and dynamics models) are accepted, so its
# files load; "batteryVoltateCritical" is its spelling of the critical voltage.
_TYPE_KEYS = {"firmwareParams", "batteryVoltageWarning", "batteryVoltageCritical", "batteryVoltateCritical",
              "bigQuad", "markerConfiguration", "dynamicsConfiguration"} | set(LOG_SWITCHES)
_TOP_KEYS = {"crazyflies", "crazyflieTypes", "firmwareParams", "markerConfigurations", "dynamicsConfigurations"}
_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

ParamList = Tuple[Tuple[str, Any], ...]     # ("group.name", value) in the order they are written
Switches = Tuple[Tuple[str, bool], ...]     # (LOG_SWITCHES name, on) as given


@dataclass(frozen=True)
class CrazyflieType:
    name: str
    firmware_params: ParamList = ()
    battery_voltage_warning: float = DEFAULT_BATTERY_WARNING_V
    battery_voltage_critical: float = DEFAULT_BATTERY_CRITICAL_V
    switches: Switches = ()


@dataclass(frozen=True)
class SwarmCrazyflie:
    """One Crazyflie of the swarm, everything resolved."""

    id: int
    uri: str                                 # canonical
    dongle: int
    channel: int
    tf_prefix: str
    initial_position: Tuple[float, float, float]
    type: str
    params: ParamList                        # swarm-wide, then type, then own; last value per name
    group_mask: int = 0                      # 0: leave the firmware's (every Crazyflie is in group 0 anyway)
    line: int = 0                            # where the entry starts in the file (0: unknown)
    switches: Switches = ()                  # logging switches: the type's, then its own
    log_blocks: Tuple[LogBlockSpec, ...] = ()    # custom log topics the file gives it (Crazyswarm2's firmware_logging)
    log_error: str = ""                      # why its custom log topics cannot be flown: it is not connected

    @property
    def name(self) -> str:
        return self.tf_prefix


@dataclass(frozen=True)
class SwarmConfig:
    source: str
    crazyflies: Tuple[SwarmCrazyflie, ...]
    types: Mapping[str, CrazyflieType] = field(default_factory=dict)
    notes: Tuple[str, ...] = ()              # what the file asks that is taken from elsewhere here

    def radios(self) -> Dict[int, List[SwarmCrazyflie]]:
        """The Crazyflies of each dongle index, in file order."""
        out: Dict[int, List[SwarmCrazyflie]] = {}
        for cf in self.crazyflies:
            out.setdefault(cf.dongle, []).append(cf)
        return dict(sorted(out.items()))

    @property
    def dongles_needed(self) -> int:
        return 1 + max((cf.dongle for cf in self.crazyflies), default=-1)

    def by_tf_prefix(self) -> Dict[str, SwarmCrazyflie]:
        return {cf.tf_prefix: cf for cf in self.crazyflies}

    def type_of(self, cf: SwarmCrazyflie) -> CrazyflieType:
        return self.types[cf.type]


# -- YAML with line numbers -----------------------------------------------------------------------
class _Doc:
    """A parsed YAML document that still knows the line of every node."""

    def __init__(self, text: str, source: str) -> None:
        self.source = source
        try:
            loader = yaml.SafeLoader(text)
            try:
                node = loader.get_single_node()
                self.data = loader.construct_document(node) if node is not None else None
            finally:
                loader.dispose()
        except yaml.YAMLError as e:
            mark = getattr(e, "problem_mark", None)
            where = "%s:%d" % (source, mark.line + 1) if mark is not None else source
            raise SwarmConfigError("%s: not valid YAML (%s); fix the syntax there"
                                   % (where, getattr(e, "problem", None) or e)) from None
        self._root = node

    def line(self, *path: Any) -> int:
        """1-based line of the node at ``path`` (keys and list indices), or of its nearest parent."""
        node, line = self._root, (self._root.start_mark.line + 1 if self._root is not None else 0)
        for step in path:
            child = None
            if isinstance(node, yaml.MappingNode):
                for k, v in node.value:
                    if k.value == step:
                        child = v
                        line = k.start_mark.line + 1
                        break
            elif isinstance(node, yaml.SequenceNode) and isinstance(step, int) and step < len(node.value):
                child = node.value[step]
                line = child.start_mark.line + 1
            if child is None:
                break
            node = child
        return line

    def error(self, path: Sequence[Any], what: str) -> SwarmConfigError:
        return SwarmConfigError("%s:%d: %s" % (self.source, self.line(*path), what))

    def mapping(self, path: Sequence[Any], where: str, value: Any, known: AbstractSet[str]) -> Dict[str, Any]:
        """``value`` (at ``path``, called ``where``) as a mapping whose keys are all in ``known`` (None: empty)."""
        return _mapping(self, path, where, value, known)


def _read(path: str) -> str:
    try:
        with open(path) as f:
            return f.read()
    except OSError as e:
        raise SwarmConfigError("swarm file %s cannot be read: %s; give the path of a YAML file listing the "
                               "Crazyflies (see crazyflie_driver/config/swarm_example.yaml)"
                               % (path, e.strerror or e)) from None


# -- values ----------------------------------------------------------------------------------------
def _number(doc: _Doc, path: Sequence[Any], where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise doc.error(path, "%s must be a finite number, got %r" % (where, value))
    return float(value)


def _params(doc: _Doc, path: Sequence[Any], where: str, value: Any) -> ParamList:
    """``{group: {name: value}}`` as ("group.name", value) pairs; values numbers or booleans."""
    if value is None:
        return ()
    if not isinstance(value, dict):
        raise doc.error(path, "%s must be a mapping {group: {name: value}}, got %r" % (where, value))
    out = []
    for group, names in value.items():
        if not isinstance(group, str) or not _IDENTIFIER.match(group):
            raise doc.error(list(path) + [group], "%s: %r is not a parameter group name" % (where, group))
        if not isinstance(names, dict) or not names:
            raise doc.error(list(path) + [group], "%s.%s must be a mapping {name: value} (e.g. {estimator: 2}), "
                                                  "got %r" % (where, group, names))
        for name, v in names.items():
            full = "%s.%s" % (group, name)
            here = list(path) + [group, name]
            if not isinstance(name, str) or not _IDENTIFIER.match(name):
                raise doc.error(here, "%s: %r is not a parameter name" % (where, full))
            if isinstance(v, bool):
                v = int(v)
            if not isinstance(v, numbers.Real) or not math.isfinite(float(v)):
                raise doc.error(here, "%s: parameter %s must be a finite number, got %r" % (where, full, v))
            out.append((full, v))
    return tuple(out)


def _switches(doc: _Doc, path: Sequence[Any], where: str, body: Mapping[str, Any]) -> Switches:
    """The logging switches ``body`` sets, each checked to be true or false."""
    out = []
    for name in LOG_SWITCHES:
        if name in body:
            value = body[name]
            if not isinstance(value, bool):
                raise doc.error(list(path) + [name], "%s.%s must be true or false, got %r" % (where, name, value))
            out.append((name, value))
    return tuple(out)


def merge_params(*layers: ParamList) -> ParamList:
    """Later layers win per name; a name keeps the position of its first appearance."""
    merged: Dict[str, Any] = {}
    for layer in layers:
        for name, value in layer:
            merged[name] = value
    return tuple(merged.items())


def _types(doc: _Doc, raw: Any, path: Sequence[Any]) -> Dict[str, CrazyflieType]:
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise doc.error(path, "crazyflieTypes must be a mapping of type name to {firmwareParams, ...}, got %r"
                        % (raw,))
    types = {}
    for name, body in raw.items():
        here = list(path) + [name]
        where = "crazyflieTypes.%s" % name
        body = {} if body is None else body
        if not isinstance(body, dict):
            raise doc.error(here, "%s must be a mapping (firmwareParams, batteryVoltageWarning, "
                                  "batteryVoltageCritical), got %r" % (where, body))
        unknown = sorted(set(body) - _TYPE_KEYS)
        if unknown:
            raise doc.error(here, "%s: unknown key(s) %s; known: %s" % (where, ", ".join(map(str, unknown)),
                                                                      ", ".join(sorted(_TYPE_KEYS))))
        critical_key = "batteryVoltageCritical" if "batteryVoltageCritical" in body else "batteryVoltateCritical"
        warning = _number(doc, here + ["batteryVoltageWarning"], where + ".batteryVoltageWarning",
                          body.get("batteryVoltageWarning", DEFAULT_BATTERY_WARNING_V))
        critical = _number(doc, here + [critical_key], where + ".batteryVoltageCritical",
                           body.get(critical_key, DEFAULT_BATTERY_CRITICAL_V))
        if critical > warning:
            raise doc.error(here, "%s: batteryVoltageCritical %.2f V is above batteryVoltageWarning %.2f V; the "
                                  "critical level must be the lower one" % (where, critical, warning))
        types[str(name)] = CrazyflieType(str(name), _params(doc, here + ["firmwareParams"], where + ".firmwareParams",
                                                            body.get("firmwareParams")), warning, critical,
                                         _switches(doc, here, where, body))
    return types


# -- the file --------------------------------------------------------------------------------------
def load_swarm_file(path: str, types_path: Optional[str] = None, dongles: Optional[int] = None) -> SwarmConfig:
    """The swarm in ``path`` (types there or in ``types_path``), checked; ``dongles``: the number of
    Crazyradios present, when known (more radios needed than present is refused)."""
    types_text = _read(types_path) if types_path else None
    return parse_swarm(_read(path), path, types_text, types_path or "", dongles)


def parse_swarm(text: str, source: str = "<swarm file>", types_text: Optional[str] = None,
                types_source: str = "<types file>", dongles: Optional[int] = None) -> SwarmConfig:
    """:func:`load_swarm_file` on text (tests and the sim node use it directly)."""
    doc = _Doc(text, source)
    data = doc.data
    if isinstance(data, dict) and "robots" in data:
        if types_text is not None:
            raise doc.error(["robots"], "a Crazyswarm2 file (robots, robot_types, all) holds its types itself; "
                                        "give no separate types file")
        return _parse_crazyswarm2(doc, data, dongles)
    data = _top_level(doc, data)
    types = _types(doc, data.get("crazyflieTypes"), ["crazyflieTypes"])
    if types_text is not None:
        _add_types_file(types, types_text, types_source, source)
    _with_default_type(types)
    swarm_params = _params(doc, ["firmwareParams"], "firmwareParams", data.get("firmwareParams"))
    entries = data["crazyflies"]
    if not isinstance(entries, list) or not entries:
        raise doc.error(["crazyflies"], "'crazyflies' must be a non-empty list of {id, channel, initialPosition, "
                                        "type}, got %r" % (entries,))
    return SwarmConfig(source, _crazyflies(doc, entries, types, swarm_params, dongles), types)


def _top_level(doc: _Doc, data: Any) -> Dict[str, Any]:
    """``data`` once checked as a Crazyswarm 1 file: a mapping with 'crazyflies' and only keys it knows."""
    if not isinstance(data, dict) or "crazyflies" not in data:
        raise doc.error([], "a swarm file is a mapping with a 'crazyflies' list (and 'crazyflieTypes'); "
                            "see crazyflie_driver/config/swarm_example.yaml")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise doc.error([unknown[0]], "unknown top-level key(s) %s; known: %s"
                        % (", ".join(map(str, unknown)), ", ".join(sorted(_TOP_KEYS))))
    return data


def _add_types_file(types: Dict[str, CrazyflieType], text: str, source: str, swarm_source: str) -> None:
    """The types of a separate types file added to ``types``; a type defined in both is refused."""
    tdoc = _Doc(text, source)
    traw = tdoc.data
    if not isinstance(traw, dict) or "crazyflieTypes" not in traw:
        raise tdoc.error([], "a types file is a mapping with a 'crazyflieTypes' entry")
    for name, t in _types(tdoc, traw["crazyflieTypes"], ["crazyflieTypes"]).items():
        if name in types:
            raise tdoc.error(["crazyflieTypes", name], "type %r is defined in %s too; define it once"
                             % (name, swarm_source))
        types[name] = t


def _with_default_type(types: Dict[str, CrazyflieType]) -> Dict[str, CrazyflieType]:
    """``types`` with the built-in ``default`` type added when the file defines none of that name."""
    if DEFAULT_TYPE not in types:
        types[DEFAULT_TYPE] = CrazyflieType(DEFAULT_TYPE, BUILTIN_DEFAULT_PARAMS)
    return types


# -- Crazyswarm2's crazyflies.yaml ------------------------------------------------------------------
# Keys of Crazyswarm2's own example files that change nothing here: a robot's ``role`` (a label for the
# user's scripts) and a top-level ``relative: false``; ``relative: true`` is refused (not supported).
_CS2_TOP_KEYS = {"fileversion", "robots", "robot_types", "all", "relative"}
_CS2_ROBOT_KEYS = {"enabled", "uri", "initial_position", "type", "firmware_params", "firmware_logging",
                   "role"} | set(LOG_SWITCHES)
_CS2_TYPE_KEYS = {"motion_capture", "big_quad", "battery", "firmware_params", "firmware_logging"} | set(LOG_SWITCHES)
_CS2_ALL_KEYS = {"firmware_params", "firmware_logging", "broadcasts"}


def _mapping(doc: _Doc, path: Sequence[Any], where: str, value: Any, known: AbstractSet[str]) -> Dict[str, Any]:
    """``value`` as a mapping whose keys are all in ``known`` (None: empty)."""
    value = {} if value is None else value
    if not isinstance(value, dict):
        raise doc.error(path, "%s must be a mapping, got %r" % (where, value))
    unknown = sorted(map(str, set(value) - known))
    if unknown:
        raise doc.error(list(path) + [unknown[0]], "%s: unknown key(s) %s; known: %s"
                        % (where, ", ".join(unknown), ", ".join(sorted(known))))
    return value


def _logging_note(where: str, logging: Any) -> List[str]:
    note = default_topics_note(where, logging)
    return [note] if note else []


def _parse_crazyswarm2(doc: _Doc, data: Dict[str, Any], dongles: Optional[int]) -> SwarmConfig:
    """A Crazyswarm2 file, read into the same swarm as a Crazyswarm 1 file (the robot's name is its
    tf_prefix; a robot with ``enabled: false`` is left out; ``enabled`` missing counts as true)."""
    _mapping(doc, [], "a Crazyswarm2 swarm file", data, _CS2_TOP_KEYS)
    if data.get("relative", False) is not False:
        raise doc.error(["relative"], "relative: %r is not supported: remove it or set it to false (positions "
                        "are in the world frame)" % (data["relative"],))
    notes: List[str] = []
    types = _cs2_types(doc, data.get("robot_types") or {}, notes)
    swarm_params = _cs2_all(doc, data.get("all"), notes)
    entries = _cs2_robots(doc, data["robots"], notes)
    crazyflies = _crazyflies(doc, [item for _, item in entries], types, swarm_params, dongles,
                             paths=[here for here, _ in entries])
    crazyflies = tuple(_with_log_topics(doc, data, cf, here[1], notes) for cf, (here, _) in zip(crazyflies, entries))
    return SwarmConfig(doc.source, crazyflies, types, tuple(dict.fromkeys(notes)))


def _with_log_topics(doc: _Doc, data: Dict[str, Any], cf: SwarmCrazyflie, name: Any,
                     notes: List[str]) -> SwarmCrazyflie:
    """``cf`` with its custom log topics: ``all``'s, its type's and its own ``firmware_logging`` merged
    (``server.swarm.file_logging``); a fault in them goes to ``log_error``, not to the whole swarm."""
    def raw(body: Any) -> Any:
        return body.get("firmware_logging") if isinstance(body, dict) else None
    raw_types = data.get("robot_types")
    raw_types = raw_types if isinstance(raw_types, dict) else {}
    levels: List[Level] = [(["all", "firmware_logging"], "all", raw(data.get("all"))),
                           (["robot_types", cf.type, "firmware_logging"], "robot_types.%s" % cf.type,
                            raw(raw_types.get(cf.type))),
                           (["robots", name, "firmware_logging"], "robots.%s" % name, raw(data["robots"][name]))]
    blocks, error = crazyflie_log_topics(doc, [level for level in levels if level[2] is not None], notes)
    return replace(cf, log_blocks=blocks, log_error=error) if blocks or error else cf


def _cs2_types(doc: _Doc, raw_types: Any, notes: List[str]) -> Dict[str, CrazyflieType]:
    """``robot_types``, with the built-in default type; what they ask of elsewhere goes to ``notes``."""
    if not isinstance(raw_types, dict):
        raise doc.error(["robot_types"], "robot_types must be a mapping of type name to {battery, "
                                         "firmware_params, ...}, got %r" % (raw_types,))
    types: Dict[str, CrazyflieType] = {}
    for name, body in raw_types.items():
        types[str(name)] = _cs2_type(doc, name, body, notes)
    return _with_default_type(types)


def _cs2_type(doc: _Doc, name: Any, body: Any, notes: List[str]) -> CrazyflieType:
    """One entry of ``robot_types``: battery levels and firmware parameters."""
    here = ["robot_types", name]
    where = "robot_types.%s" % name
    body = _mapping(doc, here, where, body, _CS2_TYPE_KEYS)
    battery = body.get("battery") or {}
    if not isinstance(battery, dict):
        raise doc.error(here + ["battery"], "%s.battery must be {voltage_warning, voltage_critical}, got %r"
                        % (where, battery))
    warning = _number(doc, here + ["battery"], where + ".battery.voltage_warning",
                      battery.get("voltage_warning", DEFAULT_BATTERY_WARNING_V))
    critical = _number(doc, here + ["battery"], where + ".battery.voltage_critical",
                       battery.get("voltage_critical", DEFAULT_BATTERY_CRITICAL_V))
    if critical > warning:
        raise doc.error(here + ["battery"], "%s: voltage_critical %.2f V is above voltage_warning %.2f V; the "
                                            "critical level must be the lower one" % (where, critical, warning))
    mocap = body.get("motion_capture")
    if isinstance(mocap, dict) and mocap.get("enabled") is False:
        notes.append("%s.motion_capture.enabled is false: in swarm mode every Crazyflie gets the motion "
                     "capture the server streams (~mocap none turns it off for all)" % where)
    notes.extend(_logging_note(where, body.get("firmware_logging")))
    return CrazyflieType(str(name), _params(doc, here + ["firmware_params"], where + ".firmware_params",
                                            body.get("firmware_params")), warning, critical,
                         _switches(doc, here, where, body))


def _cs2_all(doc: _Doc, raw: Any, notes: List[str]) -> ParamList:
    """The swarm-wide firmware parameters of ``all``; its logging and broadcasts go to ``notes``."""
    every = _mapping(doc, ["all"], "all", raw, _CS2_ALL_KEYS)
    swarm_params = _params(doc, ["all", "firmware_params"], "all.firmware_params", every.get("firmware_params"))
    notes.extend(_logging_note("all", every.get("firmware_logging")))
    if every.get("broadcasts"):
        notes.append("all.broadcasts: broadcast repeats come from the server's ~broadcast_repeats and "
                     "~broadcast_interval, not from the file")
    return swarm_params


def _cs2_robots(doc: _Doc, robots: Any, notes: List[str]) -> List[Tuple[List[Any], Dict[str, Any]]]:
    """(path, Crazyswarm 1 entry) of each enabled robot; at least one."""
    if not isinstance(robots, dict) or not robots:
        raise doc.error(["robots"], "'robots' must be a non-empty mapping of name to {enabled, uri, "
                                    "initial_position, type}, got %r" % (robots,))
    entries: List[Tuple[List[Any], Dict[str, Any]]] = []
    for name, body in robots.items():
        here = ["robots", name]
        item = _cs2_robot(doc, here, body, notes)
        if item is not None:
            entries.append((here, item))
    if not entries:
        raise doc.error(["robots"], "no robot is enabled; set 'enabled: true' on the Crazyflies to fly")
    return entries


def _cs2_robot(doc: _Doc, here: List[Any], body: Any, notes: List[str]) -> Optional[Dict[str, Any]]:
    """A robot as a Crazyswarm 1 entry (its name as tf_prefix), or None when it is not enabled."""
    name = here[-1]
    where = "robots.%s" % name
    body = _mapping(doc, here, where, body, _CS2_ROBOT_KEYS)
    if body.get("enabled", True) is False:
        return None
    if "uri" not in body:
        raise doc.error(here, "%s: give its 'uri' (e.g. radio://0/80/2M/E7E7E7E701)" % where)
    notes.extend(_logging_note(where, body.get("firmware_logging")))
    item = {"uri": body["uri"], "tf_prefix": str(name), "type": body.get("type", DEFAULT_TYPE)}
    if "initial_position" in body:
        item["initialPosition"] = body["initial_position"]
    if "firmware_params" in body:
        item["firmwareParams"] = body["firmware_params"]
    item.update((n, body[n]) for n in LOG_SWITCHES if n in body)
    return item


def _crazyflies(doc: _Doc, entries: List[Any], types: Dict[str, CrazyflieType], swarm_params: ParamList,
                dongles: Optional[int], paths: Optional[List[List[Any]]] = None) -> Tuple[SwarmCrazyflie, ...]:
    """``paths``: where each entry is in the file (Crazyswarm 1: ``crazyflies[i]``)."""
    paths = paths if paths is not None else [["crazyflies", i] for i in range(len(entries))]
    parsed = [_entry(doc, i, item, types, paths[i]) for i, item in enumerate(entries)]
    dongle_of = dongle_per_channel([(e["uri"], e["channel"]) for e in parsed])
    out: List[SwarmCrazyflie] = []
    seen: Tuple[Dict[Any, int], Dict[Any, int], Dict[Any, int]] = ({}, {}, {})     # ids, URIs, tf_prefixes
    for e in parsed:
        i, where = e["index"], e["where"]
        uri = e["uri"]
        if uri is None:
            uri = _default_uri(dongle_of[int(e["channel"])], e["channel"], e["id"])
        key = str(uri)
        _check_unique(doc, paths, e, key, seen)
        if dongles is not None and uri.index >= dongles:
            raise doc.error(paths[i], "%s: needs Crazyradio %d (channel %d) but %d %s present; the swarm "
                                               "uses %d channel(s), one Crazyradio each: plug in more Crazyradios or "
                                               "put these Crazyflies on fewer channels"
                            % (where, uri.index, uri.channel, dongles, "is" if dongles == 1 else "are",
                               len(set(dongle_of.values()))))
        params = merge_params(swarm_params, types[e["type"]].firmware_params, e["params"])
        switches = merge_params(types[e["type"]].switches, e["switches"])
        out.append(SwarmCrazyflie(e["id"], key, uri.index, uri.channel, e["tf_prefix"], e["position"], e["type"],
                                  params, e["group_mask"], doc.line(*paths[i]), switches))
    return tuple(out)


def dongle_per_channel(links: Sequence[Tuple[Any, int]]) -> Dict[int, int]:
    """The Crazyradio index of each channel, from (explicit URI or None, channel) per Crazyflie in file
    order: a channel named in an explicit URI stays on that URI's dongle; the other channels get the
    lowest free dongle each, in order of appearance."""
    dongle_of: Dict[int, int] = {}
    for uri, _ in links:
        if uri is not None:
            dongle_of.setdefault(uri.channel, uri.index)
    used = set(dongle_of.values())
    next_free = 0
    for uri, channel in links:
        if uri is None and channel not in dongle_of:
            while next_free in used:
                next_free += 1
            dongle_of[channel] = next_free
            used.add(next_free)
    return dongle_of


def _default_uri(dongle: int, channel: int, ident: int) -> Any:
    """The URI of a Crazyflie given by id and channel: the default data rate and address prefix."""
    return parse_uri("radio://%d/%d/%s/%s%02X" % (dongle, channel, DATARATE_NAMES[DEFAULT_DATARATE],
                                                   ADDRESS_PREFIX, ident))


def _check_unique(doc: _Doc, paths: List[List[Any]], e: Dict[str, Any], uri: str,
                  seen: Tuple[Dict[Any, int], Dict[Any, int], Dict[Any, int]]) -> None:
    """Refuses an entry whose id, URI or tf_prefix an earlier one has, else records them in ``seen``
    (ids, URIs, tf_prefixes: each to the index of its entry)."""
    i = e["index"]
    # unique ids also keep packed motion capture unambiguous: it names a Crazyflie by its id
    for table, value, what in zip(seen, (e["id"], uri, e["tf_prefix"]),
                                  ("id %s" % e["id"], "URI %s" % uri, "tf_prefix %r" % e["tf_prefix"])):
        if value in table:
            first = table[value]
            raise doc.error(paths[i], "%s: %s is already used by %s (line %d); give each Crazyflie its own"
                            % (e["where"], what, _label(paths[first]), doc.line(*paths[first])))
        table[value] = i


def _label(path: Sequence[Any]) -> str:
    """An entry's name in messages: ``crazyflies[i]`` (Crazyswarm 1) or ``robots.<name>`` (Crazyswarm2)."""
    return "crazyflies[%d]" % path[1] if path[0] == "crazyflies" else "%s.%s" % (path[0], path[1])


def _entry(doc: _Doc, i: int, item: Any, types: Dict[str, CrazyflieType],
           path: Optional[List[Any]] = None) -> Dict[str, Any]:
    path = path if path is not None else ["crazyflies", i]
    where = _label(path)
    if not isinstance(item, dict):
        raise doc.error(path, "%s must be a mapping {id, channel, initialPosition, type}, got %r" % (where, item))
    if "id" in item:
        where = "%s (id %s)" % (where, item["id"])
    unknown = sorted(set(item) - _ENTRY_KEYS)
    if unknown:
        raise doc.error(path + [unknown[0]], "%s: unknown key(s) %s; known: %s"
                        % (where, ", ".join(map(str, unknown)), ", ".join(sorted(_ENTRY_KEYS))))
    uri = _entry_uri(doc, path, where, item)
    ident = _entry_id(doc, path, where, item, uri)
    channel = _entry_channel(doc, path, where, item, uri)
    position = _entry_position(doc, path, where, item)
    kind = _entry_type(doc, path, where, item, types)
    tf_prefix = _entry_tf_prefix(doc, path, where, item, ident)
    mask = _entry_group_mask(doc, path, where, item)
    params = _entry_params(doc, path, where, item)
    return {"index": i, "where": where, "id": ident, "uri": uri, "channel": channel, "position": position,
            "type": kind, "tf_prefix": tf_prefix.strip("/"), "group_mask": mask, "params": params,
            "switches": _switches(doc, path, where, item)}


def _entry_uri(doc: _Doc, path: List[Any], where: str, item: Dict[str, Any]) -> Any:
    """The entry's ``uri`` parsed, or None when it gives none."""
    if "uri" not in item:
        return None
    try:
        return parse_uri(item["uri"])
    except UriError as e:
        raise doc.error(path + ["uri"], "%s: %s" % (where, e)) from None


def _entry_id(doc: _Doc, path: List[Any], where: str, item: Dict[str, Any], uri: Any) -> int:
    """The entry's ``id`` (else its URI's last address byte); both given must agree."""
    ident = item.get("id")
    if ident is None:
        if uri is None:
            raise doc.error(path, "%s: give an 'id' (1..255: the address's last byte) or a 'uri'" % where)
        ident = uri.address[-1]
    if isinstance(ident, bool) or not isinstance(ident, int) or not 0 <= ident <= MAX_ID:
        raise doc.error(path + ["id"], "%s: id must be an integer 0..%d (the last byte of the radio address), "
                                       "got %r" % (where, MAX_ID, ident))
    if uri is not None and "id" in item and uri.address[-1] != ident:
        raise doc.error(path + ["uri"], "%s: uri %s ends in 0x%02X but id is %d (0x%02X); the packed motion "
                                        "capture reaches a Crazyflie by that last byte: make them agree"
                        % (where, uri, uri.address[-1], ident, ident))
    return ident


def _entry_channel(doc: _Doc, path: List[Any], where: str, item: Dict[str, Any], uri: Any) -> int:
    """The entry's ``channel`` (else its URI's); both given must agree."""
    channel = item.get("channel", uri.channel if uri is not None else None)
    if isinstance(channel, bool) or not isinstance(channel, int) or not 0 <= channel <= MAX_CHANNEL:
        raise doc.error(path + ["channel"], "%s: channel must be an integer 0..%d, got %r"
                        % (where, MAX_CHANNEL, channel))
    if uri is not None and channel != uri.channel:
        raise doc.error(path + ["channel"], "%s: channel %d but uri %s is on channel %d; make them agree"
                        % (where, channel, uri, uri.channel))
    return channel


def _entry_position(doc: _Doc, path: List[Any], where: str, item: Dict[str, Any]) -> Tuple[float, ...]:
    """The entry's ``initialPosition`` (m; default the origin)."""
    pos = item.get("initialPosition", [0.0, 0.0, 0.0])
    if not isinstance(pos, (list, tuple)) or len(pos) != 3:
        raise doc.error(path + ["initialPosition"], "%s: initialPosition must be [x, y, z] in metres, got %r"
                        % (where, pos))
    return tuple(_number(doc, path + ["initialPosition"], where + ".initialPosition", v) for v in pos)


def _entry_type(doc: _Doc, path: List[Any], where: str, item: Dict[str, Any],
                types: Dict[str, CrazyflieType]) -> str:
    """The entry's ``type``, one of ``types``."""
    kind = item.get("type", DEFAULT_TYPE)
    if kind not in types:
        raise doc.error(path + ["type"], "%s: unknown type %r; defined types: %s (add it under %s)"
                        % (where, kind, ", ".join(sorted(types)),
                           "crazyflieTypes" if path[0] == "crazyflies" else "robot_types"))
    return kind


def _entry_tf_prefix(doc: _Doc, path: List[Any], where: str, item: Dict[str, Any], ident: int) -> str:
    """The entry's ``tf_prefix`` (default ``cf<id>``), a ROS namespace."""
    tf_prefix = item.get("tf_prefix", "cf%d" % ident)
    if not isinstance(tf_prefix, str) or not all(_IDENTIFIER.match(p) and p[0].isalpha()
                                                 for p in tf_prefix.strip("/").split("/")):
        raise doc.error(path + ["tf_prefix"], "%s: tf_prefix %r is not a ROS namespace (letters, digits, '_', "
                                              "starting with a letter)" % (where, tf_prefix))
    return tf_prefix


def _entry_group_mask(doc: _Doc, path: List[Any], where: str, item: Dict[str, Any]) -> int:
    """The entry's ``groupMask`` (0..255; 0: leave the firmware's)."""
    mask = item.get("groupMask", 0)
    if isinstance(mask, bool) or not isinstance(mask, int) or not 0 <= mask <= 0xFF:
        raise doc.error(path + ["groupMask"], "%s: groupMask must be an integer 0..255 (bit i = group i), got %r"
                        % (where, mask))
    return mask


def _entry_params(doc: _Doc, path: List[Any], where: str, item: Dict[str, Any]) -> ParamList:
    """The entry's own firmware parameters, under ``params`` or ``firmwareParams`` (not both)."""
    if "params" in item and "firmwareParams" in item:
        raise doc.error(path + ["firmwareParams"], "%s: give params or firmwareParams, not both" % where)
    own_key = "params" if "params" in item else "firmwareParams"
    return _params(doc, path + [own_key], where + "." + own_key, item.get(own_key))
