"""rospy node ``controller``: tf pose + ``goal`` in, ``cmd_vel`` out, ``takeoff`` / ``land`` services.

Thin glue around :class:``PositionController``. The pose is the tf transform ``worldFrame → frame``;
its stamp is the pose's age, so a motion-capture stream that stops is noticed (the original used
the latest transform whatever its age). The state and the safety status ("Automatic: ok",
"Automatic: pose stale: holding level", ...) are published on ``~state`` (latched, on change).
The server's ``status`` topic (its ``emergency`` value) puts it in "Idle: emergency stop ..." until the
Crazyflie is added again; idle without a pose, it says so in the log every few seconds.
"""
from __future__ import annotations

import sys
import threading
from typing import Any, Dict, Optional

import rospy
import tf2_ros
import yaml
from geometry_msgs.msg import PoseStamped, Twist
from diagnostic_msgs.msg import DiagnosticStatus
from std_msgs.msg import String
from std_srvs.srv import Empty, EmptyResponse

from crazyflie_driver.nodes.ros_signals import init_node, shutting_down

from .pid import PidGains
from .position_controller import ControllerConfig, PoseSample, PositionController, Safety, yaw_from_quaternion

NO_POSE_REPEAT_S = 5.0      # while idle without a pose, say so again this often

# private parameter → ControllerConfig field (beyond the original's frame, worldFrame, frequency, PIDs)
EXTRA_PARAMS = {
    "takeoffHandover": "takeoff_handover",
    "derivative": "derivative",
    "poseTimeout": "pose_timeout",
    "lostPoseLandTimeout": "lost_pose_land_timeout",
    "lostPoseThrustDrop": "lost_pose_thrust_drop",
    "lostPoseDescentTime": "lost_pose_descent_time",
    "handoverSpeed": "handover_speed",
    "handoverAccel": "handover_accel",
    "liftoffLag": "liftoff_lag",
    "takeoffThrustRate": "takeoff_thrust_rate",
    "takeoffHeight": "takeoff_height",
    "takeoffMaxThrust": "takeoff_max_thrust",
    "landingHeight": "landing_height",
    "goalChange": "goal_change",
    "goalSpeed": "goal_speed",
    "goalAccel": "goal_accel",
    "tiltCompensation": "tilt_compensation",
    "zIntegration": "z_integration",
    "hoverRefineTime": "hover_refine_time",
}
TEXT_PARAMS = ("takeoff_handover", "derivative", "goal_change", "z_integration")
BOOL_PARAMS = ("tilt_compensation",)
AXES = (("x", "X"), ("y", "Y"), ("z", "Z"), ("yaw", "Yaw"))


class ConfigError(ValueError):
    pass


def config_from_params(params: Dict[str, Any]) -> ControllerConfig:
    """ControllerConfig from the node's private parameters (a dict as rospy returns ``~``)."""
    pids = params.get("PIDs")
    if not isinstance(pids, dict):
        raise ConfigError("~PIDs is missing (load config/crazyflie2.yaml into the node's namespace)")
    gains = {}
    for field, axis in AXES:
        if not isinstance(pids.get(axis), dict):
            raise ConfigError("~PIDs/%s is missing" % axis)
        try:
            gains[field] = PidGains.from_params(pids[axis], axis)
        except ValueError as e:
            raise ConfigError("~PIDs/%s" % e)
    extra = {}
    for name, field in EXTRA_PARAMS.items():
        if name in params:
            value = params[name]
            if field in BOOL_PARAMS:
                if not isinstance(value, bool):
                    raise ConfigError("~%s must be true or false, got %r" % (name, value))
            elif field not in TEXT_PARAMS:
                try:
                    value = float(value)
                except (TypeError, ValueError):
                    raise ConfigError("~%s must be a number, got %r" % (name, value))
            extra[field] = value
    try:
        return ControllerConfig(gains["x"], gains["y"], gains["z"], gains["yaw"], **extra)
    except ValueError as e:
        raise ConfigError(str(e))


def emergency_of(values) -> Optional[bool]:
    """The ``emergency`` value of the server's status (KeyValue list), or None if it has none."""
    for kv in values:
        if kv.key == "emergency":
            return kv.value.strip().lower() == "true"
    return None


