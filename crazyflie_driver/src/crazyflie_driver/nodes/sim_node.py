"""``crazyflie_sim_node``: the simulated world inside a ROS node, playing the motion-capture system too.

It runs the world server (``sim.air.server.WorldServer``) that fake Crazyradios of other processes
connect to through ``CRAZYFLIE_SIM_ADDRESS`` (``~address``, default 127.0.0.1:19840), and publishes
each vehicle's pose as the motion-capture bridges of the original stack did:

* ``~mocap: vicon``: tf ``world -> vicon/<name>/<name>`` and the topic ``/vicon/<name>/<name>``
  (geometry_msgs/TransformStamped), as vicon_bridge does;
* ``~mocap: vrpn``: ``/vrpn_client_node/<name>/pose`` (geometry_msgs/PoseStamped, frame ``world``)
  and tf ``world -> <name>``, as vrpn_client_ros does;
* ``both`` or ``none``.

Private parameters: ``vehicles`` (list of ``{uri, name, x, y, z}``; ``position: [x, y, z]``,
``yaw``, ``firmware``, ``platform`` (``cf2`` or ``brushless``: armed before its motors spin), ``decks`` (e.g.
``[bcFlow2, bcLighthouse4]``) and ``frame``
also accepted: ``frame`` is the tf frame the vicon style publishes
that vehicle's pose under, as a Vicon room whose body is named that way would, e.g. the
``frame:=crazyflie1`` of a launch file; also as a YAML string holding that list, or the path of a
YAML file, which is what ``sim.launch``'s ``vehicles`` argument passes) or ``uri`` + ``name`` for one vehicle;
or ``swarm_file``, the path of the swarm file crazyflie_server reads (``server.swarm.config``): every
Crazyflie at its ``initialPosition`` on the URI the server derives from its id and channel (one
dongle per channel), named after its tf_prefix, as the server's motion capture looks for it;
``dongles``
(simulated Crazyradios, default: enough for the URIs); ``speed`` (1.0: world seconds per wall second;
``auto``: real time, slower while the host lags; ``sim.world.pacing``); ``seed``; ``mocap``
(vicon); ``mocap_rate`` (100 Hz); ``mocap_noise`` (position noise, m, standard deviation);
``mocap_latency`` (s); ``mocap_dropout`` (fraction of frames lost); ``world_frame`` (world);
``publish_clock`` (true: publish the world time on /clock every CLOCK_PERIOD_S of world time, from
the world's stepping thread, from its first tick on; the node sets no global parameter: sim.launch
sets /use_sim_time, so that ROS time is world time); ``vrpn`` (false: also serve the
motion capture as a VRPN server on loopback, one tracker per vehicle named after it, as a
motion-capture PC would) and ``vrpn_port`` (default 3883 when free, else one the system picks;
0 = any; the node logs which); ``priority_boost`` (5 niceness steps the world's process is raised
by where the system allows it, so host nodes on a busy machine cannot starve the world; 0: off;
``sim.priority``).

The frames come from the world's own motion-capture model (``sim.world.mocap.MocapModel``), sampled on
world time; a vehicle added to the world at run time is reported too.

Faults (docs/simulation.md, "Fault injection"): ``packet_loss`` and ``ack_loss`` (fraction 0..1 of
round trips, every dongle), ``latency_ms`` (every dongle) and ``faults`` (fault commands separated by
';', e.g. ``"unplug 1; battery crazyflie1 3.4"``) are applied at start; the service ``~fault``
(crazyflie_driver/InjectFault) takes one command at run time, in the words of
``rosrun crazyflie_tools fault``, and calls the same world-server operation the tool does. The faults
in force are listed on /diagnostics.

Service ``~<name>/set_mocap`` (std_srvs/SetBool) per vehicle: ``data: false`` makes the
motion-capture system stop reporting that vehicle (an occluded or lost body), ``true`` brings it
back. Tests use it to check what the controller does without a pose.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import UriError
from crazyflie_driver.sim.air.faults import MAX_MOCAP_LATENCY_S, MAX_MOCAP_NOISE_M
from crazyflie_driver.sim.firmware.memory_port import DECKS
from crazyflie_driver.sim.priority import DEFAULT_PRIORITY_BOOST, raise_priority
from crazyflie_driver.sim.world.pacing import Pacing, PacingError, parse_pacing
from crazyflie_driver.sim.world.stabilizer import PLATFORM_CF2, PLATFORMS

MOCAP_STYLES = ("vicon", "vrpn", "both", "none")
CLOCK_PERIOD_S = 0.002
"""World seconds [s] between two /clock messages (500 Hz at real time): a host loop at 100 Hz wakes
within 2 ms of world time of its deadline. Every 1 ms cost twice as much (measured: the sim node
+33 % of a core against +12 %, each subscribing node +3 % against +1.3 %; docs/simulation.md)."""


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


def vehicles_from_params(params: Mapping[str, Any]) -> List[VehicleSpec]:
    """``~vehicles`` (or ``~uri``/``~name``) checked; names must be valid ROS names, URIs unique."""
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
    out: List[VehicleSpec] = []
    seen_names, seen_uris = set(), set()
    for i, item in enumerate(raw):
        where = "~vehicles[%d]" % i
        if not isinstance(item, dict) or "uri" not in item:
            raise SimConfigError("%s needs at least a 'uri' (got %r)" % (where, item))
        unknown = set(item) - {"uri", "name", "x", "y", "z", "position", "yaw", "firmware", "frame", "platform",
                                 "decks"}
        if unknown:
            raise SimConfigError("%s has unknown keys %s" % (where, ", ".join(sorted(unknown))))
        try:
            uri = str(parse_uri(str(item["uri"])))
        except UriError as e:
            raise SimConfigError("%s: %s" % (where, e)) from None
        name = str(item.get("name") or "crazyflie%d" % (i + 1))
        if not (name[0].isalpha() and all(c.isalnum() or c == "_" for c in name)):
            raise SimConfigError("%s: name %r is not a valid ROS name (letters, digits, '_')" % (where, name))
        if "position" in item:
            pos = item["position"]
            if not isinstance(pos, (list, tuple)) or len(pos) != 3:
                raise SimConfigError("%s: position must be [x, y, z], got %r" % (where, pos))
            position = tuple(_number(where + ".position", v) for v in pos)
        else:
            position = tuple(_number("%s.%s" % (where, k), item.get(k, 0.0)) for k in ("x", "y", "z"))
        if name in seen_names:
            raise SimConfigError("%s: name %r is used twice" % (where, name))
        if uri in seen_uris:
            raise SimConfigError("%s: URI %s is used twice" % (where, uri))
        seen_names.add(name)
        seen_uris.add(uri)
        platform = item.get("platform", PLATFORM_CF2)
        if platform not in PLATFORMS:
            raise SimConfigError("%s: platform must be one of %s (brushless: armed before its motors spin), got %r"
                                 % (where, ", ".join(PLATFORMS), platform))
        decks = item.get("decks", [])
        if not isinstance(decks, list) or any(d not in DECKS for d in decks):
            raise SimConfigError("%s: decks must be a list of deck names out of %s, got %r"
                                 % (where, ", ".join(sorted(DECKS)), decks))
        out.append(VehicleSpec(uri, name, position, _number(where + ".yaw", item.get("yaw", 0.0)),
                               str(item.get("firmware", "current")), _frame(where, item.get("frame")), platform,
                               tuple(decks)))
    return out


def vehicles_from_swarm_file(path: str) -> Tuple[List[VehicleSpec], int]:
    """The vehicles of a swarm file and the dongles they need (``SwarmConfigError`` names the fault)."""
    from crazyflie_driver.server.swarm.config import load_swarm_file

    config = load_swarm_file(path)
    out = []
    for cf in config.crazyflies:
        if "/" in cf.name:
            raise SimConfigError("%s: tf_prefix %r of id %d has a '/': the simulated body (and its motion-capture "
                                 "name) must be one ROS name" % (path, cf.name, cf.id))
        out.append(VehicleSpec(cf.uri, cf.name, tuple(cf.initial_position)))
    return out, config.dongles_needed


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
    """The world's motion-capture model (``sim.world.mocap.MocapModel``) with the node's settings:
    position noise ``config.noise`` (m), no orientation noise, ``latency`` (s), ``dropout``."""
    from crazyflie_driver.sim.world.mocap import MocapModel

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


# ------------------------------------------------------------------------------------------------
# ROS side


class MocapPublisher:
    """Publishes mocap frames in vicon_bridge and/or vrpn_client_ros style.

    tf: one ``tf2_msgs/TFMessage`` on ``/tf`` per delivery, holding every body's newest transform,
    packed straight into wire bytes (``nodes.tf_wire``). A child frame never gets two transforms with
    the same stamp (``StampGuard``). Per-body topics are published only while someone subscribes.
    """

    def __init__(self, config: MocapConfig, names: Sequence[str],
                 vicon_frames: Optional[Dict[str, str]] = None, world_stamps: bool = False) -> None:
        import rospy
        from geometry_msgs.msg import PoseStamped, TransformStamped
        from tf2_msgs.msg import TFMessage

        from crazyflie_driver.nodes.tf_wire import packed_message_types

        self._rospy, self._PoseStamped, self._TransformStamped = rospy, PoseStamped, TransformStamped
        self._PackedTF, self._PackedTransform = packed_message_types()
        self.config = config
        self.vicon = config.style in ("vicon", "both")
        self.vrpn = config.style in ("vrpn", "both")
        # what tf2_ros.TransformBroadcaster does: a TFMessage publisher on /tf
        self._tf = rospy.Publisher("/tf", TFMessage, queue_size=100) if (self.vicon or self.vrpn) else None
        self._bodies: Dict[str, Any] = {}
        self.guard = StampGuard()
        self.vicon_frames = dict(vicon_frames or {})   # name -> tf child frame, where not vicon/<name>/<name>
        # under /use_sim_time ROS time is world time: stamp from the world itself, not from this
        # node's copy of /clock (which trails it by a delivery)
        self.world_stamps = world_stamps
        for n in names:
            self._body(n)

    def _body(self, name: str):
        """Per-body wires and publishers; made on first sight for one added at run time."""
        body = self._bodies.get(name)
        if body is None:
            from crazyflie_driver.nodes.tf_wire import TransformWire

            rospy, parent = self._rospy, self.config.world_frame
            body = _MocapBody(
                TransformWire(parent, self.vicon_frames.get(name) or "vicon/%s/%s" % (name, name))
                if self.vicon else None,
                rospy.Publisher("/vicon/%s/%s" % (name, name), self._TransformStamped, queue_size=10)
                if self.vicon else None,
                TransformWire(parent, name) if self.vrpn else None,
                rospy.Publisher("/vrpn_client_node/%s/pose" % name, self._PoseStamped, queue_size=1)
                if self.vrpn else None)
            self._bodies[name] = body
        return body

    def publish(self, frames: Sequence[Any], world_time: float) -> int:
        """frames: ``sim.world.mocap.MocapFrame`` s delivered since the last call; ``world_time`` now.

        vicon style stamps each frame with its capture time (ROS now minus its age in world time);
        vrpn style with the time of receipt, as vrpn_client_ros does. Returns the transforms sent.
        """
        if not frames or self._tf is None:
            return 0
        now_ns = int(round(world_time * 1e9)) if self.world_stamps else self._rospy.Time.now().to_nsec()
        parts: List[bytes] = []
        guard = self.guard
        for f in newest_per_body(frames):
            body = self._body(f.name)
            position, quaternion = f.position, f.quaternion
            if body.vicon is not None:
                stamp = now_ns - int(round(max(0.0, world_time - f.stamp) * 1e9))
                if guard.admit(body.vicon.child, stamp):
                    packed = body.vicon.pack(stamp, position, quaternion)
                    parts.append(packed)
                    if body.vicon_pub.get_num_connections() > 0:
                        body.vicon_pub.publish(self._PackedTransform(packed))
            if body.vrpn is not None and guard.admit(body.vrpn.child, now_ns):
                parts.append(body.vrpn.pack(now_ns, position, quaternion))
                if body.vrpn_pub.get_num_connections() > 0:     # vrpn_client_ros: only when subscribed
                    p = self._PoseStamped()
                    p.header.stamp, p.header.frame_id = self._rospy.Time(*divmod(now_ns, 1000000000)), \
                        self.config.world_frame
                    p.pose.position.x, p.pose.position.y, p.pose.position.z = (float(v) for v in position)
                    (p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z,
                     p.pose.orientation.w) = (float(v) for v in quaternion)
                    body.vrpn_pub.publish(p)
        if parts:
            self._tf.publish(self._PackedTF(parts))
        return len(parts)


@dataclass
class _MocapBody:
    vicon: Any          # TransformWire world -> vicon/<name>/<name>, or None
    vicon_pub: Any
    vrpn: Any           # TransformWire world -> <name>, or None
    vrpn_pub: Any


def _advertise_mocap_switches(source: Any, names: Sequence[str]) -> list:
    """One ``~<name>/set_mocap`` (std_srvs/SetBool) service per vehicle."""
    import rospy
    from std_srvs.srv import SetBool, SetBoolResponse

    def handler(name: str):
        def on_call(req) -> SetBoolResponse:
            source.set_visible(name, bool(req.data))
            rospy.loginfo("crazyflie_sim: motion capture %s %s", "reports" if req.data else "no longer reports",
                          name)
            return SetBoolResponse(success=True, message="%s %s" % (name, "visible" if req.data else "hidden"))
        return on_call
    return [rospy.Service("~%s/set_mocap" % n, SetBool, handler(n)) for n in names]


def _advertise_fault_service(control: Any) -> Any:
    """``~fault`` (crazyflie_driver/InjectFault): one fault command, applied by ``control(op, args)``."""
    import rospy

    from crazyflie_driver.sim.air import faults
    from crazyflie_driver.srv import InjectFault, InjectFaultResponse

    def on_call(req) -> InjectFaultResponse:
        try:
            op, args = faults.parse_command(req.command)
            answer = faults.describe_result(op, args, control(op, args))
        except (ValueError, KeyError) as e:       # bad words or a refused value: nothing changed
            text = str(e.args[0]) if isinstance(e, KeyError) and e.args else str(e)
            rospy.logwarn("crazyflie_sim: fault %r refused: %s", req.command, text)
            return InjectFaultResponse(success=False, message=text)
        if op not in ("faults",):
            rospy.loginfo("crazyflie_sim: fault %r: %s", req.command, answer.replace("\n", "; "))
        return InjectFaultResponse(success=True, message=answer)
    return rospy.Service("~fault", InjectFault, on_call)


def _start_diagnostics(world: Any, address: str, active_faults: Any = None, pacing: Optional[Pacing] = None,
                       pacer: Any = None):
    """Publishes the world's real-time status on /diagnostics every second; warns (throttled) when behind."""
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from crazyflie_driver.nodes.ros_signals import shutting_down
    from crazyflie_driver.sim.world.world import BEHIND_FACTOR, BEHIND_WARNING_PERIOD_S

    pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
    name = "%s: simulated world (%s)" % (rospy.get_name(), address)

    def on_timer(_event) -> None:
        st = world_status(world.realtime_factor, world.speed, len(world.vehicles()), world.ticks_behind,
                          world.overruns, float(world.time), BEHIND_FACTOR, pacing,
                          pacer.lag_wall_s if pacer is not None and pacer.samples else None)
        if st.level:
            rospy.logwarn_throttle(BEHIND_WARNING_PERIOD_S, "crazyflie_sim: the world runs %s" % st.message)
        msg = DiagnosticArray()
        msg.header.stamp = rospy.Time.now()
        msg.status = [DiagnosticStatus(level=st.level, name=name, message=st.message, hardware_id="crazyflie_sim",
                                       values=[KeyValue(k, v) for k, v in st.values])]
        if active_faults is not None:
            ft = faults_status(active_faults())
            msg.status.append(DiagnosticStatus(level=ft.level, name="%s: injected faults" % rospy.get_name(),
                                               message=ft.message, hardware_id="crazyflie_sim",
                                               values=[KeyValue(k, v) for k, v in ft.values]))
        try:
            pub.publish(msg)
        except Exception as e:
            if not shutting_down():
                rospy.logwarn_throttle(10.0, "crazyflie_sim: diagnostics failed: %s" % e)
    return rospy.Timer(rospy.Duration(1.0), on_timer)


