#!/usr/bin/env python3
"""Three Crazyflies, two dongles: every one served at full rate, each cmd_vel reaches only its own."""
from __future__ import annotations

import sys
import time
import unittest

import rospy
import rostest
import tf2_ros
from geometry_msgs.msg import Twist
from sensor_msgs.msg import Imu

from support.rostest_support import TopicRecorder, rates_per_world_second, start_test_node, wait_connected, wait_until

CRAZYFLIES = {"crazyflie1": "radio://0/80/2M/E7E7E7E701", "crazyflie2": "radio://0/80/2M/E7E7E7E702",
              "crazyflie3": "radio://1/90/2M/E7E7E7E703"}


class DriverMulti(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("driver_multi_test", CRAZYFLIES)
        cls.imu = {n: TopicRecorder("/%s/imu" % n, Imu) for n in CRAZYFLIES}
        cls.cmd = {n: rospy.Publisher("/%s/cmd_vel" % n, Twist, queue_size=1) for n in CRAZYFLIES}
        wait_connected(list(cls.cmd.values()), 10.0)

    def test_a_every_crazyflie_publishes_imu_at_100hz(self):
        rates = rates_per_world_second(self.imu, self.world, 3.0)     # per second of the firmware's clock
        for name, rec in self.imu.items():
            rate = rates[name]
            self.assertGreater(rate, 85.0, (name, rates))
            self.assertLess(rate, 115.0, name)
            self.assertEqual(rec.latest().header.frame_id, "%s/base_link" % name)

    def test_b_parameters_mirrored_per_crazyflie(self):
        for name in CRAZYFLIES:
            self.assertTrue(rospy.has_param("/%s/ring/headlightEnable" % name), name)

    def test_c_each_cmd_vel_reaches_only_its_crazyflie(self):
        thrusts = {"crazyflie1": 11000, "crazyflie2": 12000, "crazyflie3": 13000}
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            for name, pub in self.cmd.items():
                t = Twist()
                t.linear.z = thrusts[name]
                pub.publish(t)
            time.sleep(0.02)
        for name, uri in CRAZYFLIES.items():
            got = wait_until(lambda: self.world.crazyflie_state(uri)["last_setpoint"][3] == thrusts[name], 2.0)
            self.assertTrue(got, "%s: %r" % (name, self.world.crazyflie_state(uri)["last_setpoint"]))
        for pub in self.cmd.values():
            pub.publish(Twist())

    def test_d_vicon_frames_for_every_vehicle(self):
        buf = tf2_ros.Buffer()
        tf2_ros.TransformListener(buf)
        for name in CRAZYFLIES:
            t = buf.lookup_transform("world", "vicon/%s/%s" % (name, name), rospy.Time(0), rospy.Duration(3.0))
            if name == "crazyflie2":
                self.assertAlmostEqual(t.transform.translation.y, -0.75, delta=0.05)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "driver_multi", DriverMulti, sys.argv)
