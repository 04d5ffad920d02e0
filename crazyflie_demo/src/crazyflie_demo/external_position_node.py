"""publish_external_position_vicon.py: forwards a motion-capture TransformStamped topic to the
Crazyflie's ``external_position`` (PointStamped), as crazyflie_ros HEAD's demo script does.

The first transform seeds the onboard Kalman filter (``kalman/initialX/Y/Z``, then
``kalman/resetEstimation``) through ``update_params``, so the estimate starts where the Crazyflie is;
every later transform goes out as a position. A refused parameter update is logged, not fatal: the
positions still flow and the filter converges on them.
"""
from __future__ import annotations

from typing import List

import rospy
from geometry_msgs.msg import PointStamped, TransformStamped

from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down
from crazyflie_driver.srv import UpdateParams


class ExternalPositionForwarder:
    """Seeds the filter on the first transform, then republishes each one as a PointStamped."""

    def __init__(self, update_params: rospy.ServiceProxy, pub: rospy.Publisher) -> None:
        self._update_params = update_params
        self._pub = pub
        self._seeded = False
        self._seq = 0

    def _update(self, names: List[str]) -> None:
        try:
            self._update_params(names)
        except (rospy.ServiceException, rospy.ROSException) as e:
            rospy.logwarn("update_params %s failed (%s); forwarding positions anyway", names, e)

    def on_transform(self, t: TransformStamped) -> None:
        p = t.transform.translation
        if not self._seeded:
            for axis, value in (("X", p.x), ("Y", p.y), ("Z", p.z)):
                rospy.set_param("kalman/initial" + axis, float(value))
            self._update(["kalman/initialX", "kalman/initialY", "kalman/initialZ"])
            rospy.set_param("kalman/resetEstimation", 1)
            self._update(["kalman/resetEstimation"])
            self._seeded = True
            return
        msg = PointStamped()
        self._seq += 1
        msg.header.seq = self._seq
        msg.header.stamp = t.header.stamp
        msg.header.frame_id = t.header.frame_id
        msg.point.x, msg.point.y, msg.point.z = p.x, p.y, p.z
        publish_unless_shutting_down(self._pub, msg)


def main() -> None:
    init_node("publish_external_position_vicon", anonymous=True)
    topic = rospy.get_param("~topic", "/vicon/cf/cf")
    rospy.wait_for_service("update_params")
    rospy.loginfo("found update_params service; forwarding %s to external_position", topic)
    forwarder = ExternalPositionForwarder(rospy.ServiceProxy("update_params", UpdateParams),
                                          rospy.Publisher("external_position", PointStamped, queue_size=1))
    rospy.Subscriber(topic, TransformStamped, forwarder.on_transform, queue_size=1)
    rospy.spin()
