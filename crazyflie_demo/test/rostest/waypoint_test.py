#!/usr/bin/env python3
"""multi_waypoint_vicon.launch sim:=true: both Crazyflies fly every waypoint in order, then land.

Watches ``/<name>/demo/waypoint`` (index of the waypoint being flown to) and ``/<name>/demo/finished``
and checks each hand-over against the world's true position: when the index moves from k to
k+1 the vehicle must be at waypoint k (within the demo's 0.3 m per axis). Private params:
``sim_address``, ``vehicles`` (names), ``timeout`` (s for the whole mission).
"""
from __future__ import annotations

import os
import sys
import threading
import time
import unittest

import rospy
import rostest
from std_msgs.msg import Bool, Int32

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))  # test/: the support package
from support.flight_support import Track, WorldProbe, wait_until  # noqa: E402


class MultiWaypoint(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("waypoint_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.names = list(rospy.get_param("~vehicles"))
        cls.probe.wait_ready(cls.names)
        cls.timeout = float(rospy.get_param("~timeout", 90.0))
        cls.lock = threading.Lock()
        cls.indices = {n: [] for n in cls.names}      # (monotonic time, index) as published
        cls.finished = {n: None for n in cls.names}
        cls.track = Track(cls.probe, cls.names, period=0.05)
        for n in cls.names:
            rospy.Subscriber("/%s/demo/waypoint" % n, Int32, cls._on_index(n), queue_size=20)
            rospy.Subscriber("/%s/demo/finished" % n, Bool, cls._on_finished(n), queue_size=5)

    @classmethod
    def _on_index(cls, name):
        def cb(msg):
            with cls.lock:
                cls.indices[name].append((time.monotonic(), msg.data))
        return cb

    @classmethod
    def _on_finished(cls, name):
        def cb(msg):
            with cls.lock:
                if msg.data and cls.finished[name] is None:
                    cls.finished[name] = time.monotonic()
        return cb

    def test_every_waypoint_in_order_then_land(self):
        t0 = time.monotonic()
        done = wait_until(lambda: all(self.finished[n] is not None for n in self.names), self.timeout, 0.2)
        with self.lock:
            indices = {n: list(v) for n, v in self.indices.items()}
        self.assertTrue(done, "not finished after %.0f s; waypoints seen: %s"
                        % (self.timeout, {n: [i for _, i in v] for n, v in indices.items()}))
        for n in self.names:
            waypoints = rospy.get_param("/%s/demo/waypoints" % n)
            seen = [i for _, i in indices[n]]
            self.assertEqual(seen, list(range(len(waypoints))), "%s flew the waypoints out of order" % n)
            # hand-over k -> k+1 happens when waypoint k was reached; the last one at `finished`
            reached_at = [t for t, _ in indices[n][1:]] + [self.finished[n]]
            times = []
            for k, (w, t) in enumerate(zip(waypoints, reached_at)):
                p = self.track.position_at(n, t)
                for axis in range(3):
                    self.assertLess(abs(p[axis] - w[axis]), 0.3,
                                    "%s at %s when waypoint %d %s counted as reached" % (n, p, k + 1, w))
                times.append(t - t0)
            print("WAYPOINTS %s reached at %s s after the test started" % (n, ["%.1f" % x for x in times]))
        for n in self.names:
            landed = wait_until(lambda: self.probe.state(n)["on_ground"], 20.0, 0.1)
            s = self.probe.state(n)
            self.assertTrue(landed, "%s did not land: %s" % (n, s["position"]))
            self.assertLess(s["position"][2], 0.05)
            self.assertTrue(wait_until(lambda: max(self.probe.state(n)["motors"]) == 0, 10.0, 0.1),
                            "%s motors still running after landing: %s" % (n, self.probe.state(n)["motors"]))
        print("MISSION landed %.1f s after the test started" % (time.monotonic() - t0))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "multi_waypoint", MultiWaypoint, sys.argv)
