#!/usr/bin/env python3
"""Swarm mode on the world's truth: the radio of one hovering Crazyflie is unplugged; it is named on
/diagnostics and its motors stop one watchdog period after the last keep-alive it heard (the server's
broadcast emergency-stop watchdog), while the Crazyflies on the other radio keep hovering. Before that,
a takeoff that addresses a Crazyflie whose estimator motion capture never placed is refused whole."""
from __future__ import annotations

import math
import os
import sys
import time
import unittest

import rospy
import rostest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from crazyflie_driver.srv import Takeoff

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))  # test/: the support package
from support.rostest_support import RosoutRecorder, TopicRecorder, wait_until, world  # noqa: E402

HEIGHT = 0.5
TOL = 0.05              # m from the hover point
WATCHDOG_S = 1.0        # the firmware's emergency-stop watchdog period (world s)
KEEPALIVE_S = 0.25      # the server's keep-alive period


class SwarmLinkLost(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("swarm_link_lost_test")
        with open(rospy.get_param("~vehicles")) as f:
            cls.vehicles = {v["name"]: v for v in yaml.safe_load(f)["vehicles"]}
        cls.world = world(rospy.get_param("~sim_address"))
        cls.rosout = RosoutRecorder()
        cls.diagnostics = TopicRecorder("/diagnostics", DiagnosticArray)
        rospy.wait_for_service("/takeoff", 60.0)

    def state(self, name):
        return self.world.control("vehicle_state", uri=self.vehicles[name]["uri"])

    def hover_error(self, name):
        x0, y0, _ = self.vehicles[name]["position"]
        return math.dist(self.state(name)["position"], (x0, y0, HEIGHT))

    def test_unplugged_radio_stops_its_crazyflie_the_others_keep_hovering(self):
        every, others = ("cf1", "cf2", "cf3"), ("cf1", "cf2")
        takeoff = rospy.ServiceProxy("/takeoff", Takeoff)
        # every Crazyflie, cf4 among them: cf4 would take off from where its estimator believes it is
        with self.assertRaises(rospy.ServiceException) as refused:
            takeoff(groupMask=0, height=HEIGHT, duration=rospy.Duration(2.0))
        self.assertIn("/takeoff: cf4: no first motion-capture pose", str(refused.exception))
        for n in every + ("unseen4",):      # nothing was sent: all still on the floor, motors off (cf4 is the
            # world's unseen4)
            s = self.state(n)
            self.assertLess(s["position"][2], 0.02, (n, s))
            self.assertFalse(any(s["motors"]), (n, s))
        takeoff(groupMask=1, height=HEIGHT, duration=rospy.Duration(2.0))     # cf1, cf2, cf3
        self.assertTrue(wait_until(lambda: all(self.hover_error(n) < TOL for n in every), 20.0),
                        {n: self.state(n)["position"] for n in every})
        self.world.set_dongle_faults(1, unplugged=True)
        try:
            # both ends are the world's stamps (how often this loop looks does not count)
            unplugged_at = self.world.control("dongle_faults", dongle=1)[0]["plug_changed_at"]
            worst, stopped_at = 0.0, None
            t_end = time.monotonic() + 8.0
            while time.monotonic() < t_end:
                s = self.state("cf3")
                if stopped_at is None and not any(s["motors"]):
                    self.assertIsNotNone(s["locked_at"], s)     # stopped by its firmware, locked
                    stopped_at = s["locked_at"]
                worst = max(worst, max(self.hover_error(n) for n in others))
                if stopped_at is not None and s["position"][2] < 0.03:
                    break
                time.sleep(0.02)
            self.assertIsNotNone(stopped_at, self.state("cf3"))
            # the watchdog's doing: one period after the last keep-alive, which came at most one
            # keep-alive period before the radio went
            self.assertGreaterEqual(stopped_at - unplugged_at, WATCHDOG_S - KEEPALIVE_S - 0.05)
            self.assertLessEqual(stopped_at - unplugged_at, WATCHDOG_S + 0.1)
            self.assertLess(self.state("cf3")["position"][2], 0.03, self.state("cf3"))
            self.assertLess(worst, TOL)

            def cf3_link_lost_on_diagnostics():
                msg = self.diagnostics.latest()
                return msg is not None and any(
                    s.name == "crazyflie_server swarm: cf3" and s.level == DiagnosticStatus.ERROR
                    and "radio link lost" in s.message for s in msg.status)
            self.assertTrue(wait_until(cf3_link_lost_on_diagnostics, 5.0), self.diagnostics.latest())
            self.assertTrue(self.rosout.find("cf3: radio link lost"))
            self.assertTrue(all(self.hover_error(n) < TOL for n in others))     # still in the air, in place
        finally:
            self.world.set_dongle_faults(1, unplugged=False)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "swarm_link_lost", SwarmLinkLost, sys.argv)
