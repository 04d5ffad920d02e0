"""static_transform_publisher: one fixed transform on /tf_static, with the arguments of tf's tool.

The chapter's launch files attach each vehicle's ``base_link`` to its motion-capture frame this way
(``baselink_broadcaster``) so that rviz can draw the model; tf's own tool is not installed
everywhere, so the launch files use this one. Arguments: ``x y z qx qy qz qw frame child [period_ms]``
or ``x y z yaw pitch roll frame child [period_ms]``; the period is accepted and ignored (a static
transform is latched once, not repeated).
"""
from __future__ import annotations

import math
import sys
from typing import List, Sequence, Tuple

USAGE = ("usage: static_transform_publisher x y z qx qy qz qw frame child [period_ms]\n"
         "   or: static_transform_publisher x y z yaw pitch roll frame child [period_ms]")


def quaternion_from_ypr(yaw: float, pitch: float, roll: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of the rotation yaw about z, then pitch about y, then roll about x (radians)."""
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def parse_args(argv: Sequence[str]) -> Tuple[Tuple[float, float, float], Tuple[float, ...], str, str]:
    """(translation, quaternion, frame, child) from the tool's arguments; ValueError with the usage."""
    args: List[str] = list(argv)
    for n_numbers in (7, 6):            # quaternion form first, as tf's tool decides by count
        if len(args) in (n_numbers + 2, n_numbers + 3):
            try:
                numbers = [float(a) for a in args[:n_numbers]]
                if len(args) == n_numbers + 3:
                    float(args[-1])
            except ValueError:
                continue
            frame, child = args[n_numbers].strip("/"), args[n_numbers + 1].strip("/")
            if not frame or not child:
                raise ValueError("empty frame name\n" + USAGE)
            q = tuple(numbers[3:7]) if n_numbers == 7 else quaternion_from_ypr(*numbers[3:6])
            norm = math.sqrt(sum(c * c for c in q))
            if norm < 1e-9:
                raise ValueError("the quaternion (0, 0, 0, 0) is no rotation\n" + USAGE)
            return (numbers[0], numbers[1], numbers[2]), tuple(c / norm for c in q), frame, child
    raise ValueError("cannot read %r\n%s" % (" ".join(args), USAGE))


def main() -> None:
    import rospy
    import tf2_ros
    from geometry_msgs.msg import TransformStamped

    from crazyflie_driver.nodes.ros_signals import init_node

    argv = rospy.myargv(sys.argv)[1:]
    try:
        translation, q, frame, child = parse_args(argv)
    except ValueError as exc:
        print("static_transform_publisher: %s" % exc, file=sys.stderr)
        raise SystemExit(2) from None
    init_node("static_transform_publisher", anonymous=True)
    t = TransformStamped()
    t.header.stamp = rospy.Time.now()
    t.header.frame_id, t.child_frame_id = frame, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = translation
    t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w = q
    broadcaster = tf2_ros.StaticTransformBroadcaster()
    broadcaster.sendTransform(t)
    rospy.spin()
    del broadcaster
