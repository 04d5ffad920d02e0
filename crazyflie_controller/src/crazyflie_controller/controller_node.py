"""rospy node ``controller``: tf pose + ``goal`` in, ``cmd_vel`` out, ``takeoff`` / ``land`` services.

Thin glue around :class:`PositionController`. The pose is the tf transform ``worldFrame → frame``;
its stamp is the pose's age, so a motion-capture stream that stops is noticed (the original used
the latest transform whatever its age). The state and the safety status ("Automatic: ok",
"Automatic: pose stale: holding level", ...) are published on ``~state`` (latched, on change).
The server's ``status`` topic (its ``emergency`` value) puts it in "Idle: emergency stop ..." until the
Crazyflie is added again. At start-up the motion capture's first pose may come after the controller's
first lookup: that is not worth a warning, so until the first pose it waits in silence and says so
only if none came within NO_POSE_REPEAT_S (then again every NO_POSE_REPEAT_S, while idle without a
pose); a pose lost after that is said at once. Every log line starts with the node's name
(``crazyflie1/controller: ...``), so the lines of several controllers in one launch can be told apart.

By default the command is computed by a free-running timer at ``~frequency`` (the chapter's 50 Hz),
from the newest pose in the tf buffer: a motion-capture sample then waits up to one period before
it is used. With ``~computeOnPose: true`` the command is computed as a pose arrives on ``/tf`` (taken from
the message itself, no buffer lookup), still at about ``~frequency`` (set it to the mocap's rate
to use every pose), and the timer only steps the controller when no pose came for a period
(take-off ramp, stale-pose handling). ``~cmd_vel_stamped``
(geometry_msgs/TwistStamped) repeats each command stamped with the pose it was computed from,
for measuring the control path's latency; it costs nothing while nobody subscribes.
``/diagnostics`` (every second): the state, the pose's age and how often the thrust sat at a limit
(``diagnostics.controller_entry``), named ``<node>: <frame>``.
"""
from __future__ import annotations

import sys
import threading
from typing import Any, Dict, Optional, Sequence

import rospy
import tf2_ros
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from std_msgs.msg import String
from std_srvs.srv import Empty, EmptyResponse
from tf2_msgs.msg import TFMessage

from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down, shutting_down

from .diagnostics import SaturationWindow, controller_entry, thrust_saturated
from .pid import PidGains
from .position_controller import ControllerConfig, PoseSample, PositionController, Safety, yaw_from_quaternion

NO_POSE_REPEAT_S = 5.0      # while idle without a pose, say so again this often

