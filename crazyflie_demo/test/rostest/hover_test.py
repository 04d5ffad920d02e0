#!/usr/bin/env python3
"""Hover launch files in the simulator: each vehicle takes off by itself and holds its point.

Private params: ``sim_address``; ``vehicles`` = [{name, target: [x, y, z]}] (name = the world's
vehicle = the launch file's namespace); ``rms_bound`` / ``max_bound`` (m) on the hold error over
``measure_s`` seconds after ``settle_s`` seconds near the target (seconds of world time: the
flight's own clock); ``mocap`` (vicon|vrpn): the motion-capture names the poses must come through;
a vehicle's optional ``frame`` is the tf frame its vicon pose must come under (the launch file's
``frame`` argument); ``no_pose_node``: a node (a controller whose frame nobody publishes) that must
keep saying it has no pose, at least twice.
Throughout, it records /tf: no motion-capture child frame may get two transforms with the same (or
an older) stamp (tf2's TF_REPEATED_DATA), and the world's real-time status must be on /diagnostics.
"""
from __future__ import annotations

import sys
import unittest

import rospy
import rostest
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TransformStamped
from rosgraph_msgs.msg import Log
from tf2_msgs.msg import TFMessage

from support.flight_support import WorldProbe, hold_errors, wait_until


class Hover(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("hover_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.vehicles = rospy.get_param("~vehicles")
        cls.probe.wait_ready([v["name"] for v in cls.vehicles])
        cls.mocap = rospy.get_param("~mocap", "vicon")
        cls.rms_bound = float(rospy.get_param("~rms_bound"))
        cls.max_bound = float(rospy.get_param("~max_bound"))
        cls.settle_s = float(rospy.get_param("~settle_s", 5.0))
        cls.measure_s = float(rospy.get_param("~measure_s", 5.0))
        cls.tf = tf2_ros.Buffer()
        cls.listener = tf2_ros.TransformListener(cls.tf)
        cls.last_stamp, cls.tf_count, cls.repeated = {}, {}, []
        cls.world_status = None
        cls.tf_sub = rospy.Subscriber("/tf", TFMessage, cls._on_tf, queue_size=1000)
        cls.diag_sub = rospy.Subscriber("/diagnostics", DiagnosticArray, cls._on_diagnostics, queue_size=10)
        cls.no_pose_node = rospy.get_param("~no_pose_node", "")
        cls.no_pose_said = []
        rospy.Subscriber("/rosout", Log, cls._on_log, queue_size=100)

    @classmethod
    def _on_tf(cls, msg):
        for t in msg.transforms:
            child, ns = t.child_frame_id, t.header.stamp.to_nsec()
            last = cls.last_stamp.get(child)
            if last is not None and ns <= last:
                cls.repeated.append((child, last, ns))
            cls.last_stamp[child] = ns
            cls.tf_count[child] = cls.tf_count.get(child, 0) + 1

    @classmethod
    def _on_diagnostics(cls, msg):
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            if "real-time factor" in values:
                cls.world_status = (st, values)

    def mocap_frame(self, name):
        if self.mocap != "vicon":
            return name
        frames = {v["name"]: v.get("frame") for v in self.vehicles}
        return frames.get(name) or "vicon/%s/%s" % (name, name)

    @classmethod
    def _on_log(cls, msg):
        if msg.name == cls.no_pose_node and "still no pose" in msg.msg:
            cls.no_pose_said.append(msg.msg)

    def test_a_poses_come_through_the_motion_capture_names(self):
        for v in self.vehicles:
            name = v["name"]
            if self.mocap == "vicon":
                frame = v.get("frame", "vicon/%s/%s" % (name, name))
                msg = rospy.wait_for_message("/vicon/%s/%s" % (name, name), TransformStamped, timeout=20.0)
                self.assertEqual(msg.child_frame_id, frame)
            else:
                msg = rospy.wait_for_message("/vrpn_client_node/%s/pose" % name, PoseStamped, timeout=20.0)
                self.assertEqual(msg.header.frame_id, "world")
                frame = name
            t = self.tf.lookup_transform("world", frame, rospy.Time(0), rospy.Duration(5.0))
            true = self.probe.position(name)
            self.assertAlmostEqual(t.transform.translation.x, true[0], delta=0.05)
            self.assertAlmostEqual(t.transform.translation.y, true[1], delta=0.05)

    def test_b_each_vehicle_takes_off_and_holds_its_point(self):
        names = [v["name"] for v in self.vehicles]
        targets = {v["name"]: tuple(float(c) for c in v["target"]) for v in self.vehicles}
        w0 = self.probe.clock.now()
        for n in names:
            reached = self.probe.wait_near(n, targets[n], 0.05, 40.0 - (self.probe.clock.now() - w0))
            self.assertTrue(reached, "%s never came within 5 cm of %s (it is at %s)"
                            % (n, targets[n], self.probe.position(n)))
        rospy.loginfo("all within 5 cm after %.1f s of world time", self.probe.clock.now() - w0)
        self.probe.sleep(self.settle_s)
        samples = self.probe.sample(names, self.measure_s, period=0.02)
        for n in names:
            rms, worst = hold_errors(samples[n], targets[n])
            rospy.loginfo("%s hold error over %.0f s: RMS %.4f m, max %.4f m (%d samples)",
                          n, self.measure_s, rms, worst, len(samples[n]))
            print("HOVER %s rms=%.4f max=%.4f samples=%d" % (n, rms, worst, len(samples[n])))
            self.assertLess(rms, self.rms_bound, n)
            self.assertLess(worst, self.max_bound, n)
            self.assertFalse(self.probe.state(n)["on_ground"])

    def test_c_no_repeated_tf_stamps_and_the_world_reports_its_real_time_factor(self):
        for v in self.vehicles:
            frame = self.mocap_frame(v["name"])
            self.assertGreater(self.tf_count.get(frame, 0), 100, "too few transforms of %s on /tf" % frame)
        self.assertEqual(self.repeated[:5], [], "%d transforms with a stamp not after the previous one of their "
                         "frame (TF_REPEATED_DATA)" % len(self.repeated))
        self.assertTrue(wait_until(lambda: self.world_status is not None, 5.0), "no world status on /diagnostics")
        status, values = self.world_status
        self.assertEqual(int(values["vehicles"]), len(self.vehicles))
        self.assertGreater(float(values["real-time factor"]), 0.0)
        print("WORLD %s: %s" % (status.message, values))

    def test_d_a_controller_without_pose_keeps_saying_so(self):
        if not self.no_pose_node:
            self.skipTest("no ~no_pose_node in this launch")
        said = wait_until(lambda: len(self.no_pose_said) >= 2, 15.0, 0.2)
        self.assertTrue(said, "%s said 'still no pose' %d times" % (self.no_pose_node, len(self.no_pose_said)))
        print("NO_POSE %s: %s" % (self.no_pose_node, self.no_pose_said[-1]))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "hover", Hover, sys.argv)
