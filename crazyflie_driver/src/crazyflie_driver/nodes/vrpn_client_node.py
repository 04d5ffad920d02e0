"""``vrpn_client_node``: VRPN tracker poses as ROS topics and tf, compatible with vrpn_client_ros.

Private parameters (vrpn_client_ros names): ``server`` (localhost; "host" or "host:port"),
``port`` (3883), ``frame_id`` (world), ``broadcast_tf`` (false), ``refresh_tracker_frequency``
(0: only ``trackers``; > 0: every tracker the server describes is added as soon as it is
described), ``trackers`` ([]), ``use_server_time`` (false), ``process_sensor_id`` (false);
ours: ``y_up`` (false: OptiTrack Y-up -> ROS Z-up rotation), ``stale_timeout`` (0.1 s).

Publishes ``~<tracker>/pose`` (geometry_msgs/PoseStamped), ``~<tracker>/twist``
(geometry_msgs/TwistStamped, when the server sends velocity), tf ``frame_id -> <tracker>``
(with broadcast_tf) and ``/diagnostics`` (diagnostic_msgs/DiagnosticArray, 1 Hz: the connection
and each tracker's age of last pose, STALE level past stale_timeout). A tracker going stale is
logged as a warning at once and every 5 s while it stays stale. Network errors never end the
node: it reconnects with back-off. Ages and staleness are counted on ROS time (``ros_clock``: the
world's in a simulation under /use_sim_time); the network's timeouts and back-off on the wall clock.
"""
from __future__ import annotations

import logging
import math
import sys
import threading
from typing import Any, Dict

import rospy
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TransformStamped, TwistStamped

from crazyflie_driver.clock import Clock
from crazyflie_driver.mocap.vrpn_bridge import VrpnBridge, VrpnConfigError, VrpnNodeConfig, config_from_params
from crazyflie_driver.mocap.vrpn_client import PoseReport, TwistReport, VrpnClient
from crazyflie_driver.nodes.ros_clock import ros_clock
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down, shutting_down

DIAGNOSTICS_PERIOD = 1.0


def ros_log(level: int, text: str) -> None:
    if level >= logging.ERROR:
        rospy.logerr(text)
    elif level >= logging.WARNING:
        rospy.logwarn(text)
    elif level >= logging.INFO:
        rospy.loginfo(text)
    else:
        rospy.logdebug(text)


def private_params() -> Dict[str, Any]:
    prefix = rospy.get_name().rstrip("/") + "/"
    return {full[len(prefix):]: rospy.get_param(full) for full in rospy.get_param_names()
            if full.startswith(prefix)}