def _publish_clock(world: Any, pub: Any, clock_type: Any) -> None:
    """World time on /clock: now, then every CLOCK_PERIOD_S of world time from the stepping thread
    (the message is stamped with the tick's own time, so /clock is exactly the world's)."""
    import rospy

    from crazyflie_driver.nodes.ros_signals import shutting_down

    def on_tick(now: float) -> None:
        try:
            pub.publish(clock_type(clock=rospy.Time(*divmod(int(round(now * 1e9)), 1000000000))))
        except Exception as e:     # a publishing hiccup must not stop the world
            if not shutting_down():
                rospy.logwarn_throttle(5.0, "crazyflie_sim: /clock failed: %s" % e)

    on_tick(float(world.time))
    world.add_tick_listener(on_tick, CLOCK_PERIOD_S)


def _private_params() -> Dict[str, Any]:
    import rospy
    prefix = rospy.get_name().rstrip("/") + "/"
    return {n[len(prefix):]: rospy.get_param(n) for n in rospy.get_param_names() if n.startswith(prefix)}


def main() -> None:
    import rospy
    from rosgraph_msgs.msg import Clock

    from crazyflie_driver.errors import CrazyflieError
    from crazyflie_driver.nodes.ros_signals import init_node, shutting_down
    from crazyflie_driver.sim.air.faults import describe_result as faults_text
    from crazyflie_driver.sim.air.medium import parse_address
    from crazyflie_driver.sim.air.server import WorldServer
    from crazyflie_driver.sim.world.pacing import start_pacing
    from crazyflie_driver.sim.world.world import World

    init_node("crazyflie_sim")
    params = _private_params()
    # /clock first: nodes under /use_sim_time wait for it (nodes.ros_clock) before they time anything
    # queue_size 1: a subscriber that fell behind gets the newest time next, not a backlog of old ones
    # (100 queued /clock messages held a late node's ROS time up to 0.2 s of world time behind)
    clock_pub = rospy.Publisher("/clock", Clock, queue_size=1) if params.get("publish_clock", True) else None
    try:
        pacing = parse_pacing(params.get("speed", 1.0))
        boost = int(_number("~priority_boost", params.get("priority_boost", DEFAULT_PRIORITY_BOOST)))
        refused = raise_priority(boost)
        if refused is not None:
            rospy.loginfo("crazyflie_sim: runs at normal priority: %s; on a busy machine the world may fall "
                          "behind real time", refused)
        if params.get("swarm_file"):
            vehicles, need = vehicles_from_swarm_file(str(params["swarm_file"]))
            dongles = dongles_needed(vehicles, params.get("dongles", need))
        else:
            vehicles = vehicles_from_params(params)
            dongles = dongles_needed(vehicles, params.get("dongles"))
        mocap = mocap_from_params(params)
        vrpn_on, vrpn_port = vrpn_port_from_params(params)
        start_faults = start_faults_from_params(params, dongles)
        host, port = parse_address(str(params.get("address", "127.0.0.1:19840")))
        seed = params.get("seed")
        world = World(speed=pacing.target, seed=None if seed is None else int(seed))
        server = WorldServer(world, dongles=dongles, host=host, port=port, seed=None if seed is None else int(seed),
                             dongle_model=str(params.get("dongle_model", "PA")))
        for v in vehicles:
            server.add_crazyflie(v.uri, v.name, v.position, v.firmware, v.yaw, platform=v.platform, decks=v.decks)
        for name in str(params.get("usb", "")).replace(",", " ").split():
            server.plug_usb(name)          # also on a USB cable: usb://0, usb://1, ... in this order
        server.start()
    except (SimConfigError, PacingError, ValueError, CrazyflieError) as e:
        rospy.logfatal("crazyflie_sim: %s", e)
        raise SystemExit(1) from None
    if clock_pub is not None:
        _publish_clock(world, clock_pub, Clock)
    world.start()
    pacer = start_pacing(world, pacing)
    rospy.loginfo("crazyflie_sim: world served on %s (%d dongle%s, mocap %s at %.0f Hz, speed %s%s): %s",
                  server.address, dongles, "" if dongles == 1 else "s", mocap.style, mocap.rate, pacing.describe(),
                  ", /clock" if clock_pub is not None else "",
                  ", ".join("%s on %s" % (v.name, v.uri) for v in vehicles))

    names = [v.name for v in vehicles]
    model = mocap_model(world, mocap, None if seed is None else int(seed))
    publisher = MocapPublisher(mocap, names, {v.name: v.frame for v in vehicles if v.frame},
                               world_stamps=clock_pub is not None and bool(rospy.get_param("/use_sim_time", False)))
    _advertise_mocap_switches(model, names)
    server.mocap = model
    try:
        for op, args in start_faults:
            rospy.loginfo("crazyflie_sim: injected at start: %s", faults_text(op, args, server.control(op, args)))
    except (ValueError, KeyError) as e:      # e.g. a vehicle name in ~faults that the world has not
        rospy.logfatal("crazyflie_sim: ~faults: %s", e)
        server.stop()
        world.stop()
        raise SystemExit(1) from None
    _advertise_fault_service(server.control)
    stop = threading.Event()
    delivered: List[Any] = []
    delivered_lock = threading.Lock()
    frames_ready = threading.Event()

    def on_frames(frames) -> None:      # the world's stepping thread: hand over, publish elsewhere
        with delivered_lock:
            delivered.extend(frames)
        frames_ready.set()

    vrpn = None
    if vrpn_on:
        from crazyflie_driver.sim.world.mocap_vrpn import WorldVrpnServer
        try:
            vrpn = WorldVrpnServer(world, model, port=vrpn_port)
            vrpn.start()
        except OSError as e:
            rospy.logfatal("crazyflie_sim: cannot serve VRPN on port %s: %s (choose another with ~vrpn_port, "
                           "0 for any)", vrpn_port, e.strerror or e)
            server.stop()
            world.stop()
            raise SystemExit(1) from None
        rospy.loginfo("crazyflie_sim: motion capture served as VRPN on 127.0.0.1:%d (trackers %s)", vrpn.port,
                      ", ".join(names))
    if mocap.style != "none":
        model.add_listener(on_frames)
    if mocap.style != "none" or vrpn is not None:
        model.attach()

    def mocap_loop() -> None:
        period = 1.0 / mocap.rate
        while not stop.is_set() and not rospy.is_shutdown():
            frames_ready.wait(period)
            frames_ready.clear()
            with delivered_lock:
                frames = delivered[:]
                del delivered[:]
            try:
                publisher.publish(frames, float(world.time))
            except Exception as e:   # a publishing hiccup must not stop the world
                if not shutting_down():   # (at shutdown the topics close under this thread)
                    rospy.logwarn_throttle(5.0, "crazyflie_sim: mocap frame failed: %s" % e)

    thread = threading.Thread(target=mocap_loop, name="mocap", daemon=True)
    thread.start()
    diagnostics = _start_diagnostics(world, server.address, server.active_faults, pacing, pacer)

    def shutdown() -> None:
        stop.set()
        diagnostics.shutdown()
        if pacer is not None:
            pacer.stop()
        if vrpn is not None:
            vrpn.stop()
        server.stop()
        world.stop()
    rospy.on_shutdown(shutdown)
    rospy.spin()
