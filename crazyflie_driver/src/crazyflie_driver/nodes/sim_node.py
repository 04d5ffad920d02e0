"""``crazyflie_sim_node``: the simulated world inside a ROS node, playing the motion-capture system too.

It runs the world server (``sim.server.WorldServer``) that fake Crazyradios of other processes
connect to through ``CRAZYFLIE_SIM_ADDRESS`` (``~address``, default 127.0.0.1:19840), and publishes
each vehicle's pose as the motion-capture bridges of the original stack did:

* ``~mocap: vicon``: tf ``world -> vicon/<name>/<name>`` and the topic ``/vicon/<name>/<name>``
  (geometry_msgs/TransformStamped), as vicon_bridge does;
* ``~mocap: vrpn``: ``/vrpn_client_node/<name>/pose`` (geometry_msgs/PoseStamped, frame ``world``)
  and tf ``world -> <name>``, as vrpn_client_ros does;
* ``both`` or ``none``.

Private parameters: ``vehicles`` (list of ``{uri, name, x, y, z}``; ``position: [x, y, z]``,
``yaw`` and ``firmware`` also accepted; also as a YAML string holding that list, or the path of a
YAML file, which is what ``sim.launch``'s ``vehicles`` argument passes) or ``uri`` + ``name`` for one vehicle;
``dongles``
(simulated Crazyradios, default: enough for the URIs); ``speed`` (1.0); ``seed``; ``mocap``
(vicon); ``mocap_rate`` (100 Hz); ``mocap_noise`` (position noise, m, standard deviation);
``mocap_latency`` (s); ``mocap_dropout`` (fraction of frames lost); ``world_frame`` (world);
``publish_clock`` (false: publish the world time on /clock; the node sets no global parameter,
so set /use_sim_time yourself if you want ROS time to follow it).

The frames come from the world's own motion-capture model (``sim.mocap.MocapModel``), sampled on
world time; a vehicle added to the world at run time is reported too.

Service ``~<name>/set_mocap`` (std_srvs/SetBool) per vehicle: ``data: false`` makes the
motion-capture system stop reporting that vehicle (an occluded or lost body), ``true`` brings it
back. Tests use it to check what the controller does without a pose.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Sequence

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import UriError

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
        unknown = set(item) - {"uri", "name", "x", "y", "z", "position", "yaw", "firmware"}
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
        out.append(VehicleSpec(uri, name, position, _number(where + ".yaw", item.get("yaw", 0.0)),
                               str(item.get("firmware", "current"))))
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
    if noise < 0 or latency < 0 or not 0.0 <= dropout < 1.0:
        raise SimConfigError("~mocap_noise and ~mocap_latency must be >= 0 and ~mocap_dropout in [0, 1)")
    frame = str(params.get("world_frame", "world")).strip("/") or "world"
    return MocapConfig(style, rate, noise, latency, dropout, frame)


def dongles_needed(vehicles: Sequence[VehicleSpec], requested: Optional[int]) -> int:
    need = max(parse_uri(v.uri).index for v in vehicles) + 1
    if requested is None:
        return need
    if int(requested) < need:
        raise SimConfigError("~dongles is %d but a vehicle uses radio index %d" % (requested, need - 1))
    return int(requested)


def mocap_model(world: Any, config: MocapConfig, seed: Optional[int] = None):
    """The world's motion-capture model (``sim.mocap.MocapModel``) with the node's settings:
    position noise ``config.noise`` (m), no orientation noise, ``latency`` (s), ``dropout``."""
    from crazyflie_driver.sim.world.mocap import MocapModel

    return MocapModel(world, rate=config.rate, position_noise=config.noise, orientation_noise=0.0,
                      latency=config.latency, dropout=config.dropout, seed=seed)


# ------------------------------------------------------------------------------------------------
# ROS side


class MocapPublisher:
    """Publishes mocap frames in vicon_bridge and/or vrpn_client_ros style."""

    def __init__(self, config: MocapConfig, names: Sequence[str]) -> None:
        import rospy
        import tf2_ros
        from geometry_msgs.msg import PoseStamped, TransformStamped

        self._rospy, self._PoseStamped, self._TransformStamped = rospy, PoseStamped, TransformStamped
        self.config = config
        self.vicon = config.style in ("vicon", "both")
        self.vrpn = config.style in ("vrpn", "both")
        self._tf = tf2_ros.TransformBroadcaster() if (self.vicon or self.vrpn) else None
        self._vicon_pubs: Dict[str, Any] = {}
        self._vrpn_pubs: Dict[str, Any] = {}
        for n in names:
            self._publishers(n)

    def _publishers(self, name: str):
        """(vicon, vrpn) publishers of a body; made on first sight for one added at run time."""
        rospy = self._rospy
        if self.vicon and name not in self._vicon_pubs:
            self._vicon_pubs[name] = rospy.Publisher("/vicon/%s/%s" % (name, name), self._TransformStamped,
                                                     queue_size=10)
        if self.vrpn and name not in self._vrpn_pubs:
            self._vrpn_pubs[name] = rospy.Publisher("/vrpn_client_node/%s/pose" % name, self._PoseStamped,
                                                    queue_size=1)
        return self._vicon_pubs.get(name), self._vrpn_pubs.get(name)

    def _transform(self, stamp, child: str, position, quaternion):
        t = self._TransformStamped()
        t.header.stamp = stamp
        t.header.frame_id = self.config.world_frame
        t.child_frame_id = child
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = (float(v) for v in position)
        (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
         t.transform.rotation.w) = (float(v) for v in quaternion)
        return t

    def publish(self, frames: Sequence[Any], world_time: float) -> None:
        """frames: ``sim.mocap.MocapFrame`` s delivered since the last call; ``world_time`` now.

        vicon style stamps each frame with its capture time (ROS now minus its age in world time).
        """
        if not frames or self._tf is None:
            return
        now = self._rospy.Time.now()
        transforms = []
        for f in frames:
            name, position, quaternion = f.name, f.position, f.quaternion
            vicon_pub, vrpn_pub = self._publishers(name)
            stamp = now - self._rospy.Duration.from_sec(max(0.0, world_time - f.stamp))
            if self.vicon:
                t = self._transform(stamp, "vicon/%s/%s" % (name, name), position, quaternion)
                transforms.append(t)
                vicon_pub.publish(t)
            if self.vrpn:
                # vrpn_client_ros stamps with the time of receipt and publishes only when subscribed
                transforms.append(self._transform(now, name, position, quaternion))
                pub = vrpn_pub
                if pub.get_num_connections() > 0:
                    p = self._PoseStamped()
                    p.header.stamp, p.header.frame_id = now, self.config.world_frame
                    p.pose.position.x, p.pose.position.y, p.pose.position.z = (float(v) for v in position)
                    (p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z,
                     p.pose.orientation.w) = (float(v) for v in quaternion)
                    pub.publish(p)
        self._tf.sendTransform(transforms)


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


def _private_params() -> Dict[str, Any]:
    import rospy
    prefix = rospy.get_name().rstrip("/") + "/"
    return {n[len(prefix):]: rospy.get_param(n) for n in rospy.get_param_names() if n.startswith(prefix)}


def main() -> None:
    import rospy
    from rosgraph_msgs.msg import Clock

    from crazyflie_driver.errors import CrazyflieError
    from crazyflie_driver.sim.air.medium import parse_address
    from crazyflie_driver.sim.air.server import WorldServer
    from crazyflie_driver.sim.world.world import World
    from crazyflie_driver.nodes.ros_signals import init_node, shutting_down

    init_node("crazyflie_sim")
    params = _private_params()
    try:
        vehicles = vehicles_from_params(params)
        mocap = mocap_from_params(params)
        dongles = dongles_needed(vehicles, params.get("dongles"))
        host, port = parse_address(str(params.get("address", "127.0.0.1:19840")))
        speed = _number("~speed", params.get("speed", 1.0))
        seed = params.get("seed")
        world = World(speed=speed, seed=None if seed is None else int(seed))
        server = WorldServer(world, dongles=dongles, host=host, port=port, seed=None if seed is None else int(seed))
        for v in vehicles:
            server.add_crazyflie(v.uri, v.name, v.position, v.firmware, v.yaw)
        server.start()
    except (SimConfigError, ValueError, CrazyflieError) as e:
        rospy.logfatal("crazyflie_sim: %s", e)
        raise SystemExit(1)
    world.start()
    rospy.loginfo("crazyflie_sim: world served on %s (%d dongle%s, mocap %s at %.0f Hz): %s", server.address,
                  dongles, "" if dongles == 1 else "s", mocap.style, mocap.rate,
                  ", ".join("%s on %s" % (v.name, v.uri) for v in vehicles))

    names = [v.name for v in vehicles]
    model = mocap_model(world, mocap, None if seed is None else int(seed))
    publisher = MocapPublisher(mocap, names)
    _advertise_mocap_switches(model, names)
    clock_pub = rospy.Publisher("/clock", Clock, queue_size=10) if params.get("publish_clock", False) else None
    stop = threading.Event()
    delivered: List[Any] = []
    delivered_lock = threading.Lock()
    frames_ready = threading.Event()

    def on_frames(frames) -> None:      # the world's stepping thread: hand over, publish elsewhere
        with delivered_lock:
            delivered.extend(frames)
        frames_ready.set()

    if mocap.style != "none":
        model.add_listener(on_frames)
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
                if clock_pub is not None:
                    clock_pub.publish(Clock(clock=rospy.Time.from_sec(float(world.time))))
            except Exception as e:   # a publishing hiccup must not stop the world
                if not shutting_down():   # (at shutdown the topics close under this thread)
                    rospy.logwarn_throttle(5.0, "crazyflie_sim: mocap frame failed: %s" % e)

    thread = threading.Thread(target=mocap_loop, name="mocap", daemon=True)
    thread.start()

    def shutdown() -> None:
        stop.set()
        server.stop()
        world.stop()
    rospy.on_shutdown(shutdown)
    rospy.spin()
