#!/usr/bin/env python3
"""Custom log topics in swarm mode on the world's truth (swarm_log_topics.test).

The swarm file (Crazyswarm2's format) gives ``zlog`` = [stateEstimate.z] at 10 Hz to all and 20 Hz to
cf2; the server's parameters (Crazyswarm's) give ``vbat`` = [pm.vbat] every 100 ms to every Crazyflie;
cf3 asks for a variable no firmware has. Checked:
- cf3 is connected without its custom topics (it hears the broadcast takeoff: left unconnected it would
  fly unsupervised), the server's log names it and the variable, it publishes none of them, and it
  takes off with the others;
- rates per second of the Crazyflie's own clock (the messages' ``onboard_timestamp``, world time), so
  the host's delivery latency and a world slower than the wall clock cannot move the count;
- values: zlog is the onboard estimate of the height, within 3 cm of the world's true height while
  hovering at 0.5 m; vbat agrees with the world's battery.
"""
from __future__ import annotations

import statistics
import sys
import unittest
from typing import Any, List

import rospy
import rostest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rosgraph_msgs.msg import Log

from crazyflie_driver.msg import GenericLogData
from crazyflie_driver.srv import Land, Takeoff
from support.rostest_support import RosoutRecorder, TopicRecorder, wait_until, world

HEIGHT = 0.5                 # m
RATE_HZ = {("cf1", "zlog"): 10.0, ("cf2", "zlog"): 20.0, ("cf1", "vbat"): 10.0, ("cf2", "vbat"): 10.0}
SPAN_MS = 3000               # onboard ms counted over
TIMESTAMP_WRAP = 1 << 24     # the log packet's timestamp is 24 bits of ms
HEIGHT_TOL = 0.03            # m between the onboard estimate and the truth
VBAT_TOL = 0.05              # V


def onboard_window(msgs: List[Any], span_ms: int) -> List[Any]:
    """The messages the Crazyflie stamped within ``span_ms`` from the first one (24-bit wrap aware)."""
    if not msgs:
        return []
    ts0 = msgs[0].onboard_timestamp
    return [m for m in msgs if (m.onboard_timestamp - ts0) % TIMESTAMP_WRAP < span_ms]