# private parameter → ControllerConfig field (beyond the original's frame, worldFrame, frequency, PIDs)
EXTRA_PARAMS = {
    "takeoffHandover": "takeoff_handover",
    "derivative": "derivative",
    "poseTimeout": "pose_timeout",
    "frozenPoseTimeout": "frozen_pose_timeout",
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
# computeOnPose: a pose arriving sooner than this fraction of a period after the last step is
# skipped, so the commands keep to about ``frequency`` (every other pose of a 100 Hz mocap at
# 50 Hz) without a timer's wait; the tolerance keeps jitter from skipping two poses in a row
ON_POSE_MIN_GAP = 0.75
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
    gains = _pid_gains(pids)
    extra = {field: _extra_value(name, field, params[name]) for name, field in EXTRA_PARAMS.items() if name in params}
    try:
        return ControllerConfig(gains["x"], gains["y"], gains["z"], gains["yaw"], **extra)
    except ValueError as e:
        raise ConfigError(str(e)) from e


def _pid_gains(pids: Dict[str, Any]) -> Dict[str, PidGains]:
    """The gains of each axis from ``~PIDs`` (every axis required)."""
    gains = {}
    for field, axis in AXES:
        if not isinstance(pids.get(axis), dict):
            raise ConfigError("~PIDs/%s is missing" % axis)
        try:
            gains[field] = PidGains.from_params(pids[axis], axis)
        except ValueError as e:
            raise ConfigError("~PIDs/%s" % e) from e
    return gains


def _extra_value(name: str, field: str, value: Any) -> Any:
    """The value of parameter ``~name`` for ControllerConfig's ``field``: a boolean, a text, or a number."""
    if field in BOOL_PARAMS:
        if not isinstance(value, bool):
            raise ConfigError("~%s must be true or false, got %r" % (name, value))
        return value
    if field in TEXT_PARAMS:
        return value
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ConfigError("~%s must be a number, got %r" % (name, value)) from None


def emergency_of(values) -> Optional[bool]:
    """The ``emergency`` value of the server's status (KeyValue list), or None if it has none."""
    for kv in values:
        if kv.key == "emergency":
            return kv.value.strip().lower() == "true"
    return None


def node_label() -> str:
    """The node's name without the leading '/' (``crazyflie1/controller``): which Crazyflie a line is about."""
    return rospy.get_name().lstrip("/") or "controller"


def newest_transform_of(transforms: Sequence[Any], frame: str) -> Optional[Any]:
    """The last transform whose child is ``frame`` (leading '/' ignored), should a tf message carry several."""
    found = None
    for t in transforms:
        if t.child_frame_id.strip("/") == frame:
            found = t
    return found


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
        self.compute_on_pose = params.get("computeOnPose", False)
        if not isinstance(self.compute_on_pose, bool):
            raise ConfigError("~computeOnPose must be true or false, got %r" % (self.compute_on_pose,))
        self.controller = PositionController(config_from_params(params), log=self._log)
        self._lock = threading.Lock()
        self._status = ""
        self._last_lookup_error = ""
        self._had_pose = False                   # a pose has been seen: a lookup that fails is news
        self._no_pose_since: Optional[float] = None
        self._no_pose_said = 0.0
        self._pose_stamp = rospy.Time()          # stamp of the newest pose the controller has seen
        self._last_step = -1e9                   # rospy time of the last control step
        self.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(2.0))
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        self.cmd_pub = rospy.Publisher("cmd_vel", Twist, queue_size=1)
        self.stamped_pub = rospy.Publisher("~cmd_vel_stamped", TwistStamped, queue_size=10)
        self.state_pub = rospy.Publisher("~state", String, queue_size=1, latch=True)
        self._saturation = SaturationWindow()
        self.diag_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=2)
        self.diag_timer = rospy.Timer(rospy.Duration(1.0), self._on_diagnostics)
        rospy.Subscriber("goal", PoseStamped, self._on_goal, queue_size=1)
        rospy.Subscriber("status", DiagnosticStatus, self._on_server_status, queue_size=5)
        rospy.Service("takeoff", Empty, self._on_takeoff)
        rospy.Service("land", Empty, self._on_land)
        self._publish_status()
        if self.compute_on_pose:
            rospy.Subscriber("/tf", TFMessage, self._on_tf, queue_size=10, tcp_nodelay=True)
        self.timer = rospy.Timer(rospy.Duration(1.0 / self.frequency), self._on_timer)

    @staticmethod
    def _log(level: str, message: str) -> None:
        {"info": rospy.loginfo, "warn": rospy.logwarn}.get(level, rospy.logerr)("%s: %s", node_label(), message)

    def _lookup_pose(self) -> Optional[PoseSample]:
        try:
            tf = self.tf_buffer.lookup_transform(self.world_frame, self.frame, rospy.Time(0))
        except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException) as e:
            text = str(e)
            if text != self._last_lookup_error and self._had_pose:
                rospy.logwarn("%s: no pose %s -> %s: %s", node_label(), self.world_frame, self.frame, text)
            self._last_lookup_error = text
            return None
        self._last_lookup_error = ""
        self._had_pose = True
        return self._pose_of(tf)

    @staticmethod
    def _pose_of(tf) -> PoseSample:
        t, q = tf.transform.translation, tf.transform.rotation
        return PoseSample(tf.header.stamp.to_sec(), t.x, t.y, t.z, yaw_from_quaternion(q.x, q.y, q.z, q.w))

    def _on_tf(self, msg: TFMessage) -> None:
        """computeOnPose: a control step as a pose of our frame arrives (at most ~``frequency``)."""
        tf = newest_transform_of(msg.transforms, self.frame)
        if tf is None or rospy.get_time() - self._last_step < ON_POSE_MIN_GAP / self.frequency:
            return
        pose: Optional[PoseSample]
        if tf.header.frame_id.strip("/") == self.world_frame:
            pose = self._pose_of(tf)
        else:                # our frame hangs below another one: let the buffer chain it to the world
            pose = self._lookup_pose()
        self._step(pose, tf.header.stamp)

    def _on_timer(self, _event) -> None:
        if self.compute_on_pose and rospy.get_time() - self._last_step < 1.0 / self.frequency:
            return           # poses are arriving and each one computed a command
        pose = self._lookup_pose()
        self._step(pose, None if pose is None else rospy.Time.from_sec(pose.stamp))

    def _step(self, pose: Optional[PoseSample], stamp: Optional[rospy.Time]) -> None:
        """One control cycle; publishes cmd_vel (and ~cmd_vel_stamped when listened to)."""
        msg = Twist()
        try:
            with self._lock:
                now = rospy.get_time()
                cmd = self.controller.update(now, pose)
                self._last_step = now
                z = self.controller.pids["z"].gains
                self._saturation.record(now, thrust_saturated(self.controller.state, cmd[2], z.min_output,
                                                              z.max_output))
                if stamp is not None:
                    self._pose_stamp = stamp
                msg.linear.x, msg.linear.y, msg.linear.z, msg.angular.z = cmd
                self.cmd_pub.publish(msg)
                self._remind_no_pose(now)
                if self.stamped_pub.get_num_connections() > 0:
                    stamped = TwistStamped(twist=msg)
                    stamped.header.stamp, stamped.header.frame_id = self._pose_stamp, self.world_frame
                    self.stamped_pub.publish(stamped)
            self._publish_status()
        except rospy.ROSException:
            # a step racing the node's shutdown is not an error: rospy closes the topics
            # before is_shutdown() turns true, so ask whether a shutdown has begun
            if not shutting_down():
                raise

    def _on_diagnostics(self, _event) -> None:
        with self._lock:
            c = self.controller
            pose = c.pose
            now = rospy.get_time()
            level, message, values = controller_entry(
                c.state, c.safety, None if pose is None else max(0.0, now - pose.stamp), c.config.pose_timeout,
                c.last_command[2], self._saturation.share(), self._saturation.steps)
        status = DiagnosticStatus(level=level, name="%s: %s" % (rospy.get_name().lstrip("/"), self.frame),
                                  message=message, hardware_id=self.frame,
                                  values=[KeyValue(k, v) for k, v in values])
        arr = DiagnosticArray(status=[status])
        arr.header.stamp = rospy.Time.now()
        publish_unless_shutting_down(self.diag_pub, arr)

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
        rospy.logwarn("%s: still no pose of %s in %s after %.0f s, take-off is refused; tf knows %s%s. "
                      "Is the motion capture running, and does the frame argument name the tracked body? "
                      "(rosrun crazyflie_demo view_frames prints the tf tree)",
                      node_label(), self.frame, self.world_frame, now - self._no_pose_since, self._known_frames(),
                      " (tf: %s)" % self._last_lookup_error.strip() if self._last_lookup_error else "")

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
            rospy.logwarn_throttle(5.0, "%s: goal ignored: frame %r is not the world frame %r"
                                   % (node_label(), msg.header.frame_id, self.world_frame))
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
        rospy.logfatal("%s: %s", node_label(), e)
        sys.exit(1)
    rospy.spin()
