"""crazyflie_ros HEAD's motion-capture forwarders: ``publish_external_position_vicon.py``,
``publish_external_pose_vicon.py`` and ``publish_external_position_vrpn.py``.

Each reads one motion-capture topic (``~topic``: vicon_bridge's TransformStamped, or vrpn_client's
PoseStamped) and republishes it for the Crazyflie of its namespace: ``external_position``
(PointStamped) or ``external_pose`` (PoseStamped, the orientation too). The first pose seeds the
onboard Kalman filter (``kalman/initialX/Y/Z``, then ``kalman/resetEstimation``) through
``update_params``, as HEAD's scripts do; later poses go out.

Unlike HEAD's scripts, the first pose also sets ``stabilizer/estimator`` to ``~estimator`` (default
2, the Kalman filter; a negative value leaves the firmware's choice). The firmware's automatic
choice on a Crazyflie 2.x without a positioning deck is the complementary estimator, which ignores
external positions, so without this the forwarded poses change nothing onboard (docs/simulation.md,
"Onboard estimator"). A refused parameter update is logged and retried with a later pose, at most
once per RETRY_S; the poses are forwarded meanwhile.
"""
from __future__ import annotations

import time
from typing import Callable, List, Optional, Sequence, Tuple

import rospy
from geometry_msgs.msg import PointStamped, PoseStamped, TransformStamped

from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down
from crazyflie_driver.srv import UpdateParams

Vec3 = Tuple[float, float, float]
Quat = Tuple[float, float, float, float]

#: The Kalman filter's value of ``stabilizer.estimator`` (the firmware's param documentation).
KALMAN_ESTIMATOR = 2
#: s between two attempts to seed the filter after a refused ``update_params``.
RETRY_S = 1.0


def pose_of(msg) -> Tuple[Vec3, Quat]:
    """(position, quaternion x y z w) of a TransformStamped or a PoseStamped."""
    if isinstance(msg, TransformStamped):
        p, q = msg.transform.translation, msg.transform.rotation
    else:
        p, q = msg.pose.position, msg.pose.orientation
    return (p.x, p.y, p.z), (q.x, q.y, q.z, q.w)


def seed_params(position: Vec3, estimator: int) -> List[List[Tuple[str, float]]]:
    """The parameter updates of the first pose, in order, one ``update_params`` call per list:
    the estimator (unless ``estimator`` < 0), the filter's initial position, then its reset."""
    calls: List[List[Tuple[str, float]]] = []
    if estimator >= 0:
        calls.append([("stabilizer/estimator", int(estimator))])
    calls.append([("kalman/initialX", float(position[0])), ("kalman/initialY", float(position[1])),
                  ("kalman/initialZ", float(position[2]))])
    calls.append([("kalman/resetEstimation", 1)])
    return calls


def position_msg(msg, seq: int) -> PointStamped:
    out = PointStamped()
    out.header.seq, out.header.stamp, out.header.frame_id = seq, msg.header.stamp, msg.header.frame_id
    (out.point.x, out.point.y, out.point.z), _ = pose_of(msg)
    return out


def pose_msg(msg, seq: int) -> PoseStamped:
    out = PoseStamped()
    out.header.seq, out.header.stamp, out.header.frame_id = seq, msg.header.stamp, msg.header.frame_id
    p, q = pose_of(msg)
    out.pose.position.x, out.pose.position.y, out.pose.position.z = p
    out.pose.orientation.x, out.pose.orientation.y, out.pose.orientation.z, out.pose.orientation.w = q
    return out


class ExternalPositionForwarder:
    """Seeds the filter from the first pose, then republishes each pose as ``make``'s message."""

    def __init__(self, update_params: Callable[[Sequence[str]], object], publish: Callable[[object], None],
                 make: Callable[[object, int], object], estimator: int = KALMAN_ESTIMATOR,
                 set_param: Callable[[str, object], None] = rospy.set_param,
                 now: Callable[[], float] = time.monotonic) -> None:
        self._update_params, self._publish, self._make = update_params, publish, make
        self._set_param, self._now = set_param, now
        self.estimator = estimator
        self.seeded = False
        self._last_try: Optional[float] = None
        self._seq = 0

    def _seed(self, position: Vec3) -> bool:
        for call in seed_params(position, self.estimator):
            for name, value in call:
                self._set_param(name, value)
            try:
                self._update_params([name for name, _ in call])
            except (rospy.ServiceException, rospy.ROSException) as e:
                rospy.logwarn("update_params %s refused (%s); retrying with a later pose, forwarding poses "
                              "meanwhile", [name for name, _ in call], e)
                return False
        rospy.loginfo("onboard estimator %s, Kalman filter placed at (%.3f, %.3f, %.3f)",
                      self.estimator if self.estimator >= 0 else "unchanged", *position)
        return True

    def on_pose(self, msg) -> None:
        if not self.seeded:
            now = self._now()
            if self._last_try is None or now - self._last_try >= RETRY_S:
                first = self._last_try is None
                self._last_try = now
                self.seeded = self._seed(pose_of(msg)[0])
                if first:
                    return          # HEAD's scripts forward from the second pose on
        self._seq += 1
        self._publish(self._make(msg, self._seq))


def run(node_name: str, default_topic: str, in_type, out_topic: str, out_type, make) -> None:
    """One forwarder node: ``~topic`` (``in_type``) to ``out_topic`` (``out_type``) in the node's namespace."""
    init_node(node_name, anonymous=True)
    topic = rospy.get_param("~topic", default_topic)
    estimator = int(rospy.get_param("~estimator", KALMAN_ESTIMATOR))
    rospy.wait_for_service("update_params")
    rospy.loginfo("found update_params service; forwarding %s to %s", topic, rospy.resolve_name(out_topic))
    pub = rospy.Publisher(out_topic, out_type, queue_size=1)
    forwarder = ExternalPositionForwarder(rospy.ServiceProxy("update_params", UpdateParams),
                                          lambda m: publish_unless_shutting_down(pub, m), make, estimator)
    rospy.Subscriber(topic, in_type, forwarder.on_pose, queue_size=1)
    rospy.spin()


def main() -> None:
    """publish_external_position_vicon.py"""
    run("publish_external_position_vicon", "/vicon/cf/cf", TransformStamped, "external_position", PointStamped,
        position_msg)


def main_pose_vicon() -> None:
    """publish_external_pose_vicon.py"""
    run("publish_external_pose_vicon", "/vicon/cf/cf", TransformStamped, "external_pose", PoseStamped, pose_msg)


def main_position_vrpn() -> None:
    """publish_external_position_vrpn.py"""
    run("publish_external_position_vrpn", "/crazyflie1/vrpn_client_node/crazyflie1/pose", PoseStamped,
        "external_position", PointStamped, position_msg)
