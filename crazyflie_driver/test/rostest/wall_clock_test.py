#!/usr/bin/env python3
"""Without /clock (hardware) ROS time is the wall clock and the stack times on it, as before simulated time.

No /use_sim_time, no /clock publisher; ``nodes.ros_clock`` gives the wall clock; ROS time is the host's
time; the server's and the controller's /diagnostics are stamped with the wall clock and come once per
wall second (both publish them from a 1 s ROS timer, which would stop without /clock under sim time).
"""
from __future__ import annotations

import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray

from crazyflie_driver.clock import WALL
from crazyflie_driver.nodes.ros_clock import ros_clock, uses_sim_time
from support.rostest_support import start_test_node, wait_until

SOURCES = {"server": "crazyflie_server: crazyflie1", "controller": "crazyflie1/controller: "}
WINDOW_S = 5.0            # wall seconds over which the diagnostics are counted


class WallClock(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("wall_clock_test", ["crazyflie1"])
        cls.lock = threading.Lock()
        cls.seen = {k: [] for k in SOURCES}        # (stamp [s], wall time at arrival [s])
        rospy.Subscriber("/diagnostics", DiagnosticArray, cls._on_diagnostics, queue_size=50)

    @classmethod
    def _on_diagnostics(cls, msg):
        arrived = time.time()
        for key, prefix in SOURCES.items():
            if any(st.name.startswith(prefix) for st in msg.status):
                with cls.lock:
                    cls.seen[key].append((msg.header.stamp.to_sec(), arrived))

    def test_a_nothing_publishes_clock_and_ros_time_is_the_wall_clock(self):
        self.assertFalse(uses_sim_time())
        self.assertIs(ros_clock(), WALL)
        self.assertNotIn("/clock", [t for t, _ in rospy.get_published_topics()])
        for _ in range(5):
            self.assertAlmostEqual(rospy.get_time(), time.time(), delta=0.01)
            time.sleep(0.1)

    def test_b_server_and_controller_diagnostics_come_on_the_wall_clock(self):
        got = wait_until(lambda: all(self.seen[k] for k in SOURCES), 20.0)
        self.assertTrue(got, "no diagnostics from %s" % [k for k in SOURCES if not self.seen[k]])
        t0 = time.time()
        time.sleep(WINDOW_S)
        with self.lock:
            window = {k: [(s, a) for s, a in v if a >= t0] for k, v in self.seen.items()}
        for key, samples in window.items():
            ages = [a - s for s, a in samples]
            print("WALL_CLOCK %s: %d diagnostics in %.0f wall s, stamp-to-arrival %.3f..%.3f s"
                  % (key, len(samples), WINDOW_S, min(ages), max(ages)))
            self.assertTrue(WINDOW_S - 2 <= len(samples) <= WINDOW_S + 1, "%s: %d in %.0f s"
                            % (key, len(samples), WINDOW_S))
            for age in ages:                      # stamped with the host's time, delivered at once
                self.assertGreaterEqual(age, -0.01)
                self.assertLess(age, 0.5)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "wall_clock", WallClock)
