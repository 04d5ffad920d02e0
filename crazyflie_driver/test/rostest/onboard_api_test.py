#!/usr/bin/env python3
"""crazyflie_ros HEAD's per-Crazyflie API behind crazyflie_server: the setpoint topics reach the
simulated Crazyflie as the right port-7 types, mocap reaches port 6, and bad service requests get
a clear error while the server keeps serving."""
from __future__ import annotations

import math
import sys
import time
import unittest

import rospy
import rosservice
import rostest
from geometry_msgs.msg import PointStamped, PoseStamped
from std_msgs.msg import Empty as EmptyMsg

from crazyflie_driver.msg import FullState, GenericLogData, Hover, Position, TrajectoryPolynomialPiece, VelocityWorld
from crazyflie_driver.srv import GoTo, StartTrajectory, UpdateParams, UploadTrajectory
from support.rostest_support import TopicRecorder, start_test_node, wait_until

NS = "/crazyflie1"
SERVICES = {"takeoff": "Takeoff", "land": "Land", "stop": "Stop", "go_to": "GoTo",
            "upload_trajectory": "UploadTrajectory", "start_trajectory": "StartTrajectory",
            "set_group_mask": "SetGroupMask", "notify_setpoints_stop": "NotifySetpointsStop"}


class OnboardApi(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("onboard_api_test", ["crazyflie1"])
        cls.uri = rospy.get_param("~uri")
        for s in SERVICES:
            rospy.wait_for_service(NS + "/" + s, 10.0)
        cls.locsrv = TopicRecorder(NS + "/locsrv", GenericLogData)
        cls.estimate = TopicRecorder(NS + "/estimate", GenericLogData)

    def state(self):
        return self.world.crazyflie_state(self.uri)

    def port_count(self, port: int) -> int:
        return int(self.state()["packets_by_port"].get(str(port), 0))

    def publish_until(self, topic: str, kind, msg, done, timeout: float = 5.0):
        pub = rospy.Publisher(NS + "/" + topic, kind, queue_size=1)
        wait_until(lambda: pub.get_num_connections() > 0, 5.0)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            pub.publish(msg)
            if done():
                pub.unregister()
                return True
            time.sleep(0.02)
        pub.unregister()
        return False

    def test_a_services_have_head_types(self):
        for name, kind in SERVICES.items():
            self.assertEqual(rosservice.get_service_type(NS + "/" + name), "crazyflie_driver/" + kind)

    def test_b_setpoint_topics_arrive_as_their_port_7_types(self):
        position = Position(x=0.0, y=0.0, z=0.0, yaw=0.0)
        hover = Hover(vx=0.0, vy=0.0, yawrate=0.0, zDistance=0.0)
        velocity = VelocityWorld()
        full = FullState()
        full.pose.orientation.w = 1.0
        for topic, kind, msg, wire_type in (("cmd_position", Position, position, 7), ("cmd_hover", Hover, hover, 10),
                                            ("cmd_velocity_world", VelocityWorld, velocity, 8),
                                            ("cmd_full_state", FullState, full, 6),
                                            ("cmd_stop", EmptyMsg, EmptyMsg(), 0)):
            before = self.port_count(7)
            arrived = self.publish_until(topic, kind, msg, lambda: self.state()["last_generic_type"] == wire_type
                                         and self.port_count(7) > before)
            self.assertTrue(arrived, "%s did not arrive as type %d: %s" % (topic, wire_type, self.state()))

    def test_c_motion_capture_topics_reach_port_6(self):
        pose = PoseStamped()
        pose.pose.position.x, pose.pose.orientation.w = 0.1, 1.0
        before = self.port_count(6)
        self.assertTrue(self.publish_until("external_pose", PoseStamped, pose, lambda: self.port_count(6) > before))
        point = PointStamped()
        before = self.port_count(6)
        self.assertTrue(self.publish_until("external_position", PointStamped, point,
                                           lambda: self.port_count(6) > before))

    def test_d_bad_requests_get_clear_errors_and_the_server_keeps_serving(self):
        upload = rospy.ServiceProxy(NS + "/upload_trajectory", UploadTrajectory)
        piece = TrajectoryPolynomialPiece(poly_x=[0.0] * 8, poly_y=[0.0] * 7, poly_z=[0.5] + [0.0] * 7,
                                          poly_yaw=[0.0] * 8, duration=rospy.Duration(1.0))
        with self.assertRaisesRegex(rospy.ServiceException, "piece 0: y has 7 coefficients"):
            upload(trajectoryId=1, pieceOffset=0, pieces=[piece])
        go_to = rospy.ServiceProxy(NS + "/go_to", GoTo)
        req = GoTo._request_class(groupMask=0, relative=False, yaw=0.0, duration=rospy.Duration(2.0))
        req.goal.x, req.goal.y, req.goal.z = math.nan, 0.0, 1.0
        with self.assertRaisesRegex(rospy.ServiceException, "goal x must be a finite number"):
            go_to(req)
        start = rospy.ServiceProxy(NS + "/start_trajectory", StartTrajectory)
        with self.assertRaisesRegex(rospy.ServiceException, "trajectory 9 was not uploaded"):
            start(groupMask=0, trajectoryId=9, timescale=1.0, reversed=False, relative=True)
        with self.assertRaisesRegex(rospy.ServiceException, "trajectory id must be an integer 0..30"):
            start(groupMask=0, trajectoryId=31, timescale=1.0, reversed=False, relative=True)
        self.assertFalse(self.state()["emergency"])
        for name in SERVICES:   # still served
            rospy.wait_for_service(NS + "/" + name, 2.0)

    def truth(self):
        return self.world.control("vehicle_state", uri=self.uri)["position"]

    def test_e_external_pose_reaches_the_onboard_estimator(self):
        rospy.set_param(NS + "/stabilizer/estimator", 2)
        rospy.ServiceProxy(NS + "/update_params", UpdateParams)(["stabilizer/estimator"])
        pose = PoseStamped()
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = 0.12, -0.34, 0.05
        pose.pose.orientation.w = 1.0
        def seen():
            m = self.locsrv.latest()
            return m is not None and all(abs(a - b) < 1e-4 for a, b in zip(m.values, (0.12, -0.34, 0.05)))
        self.assertTrue(self.publish_until("external_pose", PoseStamped, pose, seen), self.locsrv.latest())

    def test_f_cmd_position_flies_on_mocap_from_the_host(self):
        """A host-side mocap loop: the world's true position into external_position, cmd_position to
        0.5 m above the start; the Crazyflie holds it on its onboard estimator and controller."""
        rospy.set_param(NS + "/stabilizer/estimator", 2)
        rospy.ServiceProxy(NS + "/update_params", UpdateParams)(["stabilizer/estimator"])
        start = self.truth()
        goal = (start[0], start[1], 0.5)
        mocap = rospy.Publisher(NS + "/external_position", PointStamped, queue_size=1)
        setpoint = rospy.Publisher(NS + "/cmd_position", Position, queue_size=1)
        wait_until(lambda: mocap.get_num_connections() > 0 and setpoint.get_num_connections() > 0, 5.0)
        errors = []
        end = time.monotonic() + 12.0
        while time.monotonic() < end:
            p = self.truth()
            point = PointStamped()
            point.point.x, point.point.y, point.point.z = p
            mocap.publish(point)
            setpoint.publish(Position(x=goal[0], y=goal[1], z=goal[2], yaw=0.0))
            errors.append(math.dist(p, goal))
            if len(errors) > 50 and max(errors[-50:]) < 0.05:
                break
            time.sleep(0.02)
        self.assertLess(max(errors[-50:]), 0.05, "last positions %s" % (self.truth(),))
        est = self.estimate.latest().values
        self.assertLess(math.dist(est, self.truth()), 0.05)
        stop = rospy.Publisher(NS + "/cmd_stop", EmptyMsg, queue_size=1)
        wait_until(lambda: stop.get_num_connections() > 0, 5.0)
        stop.publish(EmptyMsg())
        self.assertTrue(wait_until(lambda: self.state()["last_generic_type"] == 0, 5.0))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "onboard_api", OnboardApi, sys.argv)
