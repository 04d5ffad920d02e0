#!/usr/bin/env python3
"""One joystick for every Crazyflie (multi_hover_vicon.launch sim:=true auto:=false).

The launch file runs one joy node on /joy and each Crazyflie's button node reads it through
``joy_topic``. Pressing button 2 on the one fake pad must take both Crazyflies to their points
(judged by the world's true positions); button 1 (emergency) must then stop both motors at once,
and each controller must say so instead of "Automatic: ok".

Private params: ``sim_address``, ``joy_dev`` (the FIFO), ``vehicles`` = [{name, target}].
"""
from __future__ import annotations

import sys
import threading
import time
import unittest

import rospy
import rostest
from sensor_msgs.msg import Joy
from std_msgs.msg import String

from crazyflie_demo.fake_joystick import FakeJoystick
from support.flight_support import WorldProbe, inbound_connected, wait_until

TAKEOFF, EMERGENCY = 2, 1            # the chapter's buttons
EMERGENCY_STATUS = "Idle: emergency stop: restart and re-add the Crazyflie to fly"


class MultiHoverJoy(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("multi_hover_joy_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.vehicles = {v["name"]: tuple(float(c) for c in v["target"]) for v in rospy.get_param("~vehicles")}
        cls.names = sorted(cls.vehicles)
        cls.probe.wait_ready(cls.names)
        cls.lock = threading.Lock()
        cls.status = {n: [] for n in cls.names}
        for n in cls.names:
            rospy.Subscriber("/%s/controller/state" % n, String, cls._on_status(n), queue_size=20)
        cls.buttons = []
        rospy.Subscriber("/joy", Joy, lambda m: cls.buttons.append(list(m.buttons)), queue_size=50)
        # every reader of the one /joy topic connected before the pad sends anything
        readers = ["/%s/joystick_controller" % n for n in cls.names]
        if not wait_until(lambda: all(inbound_connected(r, "/joy", rospy.get_name()) for r in readers), 30.0):
            raise AssertionError("the button nodes %s never connected to /joy" % readers)
        # the take-off is refused without a pose: wait until both controllers have one
        if not wait_until(lambda: all(cls.last_status(n) == "Idle: ok" for n in cls.names), 30.0):
            raise AssertionError("controllers not ready: %s" % {n: cls.last_status(n) for n in cls.names})
        cls.pad = FakeJoystick(rospy.get_param("~joy_dev"), axes=8, buttons=11)
        cls.pad.plug_in(timeout=20.0)        # joy_node retries every second until the FIFO exists

    @classmethod
    def tearDownClass(cls):
        cls.pad.close()

    @classmethod
    def _on_status(cls, name):
        def cb(msg):
            with cls.lock:
                cls.status[name].append(msg.data)
        return cb

    @classmethod
    def last_status(cls, name):
        with cls.lock:
            return cls.status[name][-1] if cls.status[name] else ""

    def press(self, button: int) -> None:
        """Press and release, each seen on /joy."""
        self.pad.set_button(button, True)
        self.assertTrue(wait_until(lambda: self.buttons and self.buttons[-1][button] == 1, 5.0, 0.01),
                        "/joy never showed button %d pressed" % button)
        self.pad.set_button(button, False)
        self.assertTrue(wait_until(lambda: self.buttons[-1][button] == 0, 5.0, 0.01))

    def test_one_pad_takes_off_and_stops_every_crazyflie(self):
        t0 = time.monotonic()
        self.press(TAKEOFF)
        for n in self.names:
            reached = self.probe.wait_near(n, self.vehicles[n], 0.05, 30.0 - (time.monotonic() - t0))
            self.assertTrue(reached, "%s never came within 5 cm of %s after button %d (at %s; controller %r)"
                            % (n, self.vehicles[n], TAKEOFF, self.probe.position(n), self.last_status(n)))
            self.assertEqual(self.last_status(n), "Automatic: ok")
        print("MULTI_JOY both within 5 cm of their points %.1f s after button %d" % (time.monotonic() - t0, TAKEOFF))
        w1 = self.probe.state(self.names[0])["time"]
        self.press(EMERGENCY)
        for n in self.names:
            stopped = wait_until(lambda: max(self.probe.state(n)["motors"]) == 0, 5.0, 0.02)
            self.assertTrue(stopped, "%s motors still running after emergency: %s" % (n, self.probe.state(n)["motors"]))
            # timed in the world from the press to the supervisor's lock, not by this test's polls
            locked_at = self.probe.state(n)["locked_at"]
            self.assertIsNotNone(locked_at, self.probe.state(n))
            self.assertLess(locked_at - w1, 2.0, "%s stopped %.2f world-s after button %d" % (n, locked_at - w1,
                                                                                              EMERGENCY))
            print("MULTI_JOY %s motors stopped %.2f world-s after button %d" % (n, locked_at - w1, EMERGENCY))
        for n in self.names:
            said = wait_until(lambda: self.last_status(n) == EMERGENCY_STATUS, 5.0, 0.05)
            self.assertTrue(said, "%s controller reports %r after emergency" % (n, self.last_status(n)))
            landed = wait_until(lambda: self.probe.state(n)["on_ground"], 5.0, 0.05)
            self.assertTrue(landed, "%s not on the ground after emergency: %s" % (n, self.probe.position(n)))
        # and it stays that way: still stopped, still not "ok", another take-off does nothing
        self.press(TAKEOFF)
        self.probe.sleep(1.0)                  # world seconds: long enough for a take-off to show
        for n in self.names:
            self.assertEqual(self.last_status(n), EMERGENCY_STATUS)
            self.assertEqual(max(self.probe.state(n)["motors"]), 0, "%s motors restarted" % n)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "multi_hover_joy", MultiHoverJoy, sys.argv)
