#!/usr/bin/env python3
"""joy_node + quadrotor_teleop from xbox360.launch and ps3.launch, driven by fake joysticks.

Each stick is moved on the fake device (raw kernel values: -32767 = up / left) and the test waits
for the cmd_vel that the chapter's mapping gives: right stick pitch/roll +-30 deg, left stick
thrust 0..60000 and yaw rate +-200 deg/s. Unplugging the joystick must zero cmd_vel.
"""
from __future__ import annotations

import math
import sys
import threading
import time
import unittest
from typing import List, Optional, Tuple

import rospy
import rostest
from geometry_msgs.msg import Twist

from crazyflie_demo.fake_joystick import FakeJoystick
from crazyflie_demo.joystick import scale_axis
from support.flight_support import inbound_connected, wait_until

UP, DOWN, LEFT, RIGHT = -32767, 32767, -32767, 32767
Fields = Tuple[float, float, float, float]    # linear.x, linear.y, linear.z, angular.z


class CmdVelProbe:
    def __init__(self, topic: str) -> None:
        self._lock = threading.Lock()
        self._last: Optional[Fields] = None
        self.count = 0
        self._sub = rospy.Subscriber(topic, Twist, self._on_twist, queue_size=50)

    def connected(self) -> bool:
        return self._sub.get_num_connections() > 0

    def _on_twist(self, msg: Twist) -> None:
        with self._lock:
            self._last = (msg.linear.x, msg.linear.y, msg.linear.z, msg.angular.z)
            self.count += 1

    def wait_for(self, expected: Fields, timeout: float = 5.0) -> Optional[Fields]:
        """The last cmd_vel once it equals ``expected`` (within 1e-3), or what came last."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                last = self._last
            if last is not None and all(math.isclose(a, b, abs_tol=1e-3) for a, b in zip(last, expected)):
                return last
            time.sleep(0.01)
        return None

    @property
    def last(self) -> Optional[Fields]:
        with self._lock:
            return self._last


def wait_for_pipeline(ns: str, probe: CmdVelProbe, timeout: float) -> None:
    """Block until joy -> quadrotor_teleop -> this test is connected in namespace ``ns``.

    joy_node publishes the initial stick state once, when it opens the device; a connection still
    being set up would lose it, so the fake joystick is plugged in only after both hops are live.
    """
    if not wait_until(lambda: probe.connected() and inbound_connected(
            "/%s/quadrotor_teleop" % ns, "/%s/joy" % ns, rospy.get_name()), timeout):
        raise AssertionError("%s: joy -> quadrotor_teleop -> test not connected after %.0f s" % (ns, timeout))


class JoyTeleop(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("joy_teleop_test")
        cls.pads = {}
        cls.probes = {}
        for ns, axes in (("xbox", 8), ("ps3", 4)):
            cls.probes[ns] = CmdVelProbe("/%s/cmd_vel" % ns)
            wait_for_pipeline(ns, cls.probes[ns], timeout=20.0)
            pad = FakeJoystick(rospy.get_param("~%s_dev" % ns), axes=axes, buttons=11)
            pad.plug_in(timeout=20.0)       # joy_node retries every second until the FIFO exists
            cls.pads[ns] = pad
        deadline = time.monotonic() + 20.0   # teleop connected and the initial state through
        while time.monotonic() < deadline and not all(p.last is not None for p in cls.probes.values()):
            time.sleep(0.05)

    @classmethod
    def tearDownClass(cls):
        for pad in cls.pads.values():
            pad.close()

    def check(self, ns: str, moves: List[Tuple[int, int]], expected: Fields) -> None:
        self.pads[ns].move_axes(moves)
        got = self.probes[ns].wait_for(expected)
        self.assertIsNotNone(got, "%s: after moving %s expected cmd_vel %s, last was %s"
                             % (ns, moves, expected, self.probes[ns].last))

    def centre(self, ns: str) -> None:
        self.check(ns, [(i, 0) for i in range(len(self.pads[ns].axes))], (0.0, 0.0, 0.0, 0.0))

    def test_1_initial_state_is_zero(self):
        for ns in ("xbox", "ps3"):
            self.assertEqual((0.0, 0.0, 0.0, 0.0), self.probes[ns].wait_for((0.0, 0.0, 0.0, 0.0)), ns)

    def test_2_xbox360_sticks(self):
        half = 60000.0 * scale_axis(-16384, 0.05)
        self.check("xbox", [(4, UP)], (30.0, 0.0, 0.0, 0.0))          # right stick up: pitch
        self.check("xbox", [(4, DOWN)], (-30.0, 0.0, 0.0, 0.0))
        self.centre("xbox")
        self.check("xbox", [(3, LEFT)], (0.0, -30.0, 0.0, 0.0))       # right stick left: roll
        self.check("xbox", [(3, RIGHT)], (0.0, 30.0, 0.0, 0.0))
        self.centre("xbox")
        self.check("xbox", [(1, UP)], (0.0, 0.0, 60000.0, 0.0))       # left stick up: thrust
        self.check("xbox", [(1, -16384)], (0.0, 0.0, half, 0.0))
        self.check("xbox", [(1, DOWN)], (0.0, 0.0, 0.0, 0.0))         # fully down: no thrust
        self.centre("xbox")
        self.check("xbox", [(0, LEFT)], (0.0, 0.0, 0.0, -200.0))      # left stick: yaw rate
        self.check("xbox", [(0, RIGHT)], (0.0, 0.0, 0.0, 200.0))
        self.check("xbox", [(2, DOWN), (5, DOWN)], (0.0, 0.0, 0.0, 200.0))   # triggers: unused
        self.centre("xbox")

    def test_3_ps3_sticks(self):
        self.check("ps3", [(3, UP)], (30.0, 0.0, 0.0, 0.0))
        self.check("ps3", [(2, LEFT)], (30.0, -30.0, 0.0, 0.0))
        self.check("ps3", [(1, UP)], (30.0, -30.0, 60000.0, 0.0))
        self.check("ps3", [(0, RIGHT)], (30.0, -30.0, 60000.0, 200.0))
        self.centre("ps3")

    def test_4_unplug_zeroes_cmd_vel_and_the_joystick_comes_back(self):
        self.check("xbox", [(1, UP), (4, UP)], (30.0, 0.0, 60000.0, 0.0))
        self.pads["xbox"].unplug()
        self.assertIsNotNone(self.probes["xbox"].wait_for((0.0, 0.0, 0.0, 0.0)),
                             "unplugged with thrust up, cmd_vel stayed %s" % (self.probes["xbox"].last,))
        pad = self.pads["xbox"]
        pad.axes = [0] * len(pad.axes)
        pad.plug_in(timeout=10.0)
        self.check("xbox", [(0, LEFT)], (0.0, 0.0, 0.0, -200.0))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "joy_teleop", JoyTeleop, sys.argv)
