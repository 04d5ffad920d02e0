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
``auto``: real time, slower while the host lags; ``sim.room.pacing``); ``seed``; ``mocap``
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

The frames come from the world's own motion-capture model (``sim.room.mocap.MocapModel``), sampled on
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

import threading
from dataclasses import dataclass
from typing import Any, Dict, List, NoReturn, Optional, Sequence, Tuple

from crazyflie_driver.sim.node_config import (  # noqa: F401  (the node's parameters; also imported from here)
    MOCAP_STYLES,
    MocapConfig,
    SimConfigError,
    SimPlan,
    StampGuard,
    VehicleSpec,
    WorldStatus,
    dongles_needed,
    faults_status,
    mocap_from_params,
    mocap_model,
    newest_per_body,
    plan_from_params,
    start_faults_from_params,
    vehicles_from_params,
    vehicles_from_swarm,
    vrpn_port_from_params,
    world_status,
)
from crazyflie_driver.sim.priority import raise_priority
from crazyflie_driver.sim.room.pacing import Pacing, PacingError

CLOCK_PERIOD_S = 0.002
"""World seconds [s] between two /clock messages (500 Hz at real time): a host loop at 100 Hz wakes
within 2 ms of world time of its deadline. Every 1 ms cost twice as much (measured: the sim node
+33 % of a core against +12 %, each subscribing node +3 % against +1.3 %; docs/simulation.md)."""

def vehicles_from_swarm_file(path: str) -> Tuple[List[VehicleSpec], int]:
    """The vehicles of a swarm file and the dongles they need (``SwarmConfigError`` names the fault)."""
    from crazyflie_driver.server.swarm.config import load_swarm_file

    config = load_swarm_file(path)
    return vehicles_from_swarm(path, config.crazyflies), config.dongles_needed


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
        """frames: ``sim.room.mocap.MocapFrame`` s delivered since the last call; ``world_time`` now.

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
    from crazyflie_driver.sim.room.world import BEHIND_FACTOR, BEHIND_WARNING_PERIOD_S

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

def _start_world(plan: SimPlan) -> Tuple[Any, Any]:
    """The world and its server with the plan's vehicles, serving; raises on a refused value."""
    from crazyflie_driver.sim.air.medium import parse_address
    from crazyflie_driver.sim.room.world import World
    from crazyflie_driver.sim.world_server import WorldServer

    host, port = parse_address(plan.address)
    world = World(speed=plan.pacing.target, seed=plan.seed)
    server = WorldServer(world, dongles=plan.dongles, host=host, port=port, seed=plan.seed,
                         dongle_model=plan.dongle_model)
    for v in plan.vehicles:
        server.add_crazyflie(v.uri, v.name, v.position, v.firmware, v.yaw, platform=v.platform, decks=v.decks)
    for name in plan.usb:
        server.plug_usb(name)          # also on a USB cable: usb://0, usb://1, ... in this order
    server.start()
    return world, server


def _plan_and_start(params: Dict[str, Any]) -> Tuple[SimPlan, Any, Any]:
    """The plan from the parameters, the process priority, and the world serving; exits on bad input."""
    import rospy

    from crazyflie_driver.errors import CrazyflieError

    try:
        plan = plan_from_params(params, vehicles_from_swarm_file)
        refused = raise_priority(plan.priority_boost)
        if refused is not None:
            rospy.loginfo("crazyflie_sim: runs at normal priority: %s; on a busy machine the world may fall "
                          "behind real time", refused)
        world, server = _start_world(plan)
    except (SimConfigError, PacingError, ValueError, CrazyflieError) as e:
        rospy.logfatal("crazyflie_sim: %s", e)
        raise SystemExit(1) from None
    return plan, world, server


def _fail(server: Any, world: Any) -> NoReturn:
    """Stops what started and leaves with status 1 (the fatal line is already logged)."""
    server.stop()
    world.stop()
    raise SystemExit(1) from None


def _inject_start_faults(plan: SimPlan, server: Any, world: Any) -> None:
    import rospy

    from crazyflie_driver.sim.air.faults import describe_result as faults_text

    try:
        for op, args in plan.start_faults:
            rospy.loginfo("crazyflie_sim: injected at start: %s", faults_text(op, args, server.control(op, args)))
    except (ValueError, KeyError) as e:      # e.g. a vehicle name in ~faults that the world has not
        rospy.logfatal("crazyflie_sim: ~faults: %s", e)
        _fail(server, world)


