#!/usr/bin/env python3
"""cmd_vel stops while flying (a teleop with autorepeat off and a still stick does exactly this).

The firmware's watchdog stops the motors 2 s after the last setpoint; crazyflie_server must say so
once per Crazyflie, on /rosout and on its status topic, with the advice its firmware calls for:
current firmware (crazyflie1) is locked by its supervisor until restarted, 2016.02 (crazyflie2) only
set its thrust lock again, released by a setpoint with thrust 0. Said again only after the
Crazyflie flew again: never for the locked one (its later thrust does nothing), once more for the
2016.02 one after thrust 0, a second flight and a second stop. Judged on the world's truth too.
"""
from __future__ import annotations

import sys
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Twist
from rosgraph_msgs.msg import Log

from crazyflie_driver.sim.world_clock import WorldClock
from support.rostest_support import (
    Repeating,
    RosoutRecorder,
    TopicRecorder,
    start_test_node,
    wait_connected,
    wait_until,
)

URIS = {"crazyflie1": "radio://0/80/2M/E7E7E7E701", "crazyflie2": "radio://0/80/2M/E7E7E7E702"}
THRUST = 42000            # counts: climbs (a hover needs about 36 300)
NOTICE = "watchdog stopped the motors"


class Stick:
    """A cmd_vel source at 50 Hz (a teleop with autorepeat), switched on and off by the test."""

    def __init__(self, name: str) -> None:
        self.pub = rospy.Publisher("/%s/cmd_vel" % name, Twist, queue_size=1)
        self.thrust = None
        self.stream = Repeating(self.send, 0.02)

    def send(self) -> None:
        if self.thrust is not None:
            msg = Twist()
            msg.linear.z = self.thrust
            self.pub.publish(msg)


class WatchdogNotice(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("watchdog_notice_test", URIS)
        cls.clock = WorldClock(cls.world.ping)
        cls.rosout = RosoutRecorder("/crazyflie_server")
        cls.status = {n: TopicRecorder("/%s/status" % n, DiagnosticStatus) for n in URIS}
        cls.sticks = {n: Stick(n) for n in URIS}
        assert wait_connected([s.pub for s in cls.sticks.values()], 10.0)

    @classmethod
    def tearDownClass(cls):
        for s in cls.sticks.values():
            s.thrust = 0.0
        rospy.sleep(0.2)
        for s in cls.sticks.values():
            s.stream.stop()

    def state(self, name):
        return self.world.control("vehicle_state", uri=URIS[name])

    def notices(self, name):
        return [m for m in self.rosout.find(NOTICE, Log.WARN) if m.startswith(URIS[name])]

    def fly_then_stop(self, names):
        for n in names:
            self.sticks[n].thrust = THRUST
        up = self.clock.wait_until(lambda: all(self.state(n)["position"][2] > 0.3 for n in names), 10.0)[0]
        self.assertTrue(up, "did not take off: %s" % {n: self.state(n)["position"] for n in names})
        for n in names:
            self.sticks[n].thrust = None          # the stick held still, nothing repeats it
        return self.clock.now()

    def test_said_once_with_the_advice_and_again_only_after_flying_again(self):
        stopped_at = self.fly_then_stop(list(URIS))
        for n in URIS:
            self.assertTrue(wait_until(lambda: self.notices(n), 8.0), "nothing said for %s" % n)
        off = self.clock.wait_until(lambda: all(max(self.state(n)["motors"]) == 0 for n in URIS), 5.0)
        self.assertTrue(off[0])
        print("WATCHDOG motors of both off %.2f s (world) after the last cmd_vel" % (off[1] - stopped_at))
        one, two = self.notices("crazyflie1")[0], self.notices("crazyflie2")[0]
        print("WATCHDOG crazyflie1: %s\nWATCHDOG crazyflie2: %s" % (one, two))
        self.assertIn("supervisor locked it", one)
        self.assertIn("restart it", one)
        self.assertEqual(self.state("crazyflie1")["locked"], "setpoint watchdog")
        self.assertIn("setpoint with thrust 0", two)
        self.assertEqual(self.state("crazyflie2")["locked"], "")
        for n in URIS:
            self.assertTrue(wait_until(lambda: "motors stopped" in (self.status[n].latest() or
                                                                     DiagnosticStatus()).message, 3.0))
        self.assertEqual(self.status["crazyflie1"].latest().level, DiagnosticStatus.ERROR)

        # thrust again without thrust 0: neither flies, nothing new is said
        for n in URIS:
            self.sticks[n].thrust = THRUST
        self.clock.sleep(1.0)
        for n in URIS:
            self.assertEqual(max(self.state(n)["motors"]), 0, n)
            self.sticks[n].thrust = None
        self.clock.sleep(3.0)
        self.assertEqual(len(self.notices("crazyflie1")), 1, self.notices("crazyflie1"))
        self.assertEqual(len(self.notices("crazyflie2")), 1, self.notices("crazyflie2"))

        # 2016.02: thrust 0 releases the thrust lock; it flies again, stops again: said a second time
        self.sticks["crazyflie2"].thrust = 0.0
        self.clock.sleep(0.3)
        self.fly_then_stop(["crazyflie2"])
        self.assertTrue(wait_until(lambda: len(self.notices("crazyflie2")) == 2, 8.0), self.notices("crazyflie2"))
        self.clock.sleep(1.0)
        self.assertEqual(len(self.notices("crazyflie2")), 2)
        self.assertEqual(len(self.notices("crazyflie1")), 1)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "watchdog_notice", WatchdogNotice, sys.argv)
