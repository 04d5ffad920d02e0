#!/usr/bin/env python3
"""The onboard high-level commander through crazyflie_server's HEAD services, checked on the world's
truth: takeoff, go_to, land of one Crazyflie, an uploaded trajectory flown relative to where it
starts, and a takeoff after cmd_vel (the firmware's priority trap, handled by the server). A host-side
mocap loop feeds the world's true position to ``external_position``."""
from __future__ import annotations

import math
import sys
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import PointStamped, Twist

from crazyflie_driver.msg import TrajectoryPolynomialPiece
from crazyflie_driver.srv import GoTo, Land, StartTrajectory, Takeoff, UpdateParams, UploadTrajectory
from support.rostest_support import Repeating, start_test_node, wait_connected, wait_until

NS = "/crazyflie1"
MOCAP_PERIOD_S = 0.02
TRAJECTORY_S = 3.0
TRAJECTORY_DX = 0.6


TRAJECTORY_DZ = 0.2


def min_jerk(distance: float, duration: float):
    """x(t) = distance * (10 s^3 - 15 s^4 + 6 s^5), s = t / duration: from rest to rest."""
    return [0.0, 0.0, 0.0, 10 * distance / duration ** 3, -15 * distance / duration ** 4,
            6 * distance / duration ** 5, 0.0, 0.0]


def bump(height: float, duration: float):
    """z(t) = 16 height s^2 (1 - s)^2: up by ``height`` halfway, back at the end."""
    k = 16 * height
    return [0.0, 0.0, k / duration ** 2, -2 * k / duration ** 3, k / duration ** 4, 0.0, 0.0, 0.0]


def planned(t: float):
    """(dx, dz) of the trajectory at ``t`` s after its start (held at the end)."""
    s = min(max(t / TRAJECTORY_S, 0.0), 1.0)
    return (TRAJECTORY_DX * (10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5), 16 * TRAJECTORY_DZ * s * s * (1 - s) ** 2)


