"""The simulated world node's parameters, checked without ROS (``nodes.sim_node`` is their adapter).

Every function takes the node's private parameters as a plain mapping and either returns typed
settings or raises ``SimConfigError`` naming the parameter, so a wrong launch file stops the node with
one clear line and nothing started. ``plan_from_params`` is the whole start-up decision in one place.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Set, Tuple

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import UriError
from crazyflie_driver.sim.air.faults import MAX_MOCAP_LATENCY_S, MAX_MOCAP_NOISE_M
from crazyflie_driver.sim.crtp.memory_port import DECKS
from crazyflie_driver.sim.onboard.stabilizer import PLATFORM_CF2, PLATFORMS
from crazyflie_driver.sim.priority import DEFAULT_PRIORITY_BOOST
from crazyflie_driver.sim.room.pacing import Pacing, parse_pacing

DEFAULT_ADDRESS = "127.0.0.1:19840"
"""Where the world serves the fake Crazyradios when ``~address`` is not set (``CRAZYFLIE_SIM_ADDRESS``)."""

MOCAP_STYLES = ("vicon", "vrpn", "both", "none")


class SimConfigError(ValueError):
    """A sim node parameter that is missing or wrong; the message names it."""


@dataclass(frozen=True)
class VehicleSpec:
    uri: str
    name: str
    position: tuple
    yaw: float = 0.0
    firmware: str = "current"
    frame: str = ""          # vicon style: tf child frame of its pose; "" = vicon/<name>/<name>
    platform: str = PLATFORM_CF2     # "brushless": must be armed before its motors spin
    decks: tuple = ()                # board names (e.g. bcFlow2): one-wire memories, deck.<name> params read 1


@dataclass(frozen=True)
class MocapConfig:
    style: str = "vicon"
    rate: float = 100.0
    noise: float = 0.0
    latency: float = 0.0
    dropout: float = 0.0
    world_frame: str = "world"


def _number(what: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise SimConfigError("%s must be a number, got %r" % (what, value))
    return float(value)


def _parse_vehicles_text(text: str) -> Any:
    """``~vehicles`` given as text: the path of a YAML file, or the YAML itself."""
    import os

    import yaml

    text = text.strip()
    try:
        if os.path.isfile(text):
            with open(text) as f:
                return yaml.safe_load(f)
        return yaml.safe_load(text)
    except (OSError, yaml.YAMLError) as e:
        raise SimConfigError("~vehicles is neither a readable YAML file nor a YAML list: %s" % e) from None


def _frame(where: str, value: Any) -> str:
    """A vehicle's optional tf frame as tf2 wants it (no leading '/'); "" when not given."""
    if value is None:
        return ""
    frame = str(value).strip().strip("/")
    if not frame or not all(c.isalnum() or c in "_/-." for c in frame):
        raise SimConfigError("%s: frame %r is not a tf frame name (letters, digits, '_', '-', '.', '/')"
                             % (where, value))
    return frame


def _decks(where: str, decks: Any) -> tuple:
    """A vehicle's ``decks``: a list of board names the simulated firmware knows."""
    if not isinstance(decks, list) or any(d not in DECKS for d in decks):
        raise SimConfigError("%s: decks must be a list of deck names out of %s, got %r"
                             % (where, ", ".join(sorted(DECKS)), decks))
    return tuple(decks)


_VEHICLE_KEYS = frozenset({"uri", "name", "x", "y", "z", "position", "yaw", "firmware", "frame", "platform", "decks"})


