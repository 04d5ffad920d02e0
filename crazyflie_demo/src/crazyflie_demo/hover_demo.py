"""crazyflie_ros HEAD's ``Hover.py``: two Crazyflies (``cf1``, ``cf2``) fly the same plan at once on
``cmd_hover`` (body-frame velocity, absolute height) at 10 Hz: take off to 0.4 m, move 0.4 m forward
and 0.1 m left while descending to 0.2 m, land, stop.

The plan is HEAD's ``handler``: ``takeOff(0.4)``, ``goTo(0.4, 0.1, 0.2, 0)``, ``land()``. Its parts,
as HEAD's ``Crazyflie`` class names them:

* ``takeOff(z)``: the height target rises by 0.04 m per step up to ``z``, then holds 2 s;
* ``goTo(x, y, z, yaw)``: (x, y) relative, z absolute; every axis moves at most SPEED and all end
  together; the height target moves linearly to ``z`` over the same time (HEAD jumped down at once
  and climbed at a rate that ignored the duration);
* ``land()``: the height target descends at LAND_SPEED to 0, then ``cmd_stop``. HEAD's descended in
  0.2 m steps and then spun in a loop that never published the stop, leaving the firmware's setpoint
  watchdog to cut the motors.

Hover setpoints need an onboard velocity and height estimate: on hardware a Flow deck (v2), whose
driver selects the Kalman estimator. ``kalman/resetEstimation`` is set at start, as HEAD does.
"""
from __future__ import annotations

import math
import threading
from typing import Callable, Iterator, List, Tuple

import rospy
from std_msgs.msg import Empty

from crazyflie_driver.msg import Hover
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down, shutting_down
from crazyflie_driver.srv import UpdateParams

RATE_HZ = 10.0
STOP_FLUSH_S = 0.5   # s (ROS time) the node stays after its cmd_stop, so the message leaves
SPEED = 0.1           # m/s, HEAD's speed on the longest axis of a goTo
TAKEOFF_STEP = 0.04   # m per step of the take-off ramp (HEAD: y / 25.0)
TAKEOFF_HOLD_STEPS = 20
LAND_SPEED = 0.2      # m/s
PREFIXES = ("cf1", "cf2")

Step = Tuple[float, float, float]   # vx, vy (m/s, body frame), zDistance (m)


def takeoff_steps(z: float) -> List[Step]:
    """HEAD's ramp (1 + int(10 z / 0.4) steps of 0.04 m from 0) then 2 s at ``z``."""
    ramp = [(0.0, 0.0, min(k * TAKEOFF_STEP, z)) for k in range(1 + int(10 * z / 0.4))]
    return ramp + [(0.0, 0.0, z)] * TAKEOFF_HOLD_STEPS


def goto_steps(x: float, y: float, z_from: float, z_to: float) -> List[Step]:
    """Velocity steps that move (x, y) in the body frame and the height to ``z_to``, all together, the
    longest axis at SPEED."""
    duration = max(abs(x), abs(y), abs(z_to - z_from)) / SPEED
    n = int(math.ceil(duration * RATE_HZ - 1e-9))
    if n == 0:
        return []
    vx, vy = x / duration, y / duration
    return [(vx, vy, z_from + (z_to - z_from) * (k + 1) / n) for k in range(n)]


def land_steps(z_from: float) -> List[Step]:
    n = int(math.ceil(z_from / (LAND_SPEED / RATE_HZ) - 1e-9))
    return [(0.0, 0.0, z_from * (1.0 - (k + 1) / n)) for k in range(n)] if n > 0 else []


class Crazyflie:
    """HEAD's per-Crazyflie helper of Hover.py: ``prefix``'s ``cmd_hover`` and ``cmd_stop``."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix
        self.rate = rospy.Rate(RATE_HZ)
        rospy.wait_for_service(prefix + "/update_params")
        rospy.loginfo("found %s/update_params service", prefix)
        self.update_params = rospy.ServiceProxy(prefix + "/update_params", UpdateParams)
        self.setParam("kalman/resetEstimation", 1)
        self.pub = rospy.Publisher(prefix + "/cmd_hover", Hover, queue_size=1)
        self.stop_pub = rospy.Publisher(prefix + "/cmd_stop", Empty, queue_size=1)
        self.msg = Hover()
        self.msg.header.frame_id = rospy.get_param("~worldFrame", "/world")

    def setParam(self, name: str, value) -> None:  # noqa: N802 (HEAD's name)
        rospy.set_param(self.prefix + "/" + name, value)
        self.update_params([name])

    def _fly(self, steps: Iterator[Step]) -> None:
        for vx, vy, z in steps:
            if shutting_down():
                return
            self.msg.vx, self.msg.vy, self.msg.yawrate, self.msg.zDistance = vx, vy, 0.0, z
            self.msg.header.seq += 1
            self.msg.header.stamp = rospy.Time.now()
            publish_unless_shutting_down(self.pub, self.msg)
            self.rate.sleep()

    def takeOff(self, zDistance: float) -> None:  # noqa: N802,N803
        self._fly(iter(takeoff_steps(zDistance)))

    def goTo(self, x: float, y: float, zDistance: float, yaw: float) -> None:  # noqa: N802,N803
        """(x, y) relative in the body frame, ``zDistance`` absolute; ``yaw`` is ignored, as in HEAD."""
        self._fly(iter(goto_steps(x, y, self.msg.zDistance, zDistance)))

    def land(self) -> None:
        self._fly(iter(land_steps(self.msg.zDistance)))
        if not shutting_down():
            publish_unless_shutting_down(self.stop_pub, Empty())
            rospy.sleep(STOP_FLUSH_S)    # the stop leaves before the node does


def handler(cf: Crazyflie) -> None:
    """HEAD's flight plan for each Crazyflie."""
    try:
        cf.takeOff(0.4)
        cf.goTo(0.4, 0.1, 0.2, 0)
        cf.land()
    except rospy.ROSInterruptException:
        pass


def fly_all(prefixes, make: Callable[[str], Crazyflie] = Crazyflie) -> None:
    crazyflies = [make(p) for p in prefixes]
    threads = [threading.Thread(target=handler, args=(cf,), name=cf.prefix) for cf in crazyflies]
    for t in threads:
        t.start()
    for t in threads:
        t.join()


def main() -> None:
    init_node("hover", anonymous=True)
    try:
        fly_all(PREFIXES)
    except (rospy.ROSInterruptException, rospy.ServiceException) as e:
        if not shutting_down():
            rospy.logerr("Hover.py: %s", e)