class HighLevelApi(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("high_level_api_test", ["crazyflie1"])
        cls.uri = rospy.get_param("~uri")
        for s in ("takeoff", "land", "go_to", "upload_trajectory", "start_trajectory"):
            rospy.wait_for_service(NS + "/" + s, 10.0)
        rospy.set_param(NS + "/stabilizer/estimator", 2)
        rospy.ServiceProxy(NS + "/update_params", UpdateParams)(["stabilizer/estimator"])
        cls.mocap = rospy.Publisher(NS + "/external_position", PointStamped, queue_size=1)
        wait_connected([cls.mocap], 5.0)
        cls.mocap_stream = Repeating(cls.send_truth, MOCAP_PERIOD_S)

    @classmethod
    def tearDownClass(cls):
        cls.mocap_stream.stop()

    @classmethod
    def truth(cls):
        return cls.world.control("vehicle_state", uri=cls.uri)["position"]

    @classmethod
    def timed_truth(cls):
        """(world time s, true position) from one snapshot: the clock the firmware flies by."""
        state = cls.world.control("vehicle_state", uri=cls.uri)
        return state["time"], state["position"]

    @classmethod
    def send_truth(cls):
        point = PointStamped()
        point.point.x, point.point.y, point.point.z = cls.truth()
        cls.mocap.publish(point)

    def reaches(self, goal, tolerance=0.05, timeout=10.0):
        return wait_until(lambda: math.dist(self.truth(), goal) < tolerance, timeout)

    def test_a_takeoff_go_to_land(self):
        start = self.truth()
        rospy.ServiceProxy(NS + "/takeoff", Takeoff)(groupMask=0, height=0.5, duration=rospy.Duration(2.0))
        self.assertTrue(self.reaches((start[0], start[1], 0.5)), self.truth())
        go_to = rospy.ServiceProxy(NS + "/go_to", GoTo)
        req = GoTo._request_class(groupMask=0, relative=False, yaw=0.0, duration=rospy.Duration(2.0))
        req.goal.x, req.goal.y, req.goal.z = start[0] + 0.4, start[1] - 0.3, 0.7
        go_to(req)
        self.assertTrue(self.reaches((start[0] + 0.4, start[1] - 0.3, 0.7)), self.truth())
        req = GoTo._request_class(groupMask=0, relative=True, yaw=0.0, duration=rospy.Duration(1.5))
        req.goal.x, req.goal.y, req.goal.z = -0.4, 0.3, -0.2
        go_to(req)
        self.assertTrue(self.reaches((start[0], start[1], 0.5)), self.truth())
        rospy.ServiceProxy(NS + "/land", Land)(groupMask=0, height=0.0, duration=rospy.Duration(2.5))
        self.assertTrue(wait_until(lambda: self.truth()[2] < 0.03, 10.0), self.truth())
        motors = lambda: self.world.control("vehicle_state", uri=self.uri)["motors"]
        self.assertTrue(wait_until(lambda: not any(motors()), 5.0), motors())

    def test_b_uploaded_trajectory_flown_relative_to_the_start(self):
        # Tracking a trajectory needs the feed-forward of the Mellinger controller (the PID position
        # controller ignores the planned velocity and acceleration and lags), as swarms fly it.
        rospy.set_param(NS + "/stabilizer/controller", 2)
        rospy.ServiceProxy(NS + "/update_params", UpdateParams)(["stabilizer/controller"])
        ground = self.truth()
        rospy.ServiceProxy(NS + "/takeoff", Takeoff)(groupMask=0, height=0.5, duration=rospy.Duration(2.0))
        # A relative trajectory starts at the planner's last setpoint: the takeoff's end point.
        start = (ground[0], ground[1], 0.5)
        self.assertTrue(self.reaches(start, tolerance=0.02), self.truth())
        piece = TrajectoryPolynomialPiece(poly_x=min_jerk(TRAJECTORY_DX, TRAJECTORY_S), poly_y=[0.0] * 8,
                                          poly_z=bump(TRAJECTORY_DZ, TRAJECTORY_S), poly_yaw=[0.0] * 8,
                                          duration=rospy.Duration(TRAJECTORY_S))
        rospy.ServiceProxy(NS + "/upload_trajectory", UploadTrajectory)(trajectoryId=3, pieceOffset=0, pieces=[piece])
        before, _ = self.timed_truth()
        rospy.ServiceProxy(NS + "/start_trajectory", StartTrajectory)(groupMask=0, trajectoryId=3, timescale=1.0,
                                                                       reversed=False, relative=True)
        after, _ = self.timed_truth()
        path = []
        while not path or path[-1][0] - after < TRAJECTORY_S + 1.0:
            path.append(self.timed_truth())
            time.sleep(0.05)
        # The trajectory started between ``before`` and ``after`` (world time, bracketing the service
        # call); each true position is compared with the plan over that window.
        def error(t, p):
            return min(math.dist((p[0] - start[0], p[2] - start[2]), planned(t - t0))
                       for t0 in (before, (before + after) / 2, after))
        worst = max(error(t, p) for t, p in path)
        max_speed = 1.875 * TRAJECTORY_DX / TRAJECTORY_S      # of the min-jerk profile, m/s
        self.assertLess(worst, 0.05 + max_speed * (after - before) / 2, path)
        self.assertGreater(max(p[2] for _, p in path) - start[2], TRAJECTORY_DZ - 0.05)
        self.assertLess(math.dist(path[-1][1], (start[0] + TRAJECTORY_DX, start[1], start[2])), 0.05, path[-1])
        self.assertLess(max(abs(p[1] - start[1]) for _, p in path), 0.05)
        rospy.ServiceProxy(NS + "/land", Land)(groupMask=0, height=0.0, duration=rospy.Duration(2.5))
        self.assertTrue(wait_until(lambda: self.truth()[2] < 0.03, 10.0), self.truth())

    def test_c_takeoff_after_cmd_vel_flies(self):
        """cmd_vel's RPYT setpoints take the firmware's priority back from the high-level commander;
        the takeoff service must hand it over again (notify-setpoints-stop) or the takeoff never flies."""
        ports = lambda: self.world.crazyflie_state(self.uri)["packets_by_port"]
        before = int(ports().get("3", 0))
        cmd_vel = rospy.Publisher(NS + "/cmd_vel", Twist, queue_size=1)
        wait_connected([cmd_vel], 5.0)
        sent = Repeating(lambda: cmd_vel.publish(Twist()), 0.02)           # thrust 0: stays on the floor
        try:
            self.assertTrue(wait_until(lambda: int(ports().get("3", 0)) >= before + 10, 10.0), ports())
        finally:
            sent.stop()
            cmd_vel.unregister()
        ground = self.truth()
        rospy.ServiceProxy(NS + "/takeoff", Takeoff)(groupMask=0, height=0.5, duration=rospy.Duration(2.0))
        self.assertTrue(self.reaches((ground[0], ground[1], 0.5)), self.truth())
        rospy.ServiceProxy(NS + "/land", Land)(groupMask=0, height=0.0, duration=rospy.Duration(2.5))
        self.assertTrue(wait_until(lambda: self.truth()[2] < 0.03, 10.0), self.truth())


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "high_level_api", HighLevelApi, sys.argv)
