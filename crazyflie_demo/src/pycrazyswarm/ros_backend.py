"""The thin ROS adapter under ``pycrazyswarm``: a running swarm server's services and topics
(crazyflie_server in swarm mode, ``swarm.launch``), and ROS or world time.

Swarm-wide: ``/takeoff``, ``/land``, ``/stop``, ``/go_to``, ``/start_trajectory``, ``/emergency``,
``/update_params``. Per Crazyflie under its namespace: the same high-level services plus
``upload_trajectory``, ``set_group_mask``, ``notify_setpoints_stop``, ``update_params`` and the
streaming topics ``cmd_full_state``, ``cmd_velocity_world``, ``cmd_hover``, ``cmd_position``,
``cmd_stop``, ``cmd_vel``. A service's refusal becomes ``CommandRejected`` with the server's reason.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import rospy
from geometry_msgs.msg import Point, PoseStamped, Twist
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import Empty as EmptyMsg
from std_srvs.srv import Empty

from crazyflie_driver.errors import CommandRejected, CrazyflieError
from crazyflie_driver.msg import FullState, Hover, Position, TrajectoryPolynomialPiece, VelocityWorld
from crazyflie_driver.nodes import ros_signals
from crazyflie_driver.protocol.trajectory import Piece
from crazyflie_driver.srv import (
    GoTo,
    Land,
    NotifySetpointsStop,
    SetGroupMask,
    StartTrajectory,
    Stop,
    Takeoff,
    UpdateParams,
    UploadTrajectory,
)

Vec3 = Tuple[float, float, float]
#: Wall seconds to wait for the swarm server's services before saying what is missing.
SERVICE_WAIT_S = 120.0
#: s a position query waits for the first pose before saying where it looked.
POSITION_WAIT_S = 10.0
#: A tf pose older than this [s] is not "the latest measurement"; the pose topic is used instead.
TF_FRESH_S = 0.5
NODE_NAME = "CrazyflieAPI"        # Crazyswarm's node name (one script at a time, as there)

GLOBAL_SERVICES = {"takeoff": Takeoff, "land": Land, "stop": Stop, "go_to": GoTo, "start_trajectory": StartTrajectory,
                   "update_params": UpdateParams, "emergency": Empty}
CRAZYFLIE_SERVICES = {"takeoff": Takeoff, "land": Land, "stop": Stop, "go_to": GoTo,
                      "start_trajectory": StartTrajectory, "upload_trajectory": UploadTrajectory,
                      "set_group_mask": SetGroupMask, "notify_setpoints_stop": NotifySetpointsStop,
                      "update_params": UpdateParams}


def init_node() -> None:
    """Crazyswarm's node name; the stack's signal handling (Ctrl-C always ends the script)."""
    if not rospy.core.is_initialized():
        ros_signals.init_node(NODE_NAME, anonymous=False)


def pieces_msg(pieces: Sequence[Piece]) -> List[TrajectoryPolynomialPiece]:
    """Pieces as ``upload_trajectory`` takes them."""
    out = []
    for p in pieces:
        m = TrajectoryPolynomialPiece()
        m.poly_x, m.poly_y, m.poly_z, m.poly_yaw = list(p.x), list(p.y), list(p.z), list(p.yaw)
        m.duration = rospy.Duration.from_sec(p.duration)
        out.append(m)
    return out


class RosBackend:
    """The swarm server's services and topics for the Crazyflies in ``namespaces`` (``/cf1``, ...)."""

    def __init__(self, namespaces: Sequence[str], wait_s: float = SERVICE_WAIT_S) -> None:
        self.namespaces = list(namespaces)
        self._proxies: Dict[str, rospy.ServiceProxy] = {}
        names = ["/" + s for s in GLOBAL_SERVICES] + ["%s/%s" % (ns, s) for ns in self.namespaces
                                                      for s in CRAZYFLIE_SERVICES]
        self._wait(names, wait_s)
        for s, kind in GLOBAL_SERVICES.items():
            self._proxies["/" + s] = rospy.ServiceProxy("/" + s, kind)
        for ns in self.namespaces:
            for s, kind in CRAZYFLIE_SERVICES.items():
                self._proxies["%s/%s" % (ns, s)] = rospy.ServiceProxy("%s/%s" % (ns, s), kind)
        self._pubs: Dict[str, rospy.Publisher] = {}
        for ns in self.namespaces:
            for topic, kind in (("cmd_full_state", FullState), ("cmd_velocity_world", VelocityWorld),
                                ("cmd_hover", Hover), ("cmd_position", Position), ("cmd_stop", EmptyMsg),
                                ("cmd_vel", Twist)):
                self._pubs["%s/%s" % (ns, topic)] = rospy.Publisher("%s/%s" % (ns, topic), kind, queue_size=1)
        self._poses: Dict[str, Tuple[float, Vec3]] = {}
        self._pose_lock = threading.Condition()
        self._pose_subs = [rospy.Subscriber("%s/pose" % ns, PoseStamped, self._on_pose, callback_args=ns,
                                            queue_size=1) for ns in self.namespaces]
        self._tf = None

    @staticmethod
    def _wait(names: List[str], wait_s: float) -> None:
        deadline = time.monotonic() + wait_s
        for name in names:
            try:
                rospy.wait_for_service(name, timeout=max(0.1, deadline - time.monotonic()))
            except rospy.ROSException:
                raise CrazyflieError(
                    "%s is not served after %.0f s: start the swarm server for these Crazyflies (roslaunch "
                    "crazyflie_demo swarm.launch swarm_file:=<your crazyflies.yaml> demo:=false, add sim:=true to "
                    "simulate) or run the script with --sim" % (name, wait_s)) from None

    def _call(self, name: str, *args) -> None:
        try:
            self._proxies[name](*args)
        except rospy.ServiceException as e:
            raise CommandRejected("%s refused: %s" % (name, e)) from None

    @staticmethod
    def _service(ns: str, name: str) -> str:
        return "%s/%s" % (ns, name)

    # -- high level --
    def takeoff(self, ns, group_mask, height, duration) -> None:
        self._call(self._service(ns, "takeoff"), group_mask, height, rospy.Duration.from_sec(duration))

    def land(self, ns, group_mask, height, duration) -> None:
        self._call(self._service(ns, "land"), group_mask, height, rospy.Duration.from_sec(duration))

    def stop(self, ns, group_mask) -> None:
        self._call(self._service(ns, "stop"), group_mask)

    def go_to(self, ns, group_mask, relative, goal, yaw, duration) -> None:
        self._call(self._service(ns, "go_to"), group_mask, relative, Point(*goal), yaw,
                   rospy.Duration.from_sec(duration))

    def upload_trajectory(self, ns, trajectory_id, piece_offset, pieces) -> None:
        self._call(self._service(ns, "upload_trajectory"), trajectory_id, piece_offset, pieces_msg(pieces))

    def start_trajectory(self, ns, group_mask, trajectory_id, timescale, reverse, relative) -> None:
        self._call(self._service(ns, "start_trajectory"), group_mask, trajectory_id, timescale, reverse, relative)

    def set_group_mask(self, ns, group_mask) -> None:
        self._call(self._service(ns, "set_group_mask"), group_mask)

    def notify_setpoints_stop(self, ns, group_mask, remain_valid_ms) -> None:
        self._call(self._service(ns, "notify_setpoints_stop"), group_mask, remain_valid_ms)

    def emergency(self) -> None:
        self._call("/emergency")

    # -- parameters --
    def set_param(self, name: str, value: Any) -> None:
        rospy.set_param(name, value)

    def get_param(self, name: str) -> Any:
        try:
            return rospy.get_param(name)
        except KeyError:
            raise CrazyflieError("%s is not known: the swarm server does not read every parameter back from the "
                                 "Crazyflies; a value written with setParam (or by the server from the swarm file) "
                                 "is known after it was written" % name) from None

    def update_params(self, ns: str, names: List[str]) -> None:
        self._call(self._service(ns, "update_params"), list(names))

    # -- streaming setpoints --
    def cmd_full_state(self, ns, pos, vel, acc, quaternion, omega) -> None:
        m = FullState()
        m.header.stamp, m.header.frame_id = rospy.Time.now(), "world"
        p, o = m.pose.position, m.pose.orientation
        p.x, p.y, p.z = pos
        o.x, o.y, o.z, o.w = quaternion
        (m.twist.linear.x, m.twist.linear.y, m.twist.linear.z) = vel
        (m.twist.angular.x, m.twist.angular.y, m.twist.angular.z) = omega
        (m.acc.x, m.acc.y, m.acc.z) = acc
        self._pubs[ns + "/cmd_full_state"].publish(m)

    def cmd_velocity_world(self, ns, vel, yaw_rate_deg) -> None:
        m = VelocityWorld()
        m.header.stamp, m.header.frame_id = rospy.Time.now(), "world"
        (m.vel.x, m.vel.y, m.vel.z), m.yawRate = vel, yaw_rate_deg
        self._pubs[ns + "/cmd_velocity_world"].publish(m)

    def cmd_hover(self, ns, vx, vy, yaw_rate_deg, z_distance) -> None:
        m = Hover()
        m.header.stamp, m.header.frame_id = rospy.Time.now(), ns.strip("/")     # the body frame's name
        m.vx, m.vy, m.yawrate, m.zDistance = vx, vy, yaw_rate_deg, z_distance
        self._pubs[ns + "/cmd_hover"].publish(m)

    def cmd_stop(self, ns) -> None:
        self._pubs[ns + "/cmd_stop"].publish(EmptyMsg())

    def cmd_vel(self, ns, roll_deg, pitch_deg, yawrate_deg, thrust) -> None:
        m = Twist()       # the chapter's cmd_vel: linear.x pitch, linear.y roll, linear.z thrust, angular.z yaw rate
        m.linear.x, m.linear.y, m.linear.z, m.angular.z = pitch_deg, roll_deg, thrust, yawrate_deg
        self._pubs[ns + "/cmd_vel"].publish(m)

    def cmd_position(self, ns, pos, yaw_deg) -> None:
        m = Position()
        m.header.stamp, m.header.frame_id = rospy.Time.now(), "world"
        m.x, m.y, m.z = pos
        m.yaw = yaw_deg
        self._pubs[ns + "/cmd_position"].publish(m)

    # -- state --
    def _on_pose(self, msg: PoseStamped, ns: str) -> None:
        p = msg.pose.position
        with self._pose_lock:
            self._poses[ns] = (time.monotonic(), (p.x, p.y, p.z))
            self._pose_lock.notify_all()

    def _from_tf(self, ns: str) -> Optional[Vec3]:
        import tf2_ros
        if self._tf is None:
            self._tf = tf2_ros.Buffer()
            self._tf_listener = tf2_ros.TransformListener(self._tf)
        try:
            t = self._tf.lookup_transform("world", ns.strip("/"), rospy.Time(0))
        except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException):
            return None
        if (rospy.Time.now() - t.header.stamp).to_sec() > TF_FRESH_S:
            return None
        v = t.transform.translation
        return (v.x, v.y, v.z)

    def position(self, ns: str) -> Vec3:
        deadline = time.monotonic() + POSITION_WAIT_S
        while True:
            p = self._from_tf(ns)
            if p is not None:
                return p
            with self._pose_lock:
                if ns in self._poses:
                    return self._poses[ns][1]
                self._pose_lock.wait(0.05)
            if time.monotonic() > deadline or rospy.is_shutdown():
                raise CrazyflieError("%s: no position within %.0f s: neither tf world -> %s (motion capture) nor the "
                                     "onboard pose topic %s/pose (swarm mode's pose_period_ms must not be 0)"
                                     % (ns, POSITION_WAIT_S, ns.strip("/"), ns))