class ControllerNode:
    def __init__(self, params: Dict[str, Any]) -> None:
        # tf2 refuses a leading '/', which the chapter's frames have (/vicon/crazyflie/crazyflie)
        self.frame = str(params.get("frame", "")).strip().strip("/")
        if not self.frame:
            raise ConfigError("~frame is required (the tf frame of the tracked Crazyflie)")
        self.world_frame = str(params.get("worldFrame", "world")).strip().strip("/") or "world"
        self.frequency = float(params.get("frequency", 50.0))
        if not 0 < self.frequency <= 1000:
            raise ConfigError("~frequency must be in (0, 1000] Hz, got %r" % self.frequency)
        self.controller = PositionController(config_from_params(params), log=self._log)
        self._lock = threading.Lock()
        self._status = ""
        self._last_lookup_error = ""
        self._no_pose_since: Optional[float] = None
        self._no_pose_said = 0.0
        self.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(2.0))
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        self.cmd_pub = rospy.Publisher("cmd_vel", Twist, queue_size=1)
        self.state_pub = rospy.Publisher("~state", String, queue_size=1, latch=True)
        rospy.Subscriber("goal", PoseStamped, self._on_goal, queue_size=1)
        rospy.Subscriber("status", DiagnosticStatus, self._on_server_status, queue_size=5)
        rospy.Service("takeoff", Empty, self._on_takeoff)
        rospy.Service("land", Empty, self._on_land)
        self._publish_status()
        self.timer = rospy.Timer(rospy.Duration(1.0 / self.frequency), self._on_timer)

    @staticmethod
    def _log(level: str, message: str) -> None:
        {"info": rospy.loginfo, "warn": rospy.logwarn}.get(level, rospy.logerr)("controller: %s", message)

    def _lookup_pose(self) -> Optional[PoseSample]:
        try:
            tf = self.tf_buffer.lookup_transform(self.world_frame, self.frame, rospy.Time(0))
        except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException) as e:
            text = str(e)
            if text != self._last_lookup_error:
                rospy.logwarn("controller: no pose %s -> %s: %s", self.world_frame, self.frame, text)
                self._last_lookup_error = text
            return None
        self._last_lookup_error = ""
        t, q = tf.transform.translation, tf.transform.rotation
        return PoseSample(tf.header.stamp.to_sec(), t.x, t.y, t.z, yaw_from_quaternion(q.x, q.y, q.z, q.w))

    def _on_timer(self, _event) -> None:
        pose = self._lookup_pose()
        with self._lock:
            cmd = self.controller.update(rospy.get_time(), pose)
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.linear.z, msg.angular.z = cmd
        self._remind_no_pose(rospy.get_time())
        try:
            self.cmd_pub.publish(msg)
            self._publish_status()
        except rospy.ROSException:
            # a timer tick racing the node's shutdown is not an error: rospy closes the topics
            # before is_shutdown() turns true, so ask whether a shutdown has begun
            if not shutting_down():
                raise

    def _remind_no_pose(self, now: float) -> None:
        """Idle without a pose: say so every NO_POSE_REPEAT_S, naming the frames tf does know."""
        if self.controller.safety != Safety.NO_POSE:
            self._no_pose_since = None
            return
        if self._no_pose_since is None:
            self._no_pose_since = self._no_pose_said = now
            return
        if now - self._no_pose_said < NO_POSE_REPEAT_S:
            return
        self._no_pose_said = now
        rospy.logwarn("controller: still no pose of %s in %s after %.0f s, take-off is refused; tf knows %s. "
                      "Is the motion capture running, and does the frame argument name the tracked body?",
                      self.frame, self.world_frame, now - self._no_pose_since, self._known_frames())

    def _known_frames(self) -> str:
        try:
            frames = sorted(yaml.safe_load(self.tf_buffer.all_frames_as_yaml()) or {})
        except (yaml.YAMLError, TypeError, AttributeError):
            frames = []
        return ", ".join(frames) if frames else "no frames at all"

    def _publish_status(self) -> None:
        text = self.controller.status_text()
        if text != self._status:
            self._status = text
            self.state_pub.publish(String(data=text))

    def _on_goal(self, msg: PoseStamped) -> None:
        frame = msg.header.frame_id.lstrip("/")
        if frame and frame != self.world_frame.lstrip("/"):
            rospy.logwarn_throttle(5.0, "controller: goal ignored: frame %r is not the world frame %r"
                                   % (msg.header.frame_id, self.world_frame))
            return
        p, q = msg.pose.position, msg.pose.orientation
        yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w) if (q.x, q.y, q.z, q.w) != (0, 0, 0, 0) else 0.0
        with self._lock:
            self.controller.set_goal(p.x, p.y, p.z, yaw)

    def _on_server_status(self, msg: DiagnosticStatus) -> None:
        """The server's word on this Crazyflie: stopped by emergency, or added afresh."""
        emergency = emergency_of(msg.values)
        if emergency is None:
            return
        with self._lock:
            if emergency:
                self.controller.emergency()
            else:
                self.controller.clear_emergency()
        self._publish_status()

    def _on_takeoff(self, _req) -> EmptyResponse:
        pose = self._lookup_pose()
        with self._lock:
            self.controller.takeoff(rospy.get_time(), pose)
        self._publish_status()
        return EmptyResponse()

    def _on_land(self, _req) -> EmptyResponse:
        with self._lock:
            self.controller.land(rospy.get_time())
        self._publish_status()
        return EmptyResponse()


def main() -> None:
    init_node("controller")
    params = rospy.get_param("~", {})
    try:
        ControllerNode(params)
    except ConfigError as e:
        rospy.logfatal("controller: %s", e)
        sys.exit(1)
    rospy.spin()