def vehicles_from_params(params: Mapping[str, Any]) -> List[VehicleSpec]:
    """``~vehicles`` (or ``~uri``/``~name``) checked; names must be valid ROS names, URIs unique."""
    out: List[VehicleSpec] = []
    seen_names: Set[str] = set()
    seen_uris: Set[str] = set()
    for i, item in enumerate(_vehicle_items(params)):
        where = "~vehicles[%d]" % i
        _check_vehicle_keys(where, item)
        uri = _vehicle_uri(where, item)
        name = _vehicle_name(where, item, i)
        position = _vehicle_position(where, item)
        _check_unique(where, name, seen_names, "name %r" % name)
        _check_unique(where, uri, seen_uris, "URI %s" % uri)
        platform = _vehicle_platform(where, item)
        out.append(VehicleSpec(uri, name, position, _number(where + ".yaw", item.get("yaw", 0.0)),
                               str(item.get("firmware", "current")), _frame(where, item.get("frame")), platform,
                               _decks(where, item.get("decks", []))))
    return out


def _vehicle_items(params: Mapping[str, Any]) -> list:
    """The raw vehicle entries: ``~vehicles`` as a list, a YAML text or file (a list, or a mapping with
    ``vehicles``), else the one vehicle of ``~uri``, ``~name`` and ``~x``/``~y``/``~z``."""
    raw = params.get("vehicles")
    if isinstance(raw, str) and raw.strip():
        raw = _parse_vehicles_text(raw)
    if raw in (None, "", []):
        if not params.get("uri"):
            raise SimConfigError("no vehicles: set ~vehicles (a list of {uri, name, x, y, z}) or ~uri and ~name")
        raw = [{"uri": params["uri"], "name": params.get("name", "crazyflie"),
                "x": params.get("x", 0.0), "y": params.get("y", 0.0), "z": params.get("z", 0.0)}]
    if isinstance(raw, dict) and "vehicles" in raw:
        raw = raw["vehicles"]
    if not isinstance(raw, list):
        raise SimConfigError("~vehicles must be a list of {uri, name, x, y, z}, got %r" % (raw,))
    return raw


def _check_vehicle_keys(where: str, item: Any) -> None:
    if not isinstance(item, dict) or "uri" not in item:
        raise SimConfigError("%s needs at least a 'uri' (got %r)" % (where, item))
    unknown = set(item) - _VEHICLE_KEYS
    if unknown:
        raise SimConfigError("%s has unknown keys %s" % (where, ", ".join(sorted(unknown))))


def _vehicle_uri(where: str, item: Mapping[str, Any]) -> str:
    """The radio URI in its canonical form, so two spellings of one Crazyflie count as the same."""
    try:
        return str(parse_uri(str(item["uri"])))
    except UriError as e:
        raise SimConfigError("%s: %s" % (where, e)) from None


def _vehicle_name(where: str, item: Mapping[str, Any], i: int) -> str:
    """The given name (a valid ROS name), or crazyflie<i + 1>."""
    name = str(item.get("name") or "crazyflie%d" % (i + 1))
    if not (name[0].isalpha() and all(c.isalnum() or c == "_" for c in name)):
        raise SimConfigError("%s: name %r is not a valid ROS name (letters, digits, '_')" % (where, name))
    return name


def _vehicle_position(where: str, item: Mapping[str, Any]) -> tuple:
    """``position: [x, y, z]``, else ``x``, ``y``, ``z`` (each 0 when not given), in m."""
    if "position" not in item:
        return tuple(_number("%s.%s" % (where, k), item.get(k, 0.0)) for k in ("x", "y", "z"))
    pos = item["position"]
    if not isinstance(pos, (list, tuple)) or len(pos) != 3:
        raise SimConfigError("%s: position must be [x, y, z], got %r" % (where, pos))
    return tuple(_number(where + ".position", v) for v in pos)


def _check_unique(where: str, value: str, seen: Set[str], what: str) -> None:
    """Refuses ``value`` (described as ``what``) when an earlier vehicle has it; else remembers it."""
    if value in seen:
        raise SimConfigError("%s: %s is used twice" % (where, what))
    seen.add(value)


