#!/usr/bin/env python3
"""Twelve Crazyflies on two fake dongles, all added at once: every add succeeds, and what the
server says about its data (rates, ages, the Crazyflies' transmit queues) is true."""
from __future__ import annotations

import sys
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import Imu
from std_msgs.msg import Float32

from support.rostest_support import TopicRecorder, rates_per_world_second, start_test_node, wait_served, wait_until

NAMES = ["cf%d" % i for i in range(1, 13)]


class AddResults:
    """What each crazyflie_add said on /rosout (they are anonymous nodes: matched by text)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.added, self.failed = set(), []
        self._sub = rospy.Subscriber("/rosout", Log, self._on_log, queue_size=1000)

    def _on_log(self, msg: Log) -> None:
        if not msg.name.startswith("/crazyflie_add") and "/crazyflie_add" not in msg.name:
            return
        with self._lock:
            if "added as" in msg.msg:
                self.added.add(msg.msg.split("'")[1])
            elif msg.level >= Log.ERROR:
                self.failed.append(msg.msg)


class DriverLoad(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("driver_load_test")
        cls.adds = AddResults()
        cls.imu = {n: TopicRecorder("/%s/imu" % n, Imu) for n in NAMES}
        cls.battery = {n: TopicRecorder("/%s/battery" % n, Float32) for n in NAMES}
        cls.status = {n: TopicRecorder("/%s/status" % n, DiagnosticStatus) for n in NAMES}

    def test_a_every_add_succeeds(self):
        # success: the Crazyflie's services exist (a crazyflie_add exits right after its last log
        # line, which may then never reach /rosout); failure: any error line of a crazyflie_add
        served = wait_served(NAMES, 90.0, stop=lambda: self.adds.failed)
        print("adds: %d served, %d failed; seconds to served (from the test's start): %s; failures: %s" % (
            len(served), len(self.adds.failed), {n: round(t, 1) for n, t in sorted(served.items())},
            self.adds.failed))
        self.assertEqual(self.adds.failed, [])
        self.assertEqual(sorted(served), sorted(NAMES))

    def test_b_rates_and_ages_are_reported_honestly(self):
        """Six Crazyflies per dongle ask for more log packets than a Crazyradio carries: the
        Crazyflies' transmit queues fill up. Whatever each one gets, its status says the rate it
        gets (per onboard second), how old its data is (checked against the firmware: the time the
        last packet handed to the radio spent in its transmit queue, read as the status arrives),
        and warns."""
        self.assertTrue(wait_until(lambda: all(r.count() > 0 for r in self.imu.values()), 20.0))
        time.sleep(3.0)         # let the queues reach their steady state
        imu = rates_per_world_second(self.imu, self.world, 3.0)
        print("imu per world second: %s" % {n: round(v, 1) for n, v in imu.items()})
        # each status with the firmware's state read as it arrives (the queue moves between two statuses),
        # all of them within a second or two of the rates above (the rates move as the queues fill)
        marks = {name: self.status[name].count() for name in NAMES}
        taken = {}
        deadline = time.monotonic() + 5.0
        while len(taken) < len(NAMES) and time.monotonic() < deadline:
            for name in NAMES:
                if name not in taken and self.status[name].count() > marks[name]:
                    taken[name] = (self.status[name].latest(), self.world.crazyflie_state(self.uri_of(name)))
            time.sleep(0.005)
        self.assertEqual(sorted(taken), sorted(NAMES), "statuses that did not come within 5 s")
        for name in NAMES:
            st, fw = taken[name]
            values = {kv.key: kv.value for kv in st.values}
            reported_rate, reported_age = float(values["imu rate_hz"]), float(values["imu age_s"])
            queued_s = float(fw["tx_last_wait_s"])
            print("%s: imu %.1f/s (reported %.1f), tx queue %d (dropped %d), age reported %.2f s, "
                  "last packet queued %.2f s; status %d %r" % (
                      name, imu[name], reported_rate, fw["tx_pending"], fw["tx_dropped"], reported_age,
                      queued_s, st.level, st.message))
            self.assertGreater(imu[name], 0.0)
            self.assertAlmostEqual(reported_rate, imu[name], delta=0.25 * imu[name] + 2.0)
            if fw["tx_pending"] >= 100:         # a long queue: the data is old, and the status says so
                self.assertGreater(reported_age, 0.6 * queued_s, (name, values))
                self.assertLess(reported_age, 1.6 * queued_s + 0.2, (name, values))
                self.assertEqual(st.level, DiagnosticStatus.WARN, st.message)
                self.assertIn("late", st.message)
            elif fw["tx_pending"] <= 10:
                self.assertLess(reported_age, 0.5, (name, values))

    def uri_of(self, name: str) -> str:
        i = int(name[2:])
        return "radio://%d/%d/2M/E7E7E7E7%02X" % (0 if i <= 6 else 1, 80 if i <= 6 else 90, i)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "driver_load", DriverLoad, sys.argv)
