#!/usr/bin/env python3
"""robot_state_publisher, fed by our launch files, puts every frame of two prefixed models on tf."""
from __future__ import annotations

import math
import sys
import unittest

import rospy
import rostest
import tf2_ros

ARMS = {"cf1": 0.046, "cf2": 0.045}           # Crazyflie 2.0 and 1.0, centre to motor
MOTORS = {1: (1, -1), 2: (-1, -1), 3: (-1, 1), 4: (1, 1)}


class Description(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("description_test")
        cls.buffer = tf2_ros.Buffer()
        cls.listener = tf2_ros.TransformListener(cls.buffer)

    def lookup(self, parent: str, child: str):
        t = self.buffer.lookup_transform(parent, child, rospy.Time(0), rospy.Duration(15.0))
        return t.transform.translation

    def test_motor_frames_of_both_vehicles(self):
        for prefix, arm in ARMS.items():
            d = arm / math.sqrt(2)
            for n, (sx, sy) in MOTORS.items():
                p = self.lookup(prefix + "/base_link", "%s/m%d" % (prefix, n))
                self.assertAlmostEqual(p.x, sx * d, places=6, msg="%s m%d" % (prefix, n))
                self.assertAlmostEqual(p.y, sy * d, places=6, msg="%s m%d" % (prefix, n))
                prop = self.lookup(prefix + "/base_link", "%s/prop%d" % (prefix, n))
                self.assertGreater(prop.z, 0.0)
            self.lookup(prefix + "/base_link", prefix + "/center_of_mass")

    def test_robot_descriptions_are_per_namespace(self):
        self.assertIn('name="cf1/base_link"', rospy.get_param("/cf1/robot_description"))
        self.assertIn('name="cf2/base_link"', rospy.get_param("/cf2/robot_description"))
        self.assertIn('<mass value="0.027"', rospy.get_param("/cf1/robot_description"))
        self.assertIn('<mass value="0.019"', rospy.get_param("/cf2/robot_description"))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_description", "description", Description, sys.argv)