def _vehicle_platform(where: str, item: Mapping[str, Any]) -> str:
    platform = item.get("platform", PLATFORM_CF2)
    if platform not in PLATFORMS:
        raise SimConfigError("%s: platform must be one of %s (brushless: armed before its motors spin), got %r"
                             % (where, ", ".join(PLATFORMS), platform))
    return platform


def vehicles_from_swarm(path: str, crazyflies: Sequence[Any]) -> List[VehicleSpec]:
    """The vehicles of a loaded swarm file (``server.swarm.config``: each with ``id``, ``uri``, ``name``
    and ``initial_position``); ``path`` only names the file in the error."""
    out = []
    for cf in crazyflies:
        if "/" in cf.name:
            raise SimConfigError("%s: tf_prefix %r of id %d has a '/': the simulated body (and its motion-capture "
                                 "name) must be one ROS name" % (path, cf.name, cf.id))
        out.append(VehicleSpec(cf.uri, cf.name, tuple(cf.initial_position)))
    return out


def mocap_from_params(params: Mapping[str, Any]) -> MocapConfig:
    style = str(params.get("mocap", "vicon")).strip().lower()
    if style not in MOCAP_STYLES:
        raise SimConfigError("~mocap must be one of %s, got %r" % ("|".join(MOCAP_STYLES), style))
    rate = _number("~mocap_rate", params.get("mocap_rate", 100.0))
    if not 0.0 < rate <= 1000.0:
        raise SimConfigError("~mocap_rate must be in (0, 1000] Hz, got %r" % rate)
    noise = _number("~mocap_noise", params.get("mocap_noise", 0.0))
    latency = _number("~mocap_latency", params.get("mocap_latency", 0.0))
    dropout = _number("~mocap_dropout", params.get("mocap_dropout", 0.0))
    if not (0 <= noise <= MAX_MOCAP_NOISE_M and 0 <= latency <= MAX_MOCAP_LATENCY_S and 0.0 <= dropout < 1.0):
        raise SimConfigError("~mocap_noise must be 0..%g m, ~mocap_latency 0..%g s and ~mocap_dropout in [0, 1), "
                             "got %r, %r and %r" % (MAX_MOCAP_NOISE_M, MAX_MOCAP_LATENCY_S, noise, latency, dropout))
    frame = str(params.get("world_frame", "world")).strip("/") or "world"
    return MocapConfig(style, rate, noise, latency, dropout, frame)


def vrpn_port_from_params(params: Mapping[str, Any]) -> Tuple[bool, Optional[int]]:
    """(serve VRPN?, port): ``~vrpn`` a bool; ``~vrpn_port`` None (3883 when free) or 0..65535."""
    on = params.get("vrpn", False)
    if isinstance(on, str):
        on = on.strip().lower() in ("true", "1", "yes")
    port = params.get("vrpn_port")
    if port in (None, ""):
        return bool(on), None
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise SimConfigError("~vrpn_port must be a TCP port 0..65535 (0: any free one), got %r" % (port,))
    return bool(on), int(port)


def dongles_needed(vehicles: Sequence[VehicleSpec], requested: Optional[int]) -> int:
    need = max(parse_uri(v.uri).index for v in vehicles) + 1
    if requested is None:
        return need
    if int(requested) < need:
        raise SimConfigError("~dongles is %d but a vehicle uses radio index %d" % (requested, need - 1))
    return int(requested)


def mocap_model(world: Any, config: MocapConfig, seed: Optional[int] = None):
    """The world's motion-capture model (``sim.room.mocap.MocapModel``) with the node's settings:
    position noise ``config.noise`` (m), no orientation noise, ``latency`` (s), ``dropout``."""
    from crazyflie_driver.sim.room.mocap import MocapModel

    return MocapModel(world, rate=config.rate, position_noise=config.noise, orientation_noise=0.0,
                      latency=config.latency, dropout=config.dropout, seed=seed)