class SwarmLogTopics(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("swarm_log_topics_test")
        with open(rospy.get_param("~vehicles")) as f:
            cls.vehicles = {v["name"]: v for v in yaml.safe_load(f)["vehicles"]}
        cls.world = world(rospy.get_param("~sim_address"))
        cls.rosout = RosoutRecorder()
        cls.diagnostics = TopicRecorder("/diagnostics", DiagnosticArray)
        cls.rec = {(cf, topic): TopicRecorder("/%s/%s" % (cf, topic), GenericLogData)
                   for cf in ("cf1", "cf2", "cf3") for topic in ("zlog", "vbat", "bad")}
        rospy.wait_for_service("/takeoff", 90.0)

    def state(self, name):
        return self.world.control("vehicle_state", uri=self.vehicles[name]["uri"])

    def test_0_the_crazyflie_with_a_bad_topic_flies_without_them_said_by_name_and_the_others_publish(self):
        self.assertTrue(wait_until(lambda: all(self.rec[k].count() >= 5 for k in RATE_HZ), 60.0),
                        {k: r.count() for k, r in self.rec.items()})
        refused = wait_until(lambda: self.rosout.find("cf3 flies WITHOUT its custom log topics", Log.ERROR), 30.0)
        self.assertTrue(refused, "no error about cf3's custom log topics on rosout")
        self.assertIn("nosuch.variable", refused[0])
        print("LOG refusal: %s" % refused[0])

        name = "crazyflie_server swarm: cf3"

        def cf3_status():
            arr = self.diagnostics.latest_where(lambda a: any(s.name == name for s in a.status))
            return next((s for s in arr.status if s.name == name), None) if arr else None
        status = wait_until(cf3_status, 10.0)
        self.assertIsNotNone(status, "cf3 is not on /diagnostics")
        self.assertGreaterEqual(status.level, DiagnosticStatus.WARN, status)
        self.assertIn("no custom log topics", status.message)
        self.assertEqual(sum(self.rec[("cf3", t)].count() for t in ("zlog", "vbat", "bad")), 0)
        self.assertEqual(self.rec[("cf1", "bad")].count() + self.rec[("cf2", "bad")].count(), 0)

    def test_1_rates_and_values_on_the_worlds_truth_while_hovering(self):
        rospy.ServiceProxy("/takeoff", Takeoff)(groupMask=0, height=HEIGHT, duration=rospy.Duration(2.0))
        try:
            hovering = wait_until(lambda: all(abs(self.state(n)["position"][2] - HEIGHT) < 0.05
                                              for n in self.vehicles), 30.0)
            self.assertTrue(hovering, {n: self.state(n)["position"] for n in self.vehicles})
            self.check_values()
            self.check_rates()
            self.assertEqual(sum(self.rec[("cf3", t)].count() for t in ("zlog", "vbat", "bad")), 0)
        finally:
            rospy.ServiceProxy("/land", Land)(groupMask=0, height=0.0, duration=rospy.Duration(2.0))
        self.assertTrue(wait_until(lambda: all(self.state(n)["position"][2] < 0.05 for n in self.vehicles), 30.0))

    def check_values(self):
        """Each newest zlog and vbat against the truth at about the same time, several times."""
        for _ in range(10):
            for name in ("cf1", "cf2"):
                n_before = self.rec[(name, "zlog")].count()
                self.assertTrue(wait_until(lambda: self.rec[(name, "zlog")].count() > n_before, 5.0), name)
                truth = self.state(name)
                z = self.rec[(name, "zlog")].latest().values
                self.assertEqual(len(z), 1, "zlog carries stateEstimate.z only")
                self.assertAlmostEqual(z[0], truth["position"][2], delta=HEIGHT_TOL, msg=name)
                v = self.rec[(name, "vbat")].latest().values
                self.assertEqual(len(v), 1, "vbat carries pm.vbat only")
                self.assertAlmostEqual(v[0], truth["vbat"], delta=VBAT_TOL, msg=name)
            rospy.sleep(0.2)
        print("LOG values: cf1 zlog %.3f m (truth %.3f m), vbat %.3f V (truth %.3f V)"
              % (self.rec[("cf1", "zlog")].latest().values[0], self.state("cf1")["position"][2],
                 self.rec[("cf1", "vbat")].latest().values[0], self.state("cf1")["vbat"]))

    def check_rates(self):
        """Messages stamped within SPAN_MS of the Crazyflie's clock, from the next message on."""
        starts = {k: r.count() for k, r in self.rec.items() if k in RATE_HZ}

        def stamped(key):
            msgs = [m for _, m in self.rec[key].messages[starts[key]:]]
            return onboard_window(msgs, SPAN_MS), msgs

        def past_end(key) -> bool:
            window, msgs = stamped(key)
            return len(msgs) > len(window) > 0
        self.assertTrue(wait_until(lambda: all(past_end(k) for k in RATE_HZ), 20.0),
                        {k: len(stamped(k)[1]) for k in RATE_HZ})
        for key, hz in RATE_HZ.items():
            window, _ = stamped(key)
            rate = len(window) / (SPAN_MS / 1000.0)
            gaps = [(b.onboard_timestamp - a.onboard_timestamp) % TIMESTAMP_WRAP for a, b in zip(window, window[1:])]
            print("LOG /%s/%s: %d messages in %d onboard ms: %.1f /s (configured %.0f Hz), median spacing %.0f ms"
                  % (key[0], key[1], len(window), SPAN_MS, rate, hz, statistics.median(gaps)))
            # the first message starts the window: one period of slack, no message lost
            self.assertAlmostEqual(rate, hz, delta=1000.0 / SPAN_MS, msg=str(key))
            self.assertAlmostEqual(statistics.median(gaps), 1000.0 / hz, delta=1, msg=str(key))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "swarm_log_topics", SwarmLogTopics, sys.argv)
