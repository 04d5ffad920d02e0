#!/usr/bin/env python3
"""Swarm mode on the world's truth: the radio of one hovering Crazyflie is unplugged; it is named on
/diagnostics and its motors stop one watchdog period after the last keep-alive it heard (the server's
broadcast emergency-stop watchdog), while the Crazyflies on the other radio keep hovering. Before that,
a takeoff that addresses a Crazyflie whose estimator motion capture never placed is refused whole.
Then motion capture sees one of the two on radio 0 as a ghost 100 m away (noise 100 m, beyond the packed
broadcast's +-32.767 m): its neighbour keeps getting poses at the stream's rate and keeps hovering, and the
ghost's Crazyflie goes stale and is landed."""
from __future__ import annotations

import math
import sys
import time
import unittest

import rospy
import rostest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from crazyflie_driver.server.swarm.heartbeat import PERIOD_S as KEEPALIVE_S  # the server's keep-alive period
from crazyflie_driver.sim.air.faults import parse_command
from crazyflie_driver.srv import Takeoff
from support.rostest_support import RosoutRecorder, TopicRecorder, wait_until, world

HEIGHT = 0.5
TOL = 0.05              # m from the hover point
WATCHDOG_S = 1.0        # the firmware's emergency-stop watchdog period (world s)
GHOST_S = 6.0           # how long the ghost is watched (s)
TAKEOFF_S = 2.0         # world s
SETTLE_S = 3.0          # world s after the take-off: its overshoot (4-5 cm, the PID chain's z integrator) decays


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
        self.assertIn("/takeoff refused: cf4: no first motion-capture pose", str(refused.exception))
        for n in every + ("unseen4",):      # nothing was sent: all still on the floor, motors off (cf4 is the
            # world's unseen4)
            s = self.state(n)
            self.assertLess(s["position"][2], 0.02, (n, s))
            self.assertFalse(any(s["motors"]), (n, s))
        takeoff(groupMask=1, height=HEIGHT, duration=rospy.Duration(TAKEOFF_S))     # cf1, cf2, cf3
        settled_at = rospy.get_time() + TAKEOFF_S + SETTLE_S                             # ROS time: the world's
        self.assertTrue(wait_until(lambda: rospy.get_time() >= settled_at
                                   and all(self.hover_error(n) < TOL for n in every), 20.0),
                        {n: self.state(n)["position"] for n in every})
        # "keep hovering" is judged from where each hovered when the radio went
        hovered = {n: self.state(n)["position"] for n in others}
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
                worst = max(worst, max(math.dist(self.state(n)["position"], hovered[n]) for n in others))
                if stopped_at is not None and s["position"][2] < 0.03:
                    break
                time.sleep(0.02)
            self.assertIsNotNone(stopped_at, self.state("cf3"))
            # the watchdog's doing: one period after the last keep-alive, which came at most one
            # keep-alive period before the radio went
            self.assertGreaterEqual(stopped_at - unplugged_at, WATCHDOG_S - KEEPALIVE_S - 0.05)
            self.assertLessEqual(stopped_at - unplugged_at, WATCHDOG_S + 0.1)
            self.assertLess(self.state("cf3")["position"][2], 0.03, self.state("cf3"))
            self.assertLess(worst, TOL, "moved from where they hovered when radio 1 went")

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

    def poses_sent(self, msg, name):
        """(stamp s, "poses sent" of ``name``) from a /diagnostics message, or None."""
        for st in msg.status:
            if st.name == "crazyflie_server swarm: %s" % name:
                values = {kv.key: kv.value for kv in st.values}
                if "poses sent" in values:
                    return msg.header.stamp.to_sec(), int(values["poses sent"])
        return None

    def latest_poses_sent(self, name):
        """(stamp s, "poses sent" of ``name``) from the newest /diagnostics message that has it (the topic
        also carries the server's and the world's own messages), or None."""
        msg = self.diagnostics.latest_where(lambda m: self.poses_sent(m, name))
        return self.poses_sent(msg, name) if msg is not None else None

    def pose_rate(self, name, seconds):
        """Poses per s the server sent ``name`` over ``seconds`` of /diagnostics stamps (the server's own
        count, over ROS time: world time in simulation, whatever pace the world runs at)."""
        first = wait_until(lambda: self.latest_poses_sent(name), 5.0)
        self.assertTrue(first, self.diagnostics.latest())
        last = first
        spanned = wait_until(lambda: self._span(name, first, seconds), 30.0, 0.1)
        self.assertTrue(spanned, "/diagnostics did not span %.1f s of ROS time" % seconds)
        last = spanned
        return (last[1] - first[1]) / (last[0] - first[0])

    def _span(self, name, first, seconds):
        """The latest (stamp, count) of ``name`` once it lies ``seconds`` after ``first``, else None."""
        last = self.latest_poses_sent(name)
        return last if last is not None and last[0] - first[0] >= seconds else None

    def test_with_one_ghost_on_radio_0_its_neighbour_keeps_its_poses_and_the_ghost_lands(self):
        """Runs after the unplug test (cf1 and cf2 hover on radio 0; takes them off itself if not)."""
        if not all(self.hover_error(n) < TOL for n in ("cf1", "cf2")):
            rospy.ServiceProxy("/takeoff", Takeoff)(groupMask=1, height=HEIGHT, duration=rospy.Duration(TAKEOFF_S))
            self.assertTrue(wait_until(lambda: all(self.hover_error(n) < TOL for n in ("cf1", "cf2")), 20.0))
        before = self.pose_rate("cf1", 2.0)
        self.assertGreater(before, 20.0)
        op, args = parse_command("mocap cf2 --noise 100")
        self.world.control(op, **args)
        try:
            worst, t_end = 0.0, rospy.get_time() + GHOST_S          # ROS time: world time in simulation
            first = self.latest_poses_sent("cf1")
            while rospy.get_time() < t_end:
                worst = max(worst, self.hover_error("cf1"))
                time.sleep(0.02)
            last = self.latest_poses_sent("cf1")
            during = (last[1] - first[1]) / (last[0] - first[0])
            rospy.loginfo("ghost on cf2: cf1 got %.1f poses/s (%.1f before), worst hover error %.3f m", during,
                          before, worst)
            # the neighbour: poses at the rate it had before, hovering in place (the world's truth)
            self.assertGreater(during, 0.8 * before, (before, during))
            self.assertLess(worst, TOL)
            # the ghost's Crazyflie: stale, told to land, on the floor (its poses never went out)
            cf2 = self.state("cf2")
            self.assertLess(cf2["position"][2], 0.05, cf2)
            self.assertTrue(self.rosout.find("cf2: landing by itself: no pose"), "cf2 not landed by the watch")
            self.assertTrue(self.rosout.find("cf2: pose refused, not sent"))

            def cf2_refused_on_diagnostics():
                msg = self.diagnostics.latest()
                return msg is not None and any(
                    st.name == "crazyflie_server swarm: cf2" and st.level == DiagnosticStatus.ERROR
                    and "refused" in st.message for st in msg.status)
            self.assertTrue(wait_until(cf2_refused_on_diagnostics, 3.0), self.diagnostics.latest())
        finally:
            op, args = parse_command("mocap cf2 --clear")
            self.world.control(op, **args)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "swarm_link_lost", SwarmLinkLost, sys.argv)