def newest_per_body(frames: Sequence[Any]) -> List[Any]:
    """The newest of each body's frames (frames oldest first, as the motion-capture model delivers them).

    When the publisher falls behind, a delivery holds several frames of one body: tf gets only the
    newest, so no two transforms of one frame go out in one message.
    """
    newest: Dict[str, Any] = {}
    for f in frames:
        newest[f.name] = f
    return list(newest.values())


class StampGuard:
    """Remembers the last stamp sent per child frame and admits only strictly later ones.

    tf2 drops a transform whose stamp equals the last one of its child frame and warns
    TF_REPEATED_DATA each time; stamps are compared as integer nanoseconds, as they go on the wire.
    """

    def __init__(self) -> None:
        self._last: Dict[str, int] = {}
        self.refused = 0

    def admit(self, child: str, stamp_ns: int) -> bool:
        last = self._last.get(child)
        if last is not None and stamp_ns <= last:
            self.refused += 1
            return False
        self._last[child] = stamp_ns
        return True


@dataclass(frozen=True)
class WorldStatus:
    """How the world keeps up with real time, for /diagnostics."""

    level: int                  # 0 OK, 1 WARN (diagnostic_msgs/DiagnosticStatus levels)
    message: str
    values: Tuple[Tuple[str, str], ...]


def world_status(realtime_factor: float, speed: float, vehicles: int, ticks_behind: int, overruns: int,
                 world_time: float, behind_factor: float, pacing: Optional[Pacing] = None,
                 host_lag_s: Optional[float] = None) -> WorldStatus:
    """The world's real-time status; WARN when it runs below ``behind_factor`` × its speed.

    ``pacing``: the speed setting (``auto``: ``speed`` is where it has set the world now, ``target``
    where it returns to); ``host_lag_s``: the host's latest mean run-queue wait per time slice [wall s]
    (auto only)."""
    pacing = pacing if pacing is not None else Pacing(False, speed)
    slowed = pacing.auto and speed < pacing.target * behind_factor
    if speed <= 0:
        level, message = 0, "fast mode: %.1fx real time" % realtime_factor
    elif realtime_factor < speed * behind_factor:
        level, message = 1, ("behind real time: %.2fx instead of %.2fx (%d ticks behind); rates that follow the "
                             "firmware's clock are low by the same factor" % (realtime_factor, speed, ticks_behind))
    elif slowed:
        level, message = 0, ("slowed down to %.2fx for a lagging host (speed auto, up to %.2fx); ROS time follows"
                             % (realtime_factor, pacing.target))
    else:
        level, message = 0, "keeps real time (%.2fx)" % realtime_factor
    values: Tuple[Tuple[str, str], ...] = (("real-time factor", "%.3f" % realtime_factor), ("speed", "%.3f" % speed),
              ("speed mode", pacing.mode), ("target speed", "%.3f" % pacing.target),
              ("vehicles", str(vehicles)), ("ticks behind", str(ticks_behind)), ("overruns", str(overruns)),
              ("world time [s]", "%.3f" % world_time))
    if host_lag_s is not None:
        values += (("host run-queue wait [ms]", "%.2f" % (host_lag_s * 1e3)),)
    return WorldStatus(level, message, values)


def start_faults_from_params(params: Mapping[str, Any], dongles: int) -> List[Tuple[str, Dict[str, Any]]]:
    """The control operations that ``~packet_loss``, ``~ack_loss``, ``~latency_ms`` and ``~faults`` ask for
    at start (in that order); SimConfigError naming the parameter when one is wrong."""
    from crazyflie_driver.sim.air import faults

    ops: List[Tuple[str, Dict[str, Any]]] = []
    radio: Dict[str, Any] = {}
    try:
        for key, arg in (("packet_loss", "packet_loss"), ("ack_loss", "ack_loss")):
            if params.get(key) not in (None, "", 0, 0.0):
                radio[arg] = faults.fraction("~" + key, params[key]) * 100.0
        if params.get("latency_ms") not in (None, "", 0, 0.0):
            radio["latency_s"] = faults.duration("~latency_ms", "%sms" % (params["latency_ms"],))
    except faults.FaultError as e:
        raise SimConfigError(str(e)) from None
    if radio:
        ops += [("set_dongle_faults", dict(radio, dongle=d)) for d in range(dongles)]
    for command in faults.split_commands(params.get("faults") or ""):
        try:
            ops.append(faults.parse_command(command))
        except faults.FaultError as e:
            raise SimConfigError("~faults: %r: %s" % (command, e)) from None
    return ops


