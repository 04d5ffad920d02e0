#!/usr/bin/env python3
"""vrpn_client_node against the fake VRPN server: pose and twist topics with the Y-up stream
converted to Z-up, tf, tracker name cleaning, staleness on /diagnostics, server restart."""
from __future__ import annotations

import math
import sys
import time
import unittest

import rospy
import rostest
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, TwistStamped

from crazyflie_driver.mocap.vrpn_server import VrpnTestServer
from support.rostest_support import TopicRecorder, wait_until

YAW = math.radians(40.0)
TRUTH_Q = (0.0, 0.0, math.sin(YAW / 2), math.cos(YAW / 2))     # Z-up truth, streamed Y-up


class VrpnClientNodeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("vrpn_client_test")
        cls.server = VrpnTestServer(["crazyflie1", "Rigid Body 2"], port=rospy.get_param("~port"),
                                    rate=100, velocity=True, y_up=True)
        cls.server.set_pose("crazyflie1", (0.5, -1.0, 1.25), TRUTH_Q)
        cls.server.set_pose("Rigid Body 2", (-2.0, 0.5, 0.0))
        cls.server.set_velocity("crazyflie1", (0.2, -0.1, 0.3), (0.0, 0.0, math.sin(0.01), math.cos(0.01)), 0.01)
        cls.server.start()
        cls.pose1 = TopicRecorder("/vrpn_client_node/crazyflie1/pose", PoseStamped)
        cls.pose2 = TopicRecorder("/vrpn_client_node/RigidBody2/pose", PoseStamped)
        cls.twist1 = TopicRecorder("/vrpn_client_node/crazyflie1/twist", TwistStamped)
        cls.diag = TopicRecorder("/diagnostics", DiagnosticArray)
        cls.tf_buffer = tf2_ros.Buffer()
        cls.tf_listener = tf2_ros.TransformListener(cls.tf_buffer)
        assert cls.server.wait_for_clients(1, 20.0), "vrpn_client_node never connected"

    @classmethod
    def tearDownClass(cls):
        cls.server.stop()

    def test_1_pose_topics_in_z_up(self):
        self.assertTrue(wait_until(lambda: self.pose1.count() > 20 and self.pose2.count() > 20, 15.0))
        m = self.pose1.latest()
        self.assertEqual(m.header.frame_id, "world")
        self.assertLess(abs((rospy.Time.now() - m.header.stamp).to_sec()), 0.5)   # receive time
        p, q = m.pose.position, m.pose.orientation
        self.assertEqual((p.x, p.y, p.z), (0.5, -1.0, 1.25))
        for got, want in zip((q.x, q.y, q.z, q.w), TRUTH_Q):
            self.assertAlmostEqual(got, want, places=12)
        p2 = self.pose2.latest().pose.position
        self.assertEqual((p2.x, p2.y, p2.z), (-2.0, 0.5, 0.0))
        # every frame the server streams is forwarded: counted against the frames it sent in the
        # window (its own stream's clock), not against wall seconds of a possibly busy machine
        sent0, t0 = self.server.poses_sent, time.monotonic()
        time.sleep(1.0)
        sent, t1 = self.server.poses_sent - sent0, time.monotonic()
        frames = sent / (2.0 * max(1, self.server.client_count()))   # one Pos_Quat per tracker per client
        got = len(self.pose1.between(t0, t1))
        self.assertGreater(frames, 10, "the test server streamed only %d frames in 1 s" % frames)
        self.assertGreater(got, 0.6 * frames, (got, frames))     # ~100 Hz from the server

    def test_2_tf(self):
        t = self.tf_buffer.lookup_transform("world", "crazyflie1", rospy.Time(0), rospy.Duration(10.0))
        tr, r = t.transform.translation, t.transform.rotation
        self.assertEqual((tr.x, tr.y, tr.z), (0.5, -1.0, 1.25))
        self.assertAlmostEqual(2 * math.atan2(r.z, r.w), YAW, places=9)
        t2 = self.tf_buffer.lookup_transform("world", "RigidBody2", rospy.Time(0), rospy.Duration(10.0))
        self.assertEqual(t2.transform.translation.x, -2.0)

    def test_3_twist(self):
        self.assertTrue(wait_until(lambda: self.twist1.count() > 5, 10.0))
        tw = self.twist1.latest().twist
        self.assertAlmostEqual(tw.linear.x, 0.2, places=12)
        self.assertAlmostEqual(tw.linear.y, -0.1, places=12)
        self.assertAlmostEqual(tw.linear.z, 0.3, places=12)
        self.assertAlmostEqual(tw.angular.z, 2.0, places=9)      # 0.02 rad in 0.01 s
        self.assertAlmostEqual(tw.angular.x, 0.0, places=12)

    def _status(self, name):
        latest = self.diag.latest()
        if latest is None:
            return None
        for s in latest.status:
            if s.name == "vrpn_client_node: %s" % name:
                return s
        return None

    def test_4_staleness_on_diagnostics(self):
        self.assertTrue(wait_until(lambda: (self._status("RigidBody2") or DiagnosticStatus(level=9)).level
                                   == DiagnosticStatus.OK, 5.0))
        self.server.hide("Rigid Body 2")
        try:
            self.assertTrue(wait_until(lambda: (self._status("RigidBody2") or DiagnosticStatus()).level
                                       == DiagnosticStatus.STALE, 5.0))
            s = self._status("RigidBody2")
            age = float({kv.key: kv.value for kv in s.values}["age"])
            self.assertGreater(age, 0.1)
            self.assertEqual(self._status("crazyflie1").level, DiagnosticStatus.OK)
            self.assertEqual(self._status("connection").level, DiagnosticStatus.OK)
        finally:
            self.server.hide("Rigid Body 2", False)
        self.assertTrue(wait_until(lambda: self._status("RigidBody2").level == DiagnosticStatus.OK, 5.0))

    def test_5_server_restart(self):
        self.server.stop()
        self.assertTrue(wait_until(lambda: (self._status("connection") or DiagnosticStatus()).level
                                   == DiagnosticStatus.ERROR, 5.0))
        self.server.set_pose("crazyflie1", (1.0, 1.0, 1.0), TRUTH_Q)
        self.server.start()
        self.assertTrue(self.server.wait_for_clients(1, 15.0))
        ok = wait_until(lambda: self.pose1.latest().pose.position.x == 1.0, 10.0)
        self.assertTrue(ok)
        p = self.pose1.latest().pose.position
        self.assertEqual((p.x, p.y, p.z), (1.0, 1.0, 1.0))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "vrpn_client", VrpnClientNodeTest, sys.argv)
