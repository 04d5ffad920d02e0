#!/usr/bin/env python3
"""crazyflie_server's /diagnostics: every entry of a healthy pair of Crazyflies on one dongle, then
packet loss injected on that dongle (the world's control channel): WARN at 30 %, ERROR at 80 %, each
with the ack ratio the loss gives (1 - loss within 4 binomial standard deviations of the round trips
counted), and OK again once cleared. Only messages whose counting window began after the change are
judged: the window is host time, stamp - window [s] > the moment of the change."""
from __future__ import annotations

import sys
import threading
import unittest
from typing import Callable, Dict, List, Optional, Tuple

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from crazyflie_driver.server.diagnostics import ack_ratio_tolerance
from support.rostest_support import start_test_node, wait_until

NAMES = ("crazyflie1", "crazyflie2")
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


def values(status: DiagnosticStatus) -> Dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


class Diagnostics:
    """Every /diagnostics message of crazyflie_server: (stamp s, {name: status})."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.arrays: List[Tuple[float, Dict[str, DiagnosticStatus]]] = []
        self._sub = rospy.Subscriber("/diagnostics", DiagnosticArray, self._on, queue_size=100)

    def _on(self, msg: DiagnosticArray) -> None:
        entries = {s.name: s for s in msg.status if s.name.startswith("crazyflie_server: ")}
        if entries:
            with self._lock:
                self.arrays.append((msg.header.stamp.to_sec(), entries))

    def first(self, after: float, cond: Callable[[Dict[str, DiagnosticStatus]], bool],
              timeout: float) -> Optional[Dict[str, DiagnosticStatus]]:
        """The first message counted wholly after ``after`` (ROS time, s) for which ``cond`` holds."""
        def find():
            with self._lock:
                arrays = list(self.arrays)
            for stamp, entries in arrays:
                link = entries.get("crazyflie_server: crazyflie1 link")
                if link is None or stamp - float(values(link)["window [s]"]) <= after:
                    continue
                if cond(entries):
                    return entries
            return None
        return wait_until(find, timeout)


class DriverDiagnostics(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("driver_diagnostics_test", NAMES)
        cls.diag = Diagnostics()

    def link(self, entries, name):
        return entries["crazyflie_server: %s link" % name]

    def test_a_every_entry_when_healthy(self):
        start = rospy.Time.now().to_sec()
        want = ["crazyflie_server: %s%s" % (n, p) for n in NAMES
                for p in ("", " link", " battery", " supervisor", " commands")] + ["crazyflie_server: radio 0"]
        entries = self.diag.first(start, lambda e: all(w in e for w in want) and all(
            values(self.link(e, n))["ack ratio"] != "n/a" and values(e["crazyflie_server: %s battery" % n])
            .get("voltage [V]") for n in NAMES), 20.0)
        self.assertIsNotNone(entries, "no complete /diagnostics from crazyflie_server")
        for name in NAMES:
            link = self.link(entries, name)
            v = values(link)
            self.assertEqual(link.level, OK, link.message)
            self.assertEqual(link.hardware_id, "radio://0/80/2M/E7E7E7E70%s" % name[-1])
            self.assertEqual(v["ack ratio"], "1.000")
            self.assertGreaterEqual(int(v["round trips"]), 20)
            self.assertGreater(float(v["log packets/s"]), 10.0)   # 110/s of world time; host time: the world may lag
            self.assertEqual(v["setpoints/s"], "0.0")
            battery = entries["crazyflie_server: %s battery" % name]
            self.assertEqual(battery.level, OK, battery.message)
            self.assertTrue(3.0 < float(values(battery)["voltage [V]"]) < 4.3, battery.values)
            self.assertEqual(values(battery)["pm.state"], "0 (battery)")
            commands = entries["crazyflie_server: %s commands" % name]
            self.assertEqual(values(commands)["setpoint age [s]"], "never")
        supervisor = entries["crazyflie_server: crazyflie1 supervisor"]
        self.assertEqual(supervisor.level, OK, supervisor.message)
        self.assertNotEqual(values(supervisor)["bits"], "n/a")
        self.assertEqual(entries["crazyflie_server: crazyflie2 supervisor"].message,
                         "n/a (this firmware has no supervisor state)")
        radio = entries["crazyflie_server: radio 0"]
        v = values(radio)
        self.assertEqual(radio.hardware_id, "radio://0")
        self.assertEqual(v["crazyflies"], "crazyflie1, crazyflie2")
        self.assertEqual(v["capacity [round trips/s]"], "435")
        summed = sum(float(values(self.link(entries, n))["round trips/s"]) for n in NAMES)
        self.assertAlmostEqual(float(v["round trips/s"]), summed, delta=0.11)

    def test_b_injected_loss_warns_then_errors_with_its_ack_ratio_then_clears(self):
        try:
            for loss, level, threshold in ((30.0, WARN, 0.9), (80.0, ERROR, 0.5)):
                self.world.set_dongle_faults(0, packet_loss=loss)
                since = rospy.Time.now().to_sec()
                entries = self.diag.first(since, lambda e: all(
                    int(values(self.link(e, n))["round trips"]) >= 100 for n in NAMES), 20.0)
                self.assertIsNotNone(entries, "no /diagnostics counted after %.0f %% loss was set" % loss)
                expected = 1.0 - loss / 100.0
                for name in NAMES:
                    link = self.link(entries, name)
                    v = values(link)
                    n, ack = int(v["round trips"]), float(v["ack ratio"])
                    tolerance = ack_ratio_tolerance(expected, n)
                    print("%s, %.0f %% loss: ack ratio %.3f over %d round trips (expected %.2f +- %.3f), level %d: %s"
                          % (name, loss, ack, n, expected, tolerance, link.level, link.message))
                    self.assertLessEqual(abs(ack - expected), tolerance + 0.0005, (name, v))
                    self.assertEqual(link.level, level, (name, link.message))
                    self.assertRegex(link.message, r"^ack ratio \d\.\d\d < %.2f" % threshold)
                    status = entries["crazyflie_server: %s" % name]
                    self.assertEqual(values(status)["state"], "running", status.message)    # served throughout
        finally:
            self.world.set_dongle_faults(0, packet_loss=0.0)
        since = rospy.Time.now().to_sec()
        entries = self.diag.first(since, lambda e: all(self.link(e, n).level == OK for n in NAMES), 20.0)
        self.assertIsNotNone(entries, "the links did not come back to OK within 20 s after the loss was cleared")
        for name in NAMES:
            self.assertEqual(values(self.link(entries, name))["ack ratio"], "1.000")


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "driver_diagnostics", DriverDiagnostics, sys.argv)