def faults_status(faults: Sequence[Sequence[str]]) -> WorldStatus:
    """The injected faults for /diagnostics: OK with none, WARN listing them otherwise."""
    if not faults:
        return WorldStatus(0, "no faults injected", ())
    return WorldStatus(1, "%d injected: %s" % (len(faults), "; ".join("%s %s" % (t, d) for t, d in faults)),
                       tuple((str(t), str(d)) for t, d in faults))


SwarmLoader = Callable[[str], Tuple[List[VehicleSpec], int]]
"""Reads a swarm file: (its vehicles, the dongles they need); the node passes one built on
``server.swarm.config.load_swarm_file``."""


@dataclass(frozen=True)
class SimPlan:
    """Everything the node starts, decided from its parameters before anything runs."""

    pacing: Pacing
    priority_boost: int                 # niceness steps to raise the world's process by (0: off)
    vehicles: Tuple[VehicleSpec, ...]
    dongles: int
    mocap: MocapConfig
    vrpn_on: bool
    vrpn_port: Optional[int]            # None: 3883 when free
    start_faults: Tuple[Tuple[str, Dict[str, Any]], ...]
    address: str                        # host:port of the world server, as given
    seed: Optional[int]
    dongle_model: str
    usb: Tuple[str, ...]                # vehicles also on a USB cable: usb://0, usb://1, ... in this order
    publish_clock: bool

    @property
    def names(self) -> List[str]:
        return [v.name for v in self.vehicles]

    @property
    def vicon_frames(self) -> Dict[str, str]:
        """Vehicle name -> its own vicon tf frame, for those that set ``frame``."""
        return {v.name: v.frame for v in self.vehicles if v.frame}


def plan_from_params(params: Mapping[str, Any], load_swarm: Optional[SwarmLoader] = None) -> SimPlan:
    """The node's start-up plan; ``SimConfigError`` (or the pacing's, URI's or swarm file's own error)
    names the wrong parameter. ``load_swarm`` reads ``~swarm_file`` when that is set."""
    pacing = parse_pacing(params.get("speed", 1.0))
    boost = int(_number("~priority_boost", params.get("priority_boost", DEFAULT_PRIORITY_BOOST)))
    if params.get("swarm_file"):
        if load_swarm is None:
            raise SimConfigError("~swarm_file is set but this node cannot read swarm files")
        vehicles, need = load_swarm(str(params["swarm_file"]))
        dongles = dongles_needed(vehicles, params.get("dongles", need))
    else:
        vehicles = vehicles_from_params(params)
        dongles = dongles_needed(vehicles, params.get("dongles"))
    vrpn_on, vrpn_port = vrpn_port_from_params(params)
    seed = params.get("seed")
    return SimPlan(
        pacing=pacing, priority_boost=boost, vehicles=tuple(vehicles), dongles=dongles,
        mocap=mocap_from_params(params), vrpn_on=vrpn_on, vrpn_port=vrpn_port,
        start_faults=tuple(start_faults_from_params(params, dongles)),
        address=str(params.get("address", DEFAULT_ADDRESS)), seed=None if seed is None else int(seed),
        dongle_model=str(params.get("dongle_model", "PA")),
        usb=tuple(str(params.get("usb", "")).replace(",", " ").split()),
        publish_clock=bool(params.get("publish_clock", True)))
