#!/usr/bin/env python3
"""Emergency mid-flight (hover_vicon.launch sim:=true): /crazyflie/emergency while hovering stops
the motors at once, the vehicle falls to the floor and stays there although the position
controller keeps publishing cmd_vel. Judged by the simulated vehicle's motors and position."""
from __future__ import annotations

import sys
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import Twist
from std_srvs.srv import Empty

from support.flight_support import WorldProbe, wait_until

NAME = "crazyflie"


class EmergencyMidFlight(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("emergency_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.probe.wait_ready([NAME])
        cls.cmd_vel_count = 0
        rospy.Subscriber("/%s/cmd_vel" % NAME, Twist, cls._on_cmd_vel, queue_size=50)

    @classmethod
    def _on_cmd_vel(cls, _msg):
        cls.cmd_vel_count += 1

    def test_emergency_stops_the_motors_and_the_vehicle_falls(self):
        self.assertTrue(self.probe.wait_near(NAME, (0.0, 0.0, 0.5), 0.05, 40.0),
                        "never hovered: %s" % (self.probe.position(NAME),))
        self.probe.sleep(1.0)
        before = self.probe.state(NAME)
        self.assertGreater(min(before["motors"]), 10000, "motors should be spinning while hovering: %s" % (before,))
        rospy.wait_for_service("/%s/emergency" % NAME, 5.0)
        t0, w0 = time.monotonic(), self.probe.state(NAME)["time"]
        rospy.ServiceProxy("/%s/emergency" % NAME, Empty)()
        stopped = wait_until(lambda: max(self.probe.state(NAME)["motors"]) == 0, 5.0, 0.01)
        self.assertTrue(stopped, "motors still at %s after emergency" % (self.probe.state(NAME)["motors"],))
        # timed in the world from the call to the supervisor's lock (how often this test looks does not count)
        locked_at = self.probe.state(NAME)["locked_at"]
        self.assertIsNotNone(locked_at, self.probe.state(NAME))
        stop_s = locked_at - w0
        self.assertLess(stop_s, 1.0, "motors stopped %.2f world-s after the emergency call" % stop_s)
        self.assertTrue(self.probe.firmware(NAME)["emergency"])
        on_floor = wait_until(lambda: self.probe.state(NAME)["on_ground"], 3.0, 0.02)
        fall_s = time.monotonic() - t0
        self.assertTrue(on_floor, "not on the floor 3 s after emergency: %s" % (self.probe.position(NAME),))
        print("EMERGENCY motors stopped %.3f world-s after the call, on the floor after %.2f s" % (stop_s, fall_s))
        # the controller keeps publishing setpoints; none of them may spin the motors again
        count = self.cmd_vel_count
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            s = self.probe.state(NAME)
            self.assertEqual(max(s["motors"]), 0, "motors restarted after emergency")
            self.assertLess(s["position"][2], 0.05)
            time.sleep(0.05)
        self.assertGreater(self.cmd_vel_count, count, "the controller should still be publishing cmd_vel")
        # a second call is harmless (idempotent)
        rospy.ServiceProxy("/%s/emergency" % NAME, Empty)()
        self.assertEqual(max(self.probe.state(NAME)["motors"]), 0)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "emergency", EmergencyMidFlight, sys.argv)
