"""ROS face of crazyflie_ros HEAD's per-Crazyflie setpoint topics and high-level services.

Under the Crazyflie's namespace: subscribers ``cmd_position``, ``cmd_hover``, ``cmd_full_state``,
``cmd_velocity_world``, ``cmd_stop``, ``external_position``, ``external_pose``; services ``takeoff``,
``land``, ``stop``, ``go_to``, ``upload_trajectory``, ``start_trajectory``, ``set_group_mask``,
``notify_setpoints_stop``. Everything behind them is ``server.onboard_commands``; bad input is a
warning (topics) or a service error naming the problem, never a dead node.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, List

import rosgraph.masterapi
import rospy
from geometry_msgs.msg import PointStamped, PoseStamped
from std_msgs.msg import Empty as EmptyMsg

from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.msg import FullState, Hover, Position, VelocityWorld
from crazyflie_driver.server.onboard_commands import OnboardCommands
from crazyflie_driver.server.onboard_pose import pose_from_log
from crazyflie_driver.server.refusals import RefusalThrottle
from crazyflie_driver.srv import (
    GoTo,
    GoToResponse,
    Land,
    LandResponse,
    NotifySetpointsStop,
    NotifySetpointsStopResponse,
    SetGroupMask,
    SetGroupMaskResponse,
    StartTrajectory,
    StartTrajectoryResponse,
    Stop,
    StopResponse,
    Takeoff,
    TakeoffResponse,
    UploadTrajectory,
    UploadTrajectoryResponse,
)


class PosePublisher:
    """HEAD's onboard ``pose`` topic: the estimator's pose (``server.onboard_pose``) as PoseStamped in
    the world frame, stamped when the Crazyflie sampled it."""

    def __init__(self, topic: str, frame_id: str = "world") -> None:
        self.frame_id = frame_id
        self.pub = rospy.Publisher(topic, PoseStamped, queue_size=10)

    def publish(self, stamp, values) -> None:
        (x, y, z), (qx, qy, qz, qw) = pose_from_log(values)
        msg = PoseStamped()
        msg.header.stamp, msg.header.frame_id = stamp, self.frame_id
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = qx, qy, qz, qw
        self.pub.publish(msg)


class RosOnboardCommands:
    """Subscribers and services of one Crazyflie; ``close()`` removes them."""

    def __init__(self, ns: str, uri: str, commands: OnboardCommands) -> None:
        self.uri = uri
        self.commands = commands
        self._refusals = RefusalThrottle()
        name = lambda topic: ns + "/" + topic
        c = commands
        subs = [
            ("cmd_position", Position, lambda m: c.cmd_position(m.x, m.y, m.z, m.yaw)),
            ("cmd_hover", Hover, lambda m: c.cmd_hover(m.vx, m.vy, m.yawrate, m.zDistance)),
            ("cmd_full_state", FullState, lambda m: c.cmd_full_state(
                _xyz(m.pose.position), _xyzw(m.pose.orientation), _xyz(m.twist.linear), _xyz(m.twist.angular),
                _xyz(m.acc))),
            ("cmd_velocity_world", VelocityWorld, lambda m: c.cmd_velocity_world(m.vel.x, m.vel.y, m.vel.z,
                                                                                 m.yawRate)),
            ("cmd_stop", EmptyMsg, lambda m: c.cmd_stop()),
            ("external_position", PointStamped, lambda m: c.external_position(m.point.x, m.point.y, m.point.z)),
            ("external_pose", PoseStamped, lambda m: c.external_pose(
                m.pose.position.x, m.pose.position.y, m.pose.position.z, _xyzw(m.pose.orientation))),
        ]
        self._subscribers: List[Any] = [
            rospy.Subscriber(name(topic), kind, self._topic(topic, handler), queue_size=1, tcp_nodelay=True)
            for topic, kind, handler in subs]
        services = [
            ("takeoff", Takeoff, TakeoffResponse,
             lambda r: c.takeoff(r.groupMask, r.height, r.duration.to_sec())),
            ("land", Land, LandResponse, lambda r: c.land(r.groupMask, r.height, r.duration.to_sec())),
            ("stop", Stop, StopResponse, lambda r: c.stop(r.groupMask)),
            ("go_to", GoTo, GoToResponse, lambda r: c.go_to(r.groupMask, r.relative, _xyz(r.goal), r.yaw,
                                                           r.duration.to_sec())),
            ("upload_trajectory", UploadTrajectory, UploadTrajectoryResponse, lambda r: c.upload_trajectory(
                r.trajectoryId, r.pieceOffset,
                [(p.duration.to_sec(), p.poly_x, p.poly_y, p.poly_z, p.poly_yaw) for p in r.pieces])),
            ("start_trajectory", StartTrajectory, StartTrajectoryResponse, lambda r: c.start_trajectory(
                r.groupMask, r.trajectoryId, r.timescale, r.reversed, r.relative)),
            ("set_group_mask", SetGroupMask, SetGroupMaskResponse, lambda r: c.set_group_mask(r.groupMask)),
            ("notify_setpoints_stop", NotifySetpointsStop, NotifySetpointsStopResponse,
             lambda r: c.notify_setpoints_stop(r.remainValidMillisecs)),
        ]
        self._services: List[Any] = []
        providers = _other_providers()      # one master query for all eight (a swarm adds dozens at once)
        for s, kind, response, handler in services:
            provider = providers.get(rospy.resolve_name(name(s)), "")
            if provider:
                rospy.loginfo("%s: %s is already served by %s (the chapter's host-side controller has its own "
                              "takeoff and land there); the onboard high-level %s is not advertised under that "
                              "name. Fly without that node to use the onboard one." % (self.uri, name(s), provider, s))
                continue
            self._services.append(rospy.Service(name(s), kind, self._service(s, handler, response)))

    def _topic(self, topic: str, handler: Callable[[Any], Any]) -> Callable[[Any], None]:
        def callback(msg) -> None:
            try:
                if handler(msg) is False:
                    rospy.logwarn_throttle(5.0, "%s: %s ignored after emergency" % (self.uri, topic))
            except (ValueError, CrazyflieError) as e:
                text = self._refusals.say(self.uri, topic, str(e))     # once a second per field and rule
                if text is not None:
                    rospy.logwarn("%s: %s refused: %s" % (self.uri, topic, text))
        return callback

    def _service(self, service: str, handler: Callable[[Any], Any], response: type) -> Callable[[Any], Any]:
        def callback(req):
            try:
                handler(req)
            except (ValueError, CrazyflieError) as e:
                rospy.logerr("%s: %s: %s", self.uri, service, e)
                raise rospy.ServiceException("%s: %s" % (service, e)) from e
            return response()
        return callback

    def close(self) -> None:
        for s in self._subscribers:
            s.unregister()
        for s in self._services:
            s.shutdown("Crazyflie %s removed" % self.uri)
        self._subscribers, self._services = [], []


def _other_providers() -> Dict[str, str]:
    """Resolved service name -> another node that already serves it ({} when the master can't tell).

    crazyflie_ros HEAD advertised its high-level ``takeoff``/``land`` in the namespace where the chapter's
    controller serves std_srvs/Empty ones of the same name; the master keeps the newest registration, so
    whichever started last would silently answer the other's callers with the wrong type.
    """
    me = rospy.get_name()
    try:
        _pubs, _subs, services = rosgraph.masterapi.Master(me).getSystemState()
    except (rosgraph.masterapi.Error, OSError):
        return {}
    out = {}
    for name, nodes in services:
        others = [n for n in nodes if n != me]
        if others:
            out[name] = others[0]
    return out


def _xyz(v) -> tuple:
    return (v.x, v.y, v.z)


def _xyzw(q) -> tuple:
    return (q.x, q.y, q.z, q.w)
