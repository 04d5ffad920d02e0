#!/usr/bin/env python3
"""crazyflie_sim_node's /tf and /diagnostics: see sim_mocap_tf.test."""
from __future__ import annotations

import sys
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from tf2_msgs.msg import TFMessage

from crazyflie_driver.mocap.vrpn_client import VrpnClient
from support.rostest_support import wait_until, world, world_window

NAMES = ("cf1", "cf2", "cf3")
CHILDREN = tuple("vicon/%s/%s" % (n, n) for n in NAMES) + NAMES
WINDOW_S = 5.0          # the counting window [s of world time]
RATE_HZ = 500.0


class SimMocapTf(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("sim_mocap_tf_test")
        cls.lock = threading.Lock()
        cls.messages = []                  # (monotonic arrival, [(child, stamp ns), ...])
        cls.world = world(rospy.get_param("~sim_address"))
        cls.status = None
        cls.tf_sub = rospy.Subscriber("/tf", TFMessage, cls.on_tf, queue_size=5000)
        cls.diag_sub = rospy.Subscriber("/diagnostics", DiagnosticArray, cls.on_diagnostics, queue_size=10)

    @classmethod
    def on_tf(cls, msg):
        entry = (time.monotonic(), [(t.child_frame_id, t.header.stamp.to_nsec()) for t in msg.transforms])
        with cls.lock:
            cls.messages.append(entry)

    @classmethod
    def on_diagnostics(cls, msg):
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            if "real-time factor" in values:
                cls.status = (st, values)

    def test_a_stamps_strictly_increase_per_child_frame_and_frames_come_batched(self):
        self.assertTrue(wait_until(lambda: len(self.messages) > 50, 30.0), "no motion capture on /tf")
        # a window of the world's time: the motion capture runs on it, and a world slowed down by a
        # busy machine captures fewer frames per wall second however well they are published
        span = world_window(self.world, WINDOW_S)
        with self.lock:
            window = [m for t, m in self.messages if span.t0 <= t <= span.t1]
        last, repeated, count = {}, [], {}
        for transforms in window:
            for child, ns in transforms:
                if child in last and ns <= last[child]:
                    repeated.append((child, last[child], ns))
                last[child] = ns
                count[child] = count.get(child, 0) + 1
        self.assertEqual(repeated[:5], [], "%d transforms not after the previous stamp of their frame "
                         "(TF_REPEATED_DATA)" % len(repeated))
        for child in CHILDREN:
            # a late publisher merges frames (newest per body), but most of 500 Hz come through
            self.assertGreater(count.get(child, 0), 0.25 * RATE_HZ * span.world_s, (child, span.world_s))
        # one message carries every body of a frame: far fewer messages than transforms
        self.assertLess(len(window), sum(count.values()) / 3.0)

    def test_b_the_world_reports_its_real_time_factor_on_diagnostics(self):
        self.assertTrue(wait_until(lambda: self.status is not None, 10.0), "no world status on /diagnostics")
        status, values = self.status
        self.assertEqual(values["vehicles"], "3")
        self.assertGreater(float(values["real-time factor"]), 0.0)
        self.assertIn(status.level, (0, 1))
        self.assertIn("ticks behind", values)

    def test_c_the_motion_capture_is_served_as_vrpn_one_tracker_per_vehicle(self):
        reports, lock = [], threading.Lock()

        def on_pose(report):
            with lock:
                reports.append(report)

        def of(name):
            with lock:
                return [r for r in reports if r.tracker == name]

        port = int(rospy.get_param("~vrpn_port"))
        with VrpnClient("127.0.0.1", port, on_pose=on_pose, retry_min=0.1, retry_max=0.5):
            self.assertTrue(wait_until(lambda: all(len(of(n)) > 0.5 * RATE_HZ for n in NAMES), 30.0),
                            "VRPN trackers: %s" % sorted({r.tracker for r in reports}))
            counted = {n: len(of(n)) for n in NAMES}
            span = world_window(self.world, 2.0)
            counted = {n: len(of(n)) - counted[n] for n in NAMES}
        for i, name in enumerate(NAMES):
            got = of(name)
            self.assertLess(max(abs(a - b) for a, b in zip(got[-1].position, (0.5 * i, 0.0, 0.0))), 0.01, name)
            stamps = [r.server_sec + 1e-6 * r.server_usec for r in got]
            # one report per capture: the mocap rate per second of the world's time
            rate = counted[name] / span.world_s
            self.assertTrue(0.5 * RATE_HZ < rate < 1.5 * RATE_HZ, "%s: %.0f reports per world second"
                            % (name, rate))
            self.assertTrue(all(b > a for a, b in zip(stamps, stamps[1:])), name)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "sim_mocap_tf", SimMocapTf, sys.argv)