def _start_vrpn(plan: SimPlan, world: Any, model: Any, server: Any) -> Any:
    """The VRPN server of the motion capture when ``~vrpn`` asks for it, else None."""
    import rospy

    if not plan.vrpn_on:
        return None
    from crazyflie_driver.sim.room.mocap_vrpn import WorldVrpnServer
    try:
        vrpn = WorldVrpnServer(world, model, port=plan.vrpn_port)
        vrpn.start()
    except OSError as e:
        rospy.logfatal("crazyflie_sim: cannot serve VRPN on port %s: %s (choose another with ~vrpn_port, "
                       "0 for any)", plan.vrpn_port, e.strerror or e)
        _fail(server, world)
    rospy.loginfo("crazyflie_sim: motion capture served as VRPN on 127.0.0.1:%d (trackers %s)", vrpn.port,
                  ", ".join(plan.names))
    return vrpn


class _FrameRelay:
    """Hands the frames from the world's stepping thread to the publishing thread."""

    def __init__(self) -> None:
        self._frames: List[Any] = []
        self._lock = threading.Lock()
        self._ready = threading.Event()

    def on_frames(self, frames) -> None:      # the world's stepping thread: hand over, publish elsewhere
        with self._lock:
            self._frames.extend(frames)
        self._ready.set()

    def take(self, timeout_s: float) -> List[Any]:
        """The frames delivered since the last call, waiting up to ``timeout_s`` for some."""
        self._ready.wait(timeout_s)
        self._ready.clear()
        with self._lock:
            frames = self._frames[:]
            del self._frames[:]
        return frames


def _start_mocap_loop(plan: SimPlan, world: Any, relay: _FrameRelay, publisher: MocapPublisher,
                      stop: threading.Event) -> threading.Thread:
    import rospy

    from crazyflie_driver.nodes.ros_signals import shutting_down

    def mocap_loop() -> None:
        period = 1.0 / plan.mocap.rate
        while not stop.is_set() and not rospy.is_shutdown():
            frames = relay.take(period)
            try:
                publisher.publish(frames, float(world.time))
            except Exception as e:   # a publishing hiccup must not stop the world
                if not shutting_down():   # (at shutdown the topics close under this thread)
                    rospy.logwarn_throttle(5.0, "crazyflie_sim: mocap frame failed: %s" % e)

    thread = threading.Thread(target=mocap_loop, name="mocap", daemon=True)
    thread.start()
    return thread


def main() -> None:
    import rospy
    from rosgraph_msgs.msg import Clock

    from crazyflie_driver.nodes.ros_signals import init_node
    from crazyflie_driver.sim.room.pacing import start_pacing

    init_node("crazyflie_sim")
    params = _private_params()
    # /clock first: nodes under /use_sim_time wait for it (nodes.ros_clock) before they time anything
    # queue_size 1: a subscriber that fell behind gets the newest time next, not a backlog of old ones
    # (100 queued /clock messages held a late node's ROS time up to 0.2 s of world time behind)
    clock_pub = rospy.Publisher("/clock", Clock, queue_size=1) if params.get("publish_clock", True) else None
    plan, world, server = _plan_and_start(params)
    if clock_pub is not None:
        _publish_clock(world, clock_pub, Clock)
    world.start()
    pacer = start_pacing(world, plan.pacing)
    rospy.loginfo("crazyflie_sim: world served on %s (%d dongle%s, mocap %s at %.0f Hz, speed %s%s): %s",
                  server.address, plan.dongles, "" if plan.dongles == 1 else "s", plan.mocap.style, plan.mocap.rate,
                  plan.pacing.describe(), ", /clock" if clock_pub is not None else "",
                  ", ".join("%s on %s" % (v.name, v.uri) for v in plan.vehicles))

    model = mocap_model(world, plan.mocap, plan.seed)
    publisher = MocapPublisher(plan.mocap, plan.names, plan.vicon_frames,
                               world_stamps=clock_pub is not None and bool(rospy.get_param("/use_sim_time", False)))
    _advertise_mocap_switches(model, plan.names)
    server.mocap = model
    _inject_start_faults(plan, server, world)
    _advertise_fault_service(server.control)
    relay = _FrameRelay()
    vrpn = _start_vrpn(plan, world, model, server)
    if plan.mocap.style != "none":
        model.add_listener(relay.on_frames)
    if plan.mocap.style != "none" or vrpn is not None:
        model.attach()
    stop = threading.Event()
    _start_mocap_loop(plan, world, relay, publisher, stop)
    diagnostics = _start_diagnostics(world, server.address, server.active_faults, plan.pacing, pacer)

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
