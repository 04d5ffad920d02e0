#!/usr/bin/env python3
"""Swarm mode on the world's truth: crazyflie_server flies 8 simulated Crazyflies from its own motion
capture stream (packed broadcasts from the world's tf; no controller node, no host-side mocap loop),
by broadcast takeoff with group masks, lands a Crazyflie whose pose goes stale while the others keep
hovering, stops all on /emergency, and flies them again after /all/reboot."""
from __future__ import annotations

import math
import sys
import time
import unittest

import rospy
import rostest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from std_srvs.srv import Empty, SetBool

from crazyflie_driver.srv import GoTo, Land, Takeoff, UpdateParams
from support.rostest_support import RosoutRecorder, TopicRecorder, wait_until, world

HEIGHT = 0.5
TOL = 0.05          # m from the hover point
SETTLED = 0.02      # m: arrived and settled


class SwarmApi(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("swarm_api_test")
        with open(rospy.get_param("~vehicles")) as f:
            cls.vehicles = {v["name"]: v for v in yaml.safe_load(f)["vehicles"]}
        cls.world = world(rospy.get_param("~sim_address"))
        cls.rosout = RosoutRecorder()
        cls.diagnostics = TopicRecorder("/diagnostics", DiagnosticArray)
        cls.pose = TopicRecorder("/cf1/pose", PoseStamped)
        for s in ("/takeoff", "/land", "/go_to", "/stop", "/emergency", "/start_trajectory", "/update_params"):
            rospy.wait_for_service(s, 90.0)

    def state(self, name):
        return self.world.control("vehicle_state", uri=self.vehicles[name]["uri"])

    def z(self, name):
        return self.state(name)["position"][2]

    def hover_error(self, name, offset=(0.0, 0.0)):
        x0, y0, _ = self.vehicles[name]["position"]
        return math.dist(self.state(name)["position"], (x0 + offset[0], y0 + offset[1], HEIGHT))

    def names(self, *ids):
        return ["cf%d" % i for i in ids]

    def test_0_update_params_reaches_every_crazyflie_and_refuses_a_bad_name_by_name(self):
        update = rospy.ServiceProxy("/update_params", UpdateParams)
        rospy.set_param("/allcfs/ring/effect", 7)
        update(["ring/effect"])
        for name, v in self.vehicles.items():     # on the world's truth: each simulated firmware's value
            self.assertEqual(self.world.control("state", uri=v["uri"])["params"]["ring.effect"], 7, name)
        bad = "ring/eff\x01ect"
        with self.assertRaises(rospy.ServiceException) as refused:
            update([bad])
        self.assertIn("ring/eff", str(refused.exception))     # named, with the rule it breaks
        self.assertIn("printable ASCII", str(refused.exception))
        self.assertNotIn("ExpatError", str(refused.exception))
        update(["ring/effect"])     # still serving

    def test_1_group_mask_takeoff_only_the_masked_subset_flies(self):
        rospy.ServiceProxy("/takeoff", Takeoff)(groupMask=1, height=HEIGHT, duration=rospy.Duration(2.0))
        group1, group2 = self.names(1, 2, 3, 4), self.names(5, 6, 7, 8)
        self.assertTrue(wait_until(lambda: all(self.hover_error(n) < TOL for n in group1), 20.0),
                        {n: self.state(n)["position"] for n in group1})
        for n in group2:            # never left the floor, motors off
            s = self.state(n)
            self.assertLess(s["position"][2], 0.02, (n, s))
            self.assertFalse(any(s["motors"]), (n, s))
        rospy.ServiceProxy("/takeoff", Takeoff)(groupMask=2, height=HEIGHT, duration=rospy.Duration(2.0))
        self.assertTrue(wait_until(lambda: all(self.hover_error(n) < TOL for n in group2), 20.0),
                        {n: self.state(n)["position"] for n in group2})

    def test_2_eight_hover_on_the_servers_mocap_and_move_together(self):
        every = self.names(*range(1, 9))
        # the takeoff of group 2 has just arrived: its height controller settles first (it may overshoot
        # a few cm at arrival); the hover is judged from then on
        self.assertTrue(wait_until(lambda: all(self.hover_error(n) < SETTLED for n in every), 15.0),
                        {n: self.state(n)["position"] for n in every})
        worst = 0.0
        t_end = time.monotonic() + 3.0
        while time.monotonic() < t_end:
            worst = max(worst, max(self.hover_error(n) for n in every))
            time.sleep(0.1)
        self.assertLess(worst, TOL)
        req = GoTo._request_class(groupMask=0, relative=False, yaw=0.0, duration=rospy.Duration(2.0))
        req.goal.x, req.goal.y = 0.25, -0.1       # a swarm go_to is relative: each moves by this
        rospy.ServiceProxy("/go_to", GoTo)(req)
        self.assertTrue(wait_until(lambda: all(self.hover_error(n, (0.25, -0.1)) < TOL for n in every), 15.0),
                        {n: self.state(n)["position"] for n in every})
        req.goal.x, req.goal.y = -0.25, 0.1
        rospy.ServiceProxy("/go_to", GoTo)(req)
        self.assertTrue(wait_until(lambda: all(self.hover_error(n) < TOL for n in every), 15.0))
        # the onboard pose topic: the estimate, close to the truth. Judged with cf1 at rest, on a pose the
        # Crazyflie sampled 0.3 s after it came to rest (the topic's stamp is the sampling time): a pose
        # sampled while it still moved trails the truth, and a busy radio delivers samples late
        self.assertTrue(wait_until(lambda: math.hypot(*self.state("cf1")["velocity"]) < 0.05, 5.0),
                        self.state("cf1"))
        after = rospy.Time.now() + rospy.Duration.from_sec(0.3)
        at_rest = lambda: self.pose.latest_where(lambda m: m.header.stamp >= after)
        self.assertTrue(wait_until(at_rest, 3.0), "no pose topic message sampled after cf1 came to rest")
        p = at_rest().pose.position
        self.assertLess(math.dist((p.x, p.y, p.z), self.state("cf1")["position"]), 0.05)

    def test_3_a_stale_pose_lands_that_crazyflie_while_the_others_keep_flying(self):
        others = self.names(1, 2, 4, 5, 6, 7, 8)
        hide = rospy.ServiceProxy("/crazyflie_sim/cf3/set_mocap", SetBool)
        t0 = time.monotonic()
        hide(False)
        worst = 0.0
        while time.monotonic() - t0 < 20.0 and not (self.z("cf3") < 0.03 and not any(self.state("cf3")["motors"])):
            worst = max(worst, max(self.hover_error(n) for n in others))
            time.sleep(0.05)
        self.assertLess(self.z("cf3"), 0.03, self.state("cf3"))
        self.assertFalse(any(self.state("cf3")["motors"]))
        self.assertLess(worst, TOL)
        self.assertTrue(all(self.hover_error(n) < TOL for n in others))
        self.assertTrue(wait_until(lambda: self.rosout.find("cf3: no pose for"), 5.0))
        self.assertTrue(wait_until(lambda: self.rosout.find("cf3: landing by itself: no pose for"), 5.0))

        def cf3_error_on_diagnostics():
            name = "crazyflie_server swarm: cf3"
            msg = self.diagnostics.latest_where(lambda a: any(s.name == name for s in a.status))  # not the world's
            return msg is not None and any(s.name == name and s.level == DiagnosticStatus.ERROR
                                           and ("stale" in s.message or "landing" in s.message) for s in msg.status)
        self.assertTrue(wait_until(cf3_error_on_diagnostics, 5.0))
        hide(True)

    def test_4_emergency_stops_every_crazyflie(self):
        flying = [n for n in self.names(*range(1, 9)) if self.z(n) > 0.3]
        self.assertEqual(len(flying), 7)
        w0 = self.state("cf1")["time"]
        rospy.ServiceProxy("/emergency", Empty)()
        every = self.names(*range(1, 9))
        self.assertTrue(wait_until(lambda: not any(any(self.state(n)["motors"]) for n in every), 5.0),
                        {n: self.state(n)["motors"] for n in every})
        for n in every:     # timed in the world from the call to each supervisor's lock, not by the polls
            s = self.state(n)
            self.assertIsNotNone(s["locked_at"], (n, s))
            self.assertLess(s["locked_at"] - w0, 2.0, (n, s["locked_at"] - w0))
        with self.assertRaises(rospy.ServiceException):
            rospy.ServiceProxy("/land", Land)(groupMask=0, height=0.0, duration=rospy.Duration(2.0))

    def test_5_a_reboot_of_all_brings_the_swarm_back_from_the_emergency(self):
        every = self.names(*range(1, 9))
        self.assertTrue(wait_until(lambda: all(self.z(n) < 0.03 for n in every), 10.0),
                        {n: self.state(n)["position"] for n in every})
        rospy.ServiceProxy("/all/reboot", Empty)()
        self.assertTrue(wait_until(lambda: all(self.state(n)["locked"] == "" for n in every), 20.0),
                        {n: self.state(n)["locked"] for n in every})     # each supervisor: unlocked by its reboot
        takeoff = rospy.ServiceProxy("/takeoff", Takeoff)

        def taken() -> bool:        # refused until every Crazyflie is back and placed again
            try:
                takeoff(groupMask=0, height=HEIGHT, duration=rospy.Duration(2.0))
                return True
            except rospy.ServiceException:
                return False
        ground = {n: self.state(n)["position"] for n in every}      # cf3 landed where its pose went stale
        self.assertTrue(wait_until(taken, 30.0, 0.5), self.rosout.find("swarm"))
        above = lambda n: math.dist(self.state(n)["position"], (ground[n][0], ground[n][1], HEIGHT))
        self.assertTrue(wait_until(lambda: all(above(n) < TOL for n in every), 15.0),
                        {n: self.state(n)["position"] for n in every})
        back = "back after the reboot: flight commands are taken again"
        self.assertTrue(wait_until(lambda: self.rosout.find(back), 5.0))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "swarm_api", SwarmApi, sys.argv)
