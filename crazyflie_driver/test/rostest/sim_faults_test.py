#!/usr/bin/env python3
"""Faults injected through the sim node (its ``faults`` parameter and ``~fault`` service) reach the world,
and the stack sees them: the battery topic, the link statistics, the link state, the motion capture and
the injected-faults entry of /diagnostics."""
from __future__ import annotations

import sys
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import TransformStamped
from std_msgs.msg import Float32

from crazyflie_driver.srv import InjectFault
from support.rostest_support import TopicRecorder, start_test_node, wait_until, world_window

NAMES = ("crazyflie1", "crazyflie2")


def values(status: DiagnosticStatus) -> dict:
    return {kv.key: kv.value for kv in status.values}


class SimFaults(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("sim_faults_test", NAMES)
        rospy.wait_for_service("/crazyflie_sim/fault", 30.0)
        cls.fault = rospy.ServiceProxy("/crazyflie_sim/fault", InjectFault)
        cls.battery = {n: TopicRecorder("/%s/battery" % n, Float32) for n in NAMES}
        cls.status = {n: TopicRecorder("/%s/status" % n, DiagnosticStatus) for n in NAMES}
        cls.diagnostics = TopicRecorder("/diagnostics", DiagnosticArray)
        cls.vicon = TopicRecorder("/vicon/crazyflie1/crazyflie1", TransformStamped)

    def inject(self, command: str) -> str:
        answer = self.fault(command)
        self.assertTrue(answer.success, "%s: %s" % (command, answer.message))
        return answer.message

    def injected_faults(self):
        """The sim node's newest injected-faults status on /diagnostics."""
        for _, msg in reversed(self.diagnostics.since(0.0)):
            for st in msg.status:
                if st.name.endswith("injected faults"):
                    return st
        return None

    def later_injected_faults(self, t0, cond, timeout=5.0):
        """The first injected-faults status published after wall time t0 that satisfies cond."""
        def found():
            for _, msg in self.diagnostics.since(t0):
                for st in msg.status:
                    if st.name.endswith("injected faults") and cond(st):
                        return st
            return None
        return wait_until(found, timeout)

    def link_quality(self, name: str, since: float):
        st = wait_until(lambda: [m for _, m in self.status[name].since(since)], 10.0)
        return float(values(st[-1])["link_quality"]) if st else None

    def test_a_the_fault_given_at_start_is_in_force(self):
        got = wait_until(lambda: self.battery["crazyflie2"].latest(), 10.0)
        self.assertIsNotNone(got)
        self.assertAlmostEqual(got.data, 3.7, delta=0.02)
        other = wait_until(lambda: self.battery["crazyflie1"].latest(), 10.0)
        self.assertIsNotNone(other)
        self.assertGreater(other.data, 4.0)
        st = wait_until(self.injected_faults, 5.0)
        self.assertEqual(st.level, DiagnosticStatus.WARN)
        self.assertIn("crazyflie2", values(st))
        self.assertIn("battery set to", values(st)["crazyflie2"])

    def test_b_battery_drained_at_run_time_reads_on_the_battery_topic(self):
        self.assertIn("crazyflie1: battery 3.40 V", self.inject("battery crazyflie1 3.4"))
        t0 = time.monotonic()
        got = wait_until(lambda: [m for t, m in self.battery["crazyflie1"].since(t0) if m.data < 3.5], 10.0)
        self.assertTrue(got, "no /crazyflie1/battery reading near 3.4 V")
        self.assertAlmostEqual(got[-1].data, 3.4, delta=0.02)
        self.inject("battery crazyflie1 100%")

    def test_c_packet_loss_shows_in_the_link_statistics_and_on_diagnostics(self):
        try:
            self.inject("loss 0 --packet 0.5")
            t0 = time.monotonic()
            world_window(self.world, 3.0)           # the link statistics' window fills with lossy round trips
            quality = self.link_quality("crazyflie1", time.monotonic())
            print("link quality of crazyflie1 with 50 %% packet loss: %s" % quality)
            self.assertLess(quality, 0.7)
            self.assertGreater(quality, 0.3)
            self.assertGreater(self.link_quality("crazyflie2", time.monotonic()), 0.95)   # other dongle
            st = self.later_injected_faults(t0, lambda s: "dongle 0" in values(s))
            self.assertTrue(st, "no injected-faults status naming dongle 0")
            self.assertEqual(values(st)["dongle 0"], "packet loss 50 %")
        finally:
            self.inject("clear 0")
        world_window(self.world, 3.0)
        self.assertGreater(self.link_quality("crazyflie1", time.monotonic()), 0.95)

    def test_d_switched_off_means_link_lost_and_switched_on_it_comes_back(self):
        self.assertEqual(self.inject("power crazyflie2 off"), "crazyflie2: switched off")
        t0 = time.monotonic()
        lost = wait_until(lambda: [m for _, m in self.status["crazyflie2"].since(t0)
                                   if m.level == DiagnosticStatus.ERROR and "link lost" in m.message], 10.0)
        self.assertTrue(lost, "no 'link lost' on /crazyflie2/status after power-off")
        self.assertGreater(self.link_quality("crazyflie1", time.monotonic()), 0.95)       # the other is served
        self.inject("power crazyflie2 on")
        t1 = time.monotonic()
        back = wait_until(lambda: [m for _, m in self.status["crazyflie2"].since(t1) if m.message == "running"], 20.0)
        self.assertTrue(back, "crazyflie2 not running again after power-on")

    def test_e_mocap_frozen_repeats_one_pose_then_moves_again(self):
        self.inject("mocap crazyflie1 --freeze 1")
        t0, r0 = time.monotonic(), rospy.Time.now()     # the freeze is on by the time the service answers
        world_window(self.world, 0.5)
        # captured after that (a frame's stamp is its capture time), not frames still on their way
        frozen = [m for t, m in self.vicon.since(t0) if m.header.stamp > r0]
        self.assertGreater(len(frozen), 20)
        self.assertEqual(len({(m.transform.translation.x, m.transform.translation.y) for m in frozen}), 1)
        self.assertEqual(len({m.header.stamp for m in frozen}), len(frozen))          # stamps still advance
        world_window(self.world, 1.0)
        t1 = time.monotonic()
        world_window(self.world, 0.3)
        moving = [m for t, m in self.vicon.since(t1)]
        self.assertGreater(len({m.transform.translation.x for m in moving}), len(moving) // 2)

    def test_f_bad_command_changes_nothing_and_says_why(self):
        before = self.world.control("faults")
        for command, says in (("unplug 9", "no simulated dongle 9"), ("battery ghost 3.3", "ghost"),
                              ("latency 0 50", "give a unit"), ("explode", "invalid choice")):
            answer = self.fault(command)
            self.assertFalse(answer.success, command)
            self.assertIn(says, answer.message)
        self.assertEqual(self.world.control("faults"), before)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "sim_faults", SimFaults, sys.argv)