class RosClock:
    """ROS time (the wall clock, or ``/clock`` under ``/use_sim_time``), as Crazyswarm's TimeHelper."""

    def __init__(self) -> None:
        self._rate: Optional[rospy.Rate] = None
        self._rate_hz = 0.0

    def time(self) -> float:
        return rospy.Time.now().to_sec()

    def sleep(self, duration: float) -> None:
        rospy.sleep(duration)

    def sleep_for_rate(self, rate_hz: float) -> None:
        if self._rate is None or self._rate_hz != rate_hz:
            self._rate, self._rate_hz = rospy.Rate(rate_hz), rate_hz
        self._rate.sleep()

    def is_shutdown(self) -> bool:
        return rospy.is_shutdown()


class WorldClock:
    """The simulated world's time from its ``/clock`` topic, whether or not ``/use_sim_time`` is set:
    with ``--sim`` a script's seconds are the world's, as in Crazyswarm's simulator, even when the
    world runs slower than real time on a busy machine."""

    FIRST_WAIT_S = 30.0

    def __init__(self, topic: str = "/clock") -> None:
        self._now: Optional[float] = None
        self._cond = threading.Condition()
        self._next: Optional[float] = None
        self._sub = rospy.Subscriber(topic, ClockMsg, self._on_clock, queue_size=1)
        with self._cond:
            if not self._cond.wait_for(lambda: self._now is not None or rospy.is_shutdown(), self.FIRST_WAIT_S):
                raise CrazyflieError("no %s from the simulated world within %.0f s: is it running with publish_clock:="
                                     "true (swarm.launch sim:=true sets it)?" % (topic, self.FIRST_WAIT_S))

    def _on_clock(self, msg) -> None:
        with self._cond:
            self._now = msg.clock.to_sec()
            self._cond.notify_all()

    def time(self) -> float:
        with self._cond:
            return float(self._now)

    def _until(self, t: float) -> None:
        with self._cond:
            while self._now < t:
                if rospy.is_shutdown():
                    raise rospy.ROSInterruptException("ROS shutdown while sleeping")
                self._cond.wait(0.1)

    def sleep(self, duration: float) -> None:
        self._until(self.time() + max(0.0, duration))

    def sleep_for_rate(self, rate_hz: float) -> None:
        period = 1.0 / rate_hz
        now = self.time()
        if self._next is None or self._next < now - period:    # first call, or fell behind: start afresh
            self._next = now + period
        else:
            self._next += period
        self._until(self._next)

    def is_shutdown(self) -> bool:
        return rospy.is_shutdown()