class VrpnClientNode:
    """Thin glue: VrpnClient reports -> VrpnBridge records -> messages."""

    def __init__(self, config: VrpnNodeConfig, clock: Clock) -> None:
        self.config = config
        self.clock = clock
        self.bridge = VrpnBridge(config, clock=clock.now, log=ros_log)
        self._lock = threading.Lock()
        self._pose_pubs: Dict[str, rospy.Publisher] = {}
        self._twist_pubs: Dict[str, rospy.Publisher] = {}
        self._tf = tf2_ros.TransformBroadcaster() if config.broadcast_tf else None
        self._diag_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=2)
        wanted = None if config.auto_discover else config.trackers
        self.client = VrpnClient(config.host, config.port, trackers=wanted, on_pose=self._on_pose,
                                 on_twist=self._on_twist, on_tracker=self._on_tracker, log=ros_log,
                                 clock=clock.now)
        if not config.auto_discover and not config.trackers:
            rospy.logwarn("vrpn_client_node: ~trackers is empty and ~refresh_tracker_frequency is 0: "
                          "nothing will be published (set one of them)")

    # -- reports (socket thread) ----------------------------------------------------------------
    def _stamp(self, sec: int, usec: int) -> rospy.Time:
        if self.config.use_server_time:
            return rospy.Time(sec, usec * 1000)
        return rospy.Time.now()

    def _on_tracker(self, name: str) -> None:
        if self.config.auto_discover or name in self.config.trackers:
            clean = self.bridge.ros_name(name)
            if clean is not None:
                rospy.loginfo("VRPN: tracker %r -> %s/%s/pose", name, rospy.get_name(), clean)

    def _on_pose(self, report: PoseReport) -> None:
        out = self.bridge.pose(report)
        if out is None:
            return
        stamp = self._stamp(report.server_sec, report.server_usec)
        pub = self._pose_pubs.get(out.key)
        if pub is None:
            pub = self._pose_pubs[out.key] = rospy.Publisher("~%s/pose" % out.key, PoseStamped, queue_size=1)
        if pub.get_num_connections() > 0:           # as vrpn_client_ros: only when someone listens
            msg = PoseStamped()
            msg.header.stamp = stamp
            msg.header.frame_id = self.config.frame_id
            p, q = msg.pose.position, msg.pose.orientation
            p.x, p.y, p.z = out.position
            q.x, q.y, q.z, q.w = out.orientation
            publish_unless_shutting_down(pub, msg)
        if self._tf is not None and not shutting_down():
            t = TransformStamped()
            t.header.stamp = stamp
            t.header.frame_id = self.config.frame_id
            t.child_frame_id = out.child_frame
            tr, r = t.transform.translation, t.transform.rotation
            tr.x, tr.y, tr.z = out.position
            r.x, r.y, r.z, r.w = out.orientation
            self._tf.sendTransform(t)

    def _on_twist(self, report: TwistReport) -> None:
        out = self.bridge.twist(report)
        if out is None:
            return
        pub = self._twist_pubs.get(out.key)
        if pub is None:
            pub = self._twist_pubs[out.key] = rospy.Publisher("~%s/twist" % out.key, TwistStamped, queue_size=1)
        if pub.get_num_connections() > 0:
            msg = TwistStamped()
            msg.header.stamp = self._stamp(report.server_sec, report.server_usec)
            msg.header.frame_id = self.config.frame_id
            lin, ang = msg.twist.linear, msg.twist.angular
            lin.x, lin.y, lin.z = out.linear
            ang.x, ang.y, ang.z = out.angular
            publish_unless_shutting_down(pub, msg)

    # -- staleness and diagnostics (own thread) ---------------------------------------------------
    def watch(self) -> None:
        period = min(0.05, self.config.stale_timeout / 2.0)
        next_diag = self.clock.now()
        while not rospy.is_shutdown():
            self.clock.sleep(period)
            now = self.clock.now()
            try:
                for ev in self.bridge.staleness.check(now):
                    if ev.kind == "stale":
                        rospy.logwarn("VRPN tracker %s: no pose for %.2f s (stale: out of view of the "
                                      "mocap, or the server stopped sending it)", ev.name, ev.age)
                    else:
                        rospy.loginfo("VRPN tracker %s: poses again", ev.name)
                if now >= next_diag:
                    next_diag = now + DIAGNOSTICS_PERIOD
                    publish_unless_shutting_down(self._diag_pub, self.diagnostics(now))
            except Exception as e:  # never let bookkeeping end the node
                rospy.logerr("vrpn_client_node: diagnostics failed: %r", e)

    def diagnostics(self, now: float) -> DiagnosticArray:
        arr = DiagnosticArray()
        arr.header.stamp = rospy.Time.now()
        node = rospy.get_name().lstrip("/")
        c = self.client
        stats = c.session.stats
        conn = DiagnosticStatus(name="%s: connection" % node, hardware_id=c.address)
        conn.level = DiagnosticStatus.OK if c.connected else DiagnosticStatus.ERROR
        conn.message = "connected" if c.connected else "not connected (%s)" % (c.last_error or c.state)
        conn.values = [KeyValue(k, str(v)) for k, v in (
            ("state", c.state), ("server_version", c.server_version), ("connections", c.connections),
            ("poses", stats.poses), ("velocities", stats.velocities), ("malformed", stats.malformed),
            ("undescribed", stats.undescribed), ("ignored", stats.ignored))]
        arr.status.append(conn)
        for t in self.bridge.staleness.report(now):
            s = DiagnosticStatus(name="%s: %s" % (node, t.name), hardware_id=c.address)
            s.level = DiagnosticStatus.STALE if t.stale else DiagnosticStatus.OK
            s.message = ("never seen" if math.isinf(t.age) else
                         "no pose for %.2f s" % t.age if t.stale else "ok")
            s.values = [KeyValue("age", "%.3f" % t.age), KeyValue("rate", "%.1f" % t.rate),
                        KeyValue("poses", str(t.count)),
                        KeyValue("stale_timeout", "%.3f" % self.config.stale_timeout)]
            arr.status.append(s)
        return arr

    def run(self) -> None:
        rospy.loginfo("vrpn_client_node: VRPN server %s, frame %s%s%s", self.client.address,
                      self.config.frame_id, ", Y-up -> Z-up" if self.config.y_up else "",
                      ", tf on" if self.config.broadcast_tf else "")
        self.client.start()
        watcher = threading.Thread(target=self.watch, name="vrpn-staleness", daemon=True)
        watcher.start()
        try:
            rospy.spin()
        finally:
            self.client.stop()


def run() -> int:
    init_node("vrpn_client_node")
    try:
        config = config_from_params(private_params())
    except VrpnConfigError as e:
        rospy.logerr("vrpn_client_node: %s", e)
        return 1
    VrpnClientNode(config, ros_clock()).run()
    return 0


def main() -> None:
    try:
        code = run()
    except rospy.ROSInterruptException:
        code = 0
    sys.exit(code)
