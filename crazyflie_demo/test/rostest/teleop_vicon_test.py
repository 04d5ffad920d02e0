#!/usr/bin/env python3
"""teleop_vicon.launch sim:=true auto:=true joy:=true: the sticks move the goal, the vehicle follows.

The autopilot takes off to (0, 0, 0.5); then the test deflects one stick at a time on a fake
joystick (a FIFO carrying js_event records, read by the launch file's joy node) laid out as an
Xbox 360 pad: right stick y (axis 4) moves the goal in x, right stick x (axis 3) in y, left
stick y (axis 1) in z; up / left is +. The goal published by publish_pose_teleop.py must move
that way and by about speed x scaled deflection x time, only along that axis; the vehicle,
judged by the world's true position, must follow it there.

Private params: ``sim_address``, ``joy_dev`` (the FIFO), ``deadzone`` (the joy node's, 0.05).
"""
from __future__ import annotations

import sys
import threading
import time
import unittest
from typing import List, Optional, Tuple

import rospy
import rostest
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import Joy

from crazyflie_demo.fake_joystick import FakeJoystick
from support.flight_support import WorldProbe, distance, inbound_connected, wait_until

NAME = "crazyflie"
START = (0.0, 0.0, 0.5)
AXIS_X, AXIS_Y, AXIS_Z = 4, 3, 1              # publish_pose_teleop.py's default axes
SPEED = {AXIS_X: 1.0, AXIS_Y: 1.0, AXIS_Z: 0.5}   # m/s at full deflection (its defaults)
DEFLECTION = 0.5                               # of the raw range, up / left
HOLD_S = 1.0


def raw_up(fraction: float) -> int:
    """Raw kernel value of a stick pushed up / left by ``fraction`` (negative is up / left)."""
    return -int(round(fraction * 32767))


class Latest:
    """The last message of a topic (and all of them, in ``history``)."""

    def __init__(self, topic: str, msg_type) -> None:
        self.lock = threading.Lock()
        self.msg: Optional[object] = None
        self.history: List[object] = []
        self.sub = rospy.Subscriber(topic, msg_type, self.on_msg, queue_size=10)

    def on_msg(self, msg) -> None:
        with self.lock:
            self.msg = msg
            self.history.append(msg)

    def since(self, index: int) -> List[object]:
        with self.lock:
            return self.history[index:]

    def get(self):
        with self.lock:
            return self.msg


def goal_xyz(msg: PoseStamped) -> Tuple[float, float, float]:
    p = msg.pose.position
    return (p.x, p.y, p.z)


class TeleopVicon(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("teleop_vicon_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.probe.wait_ready([NAME])
        deadzone = float(rospy.get_param("~deadzone", 0.05))
        cls.scaled = (DEFLECTION - deadzone) / (1.0 - deadzone)   # what the joy node reports
        cls.goal = Latest("/%s/goal" % NAME, PoseStamped)
        cls.joy = Latest("/%s/joy" % NAME, Joy)
        # the joy node publishes the initial state once: plug in only when both readers are connected
        joy_topic = "/%s/joy" % NAME
        if not wait_until(lambda: cls.joy.sub.get_num_connections() > 0
                          and inbound_connected("/%s/pose" % NAME, joy_topic, rospy.get_name()), 20.0):
            raise AssertionError("%s: the joy node and publish_pose_teleop.py never connected" % joy_topic)
        cls.pad = FakeJoystick(rospy.get_param("~joy_dev"), axes=8, buttons=11)
        cls.pad.plug_in(timeout=20.0)        # joy_node retries every second until the FIFO exists
        if not wait_until(lambda: cls.joy.get() is not None, 10.0):
            raise AssertionError("the joy node never published the fake joystick's state")

    @classmethod
    def tearDownClass(cls):
        cls.pad.close()

    def stick(self, axis: int, fraction: float, seconds: float) -> Tuple[float, float]:
        """Deflect a stick for about ``seconds``; the joy node's reported value while it was held, and
        for how long it reported it held (from the stamps of its messages: the interval the goal's
        node integrated over, whatever this thread's own sleep came to)."""
        first = len(self.joy.since(0))
        self.pad.move_axis(axis, raw_up(fraction))
        ok = wait_until(lambda: abs(self.joy.get().axes[axis]) > 0.0, 2.0, period=0.01)
        self.assertTrue(ok, "the joy node did not report axis %d" % axis)
        value = self.joy.get().axes[axis]
        time.sleep(seconds)
        self.pad.move_axis(axis, 0)
        self.assertTrue(wait_until(lambda: self.joy.get().axes[axis] == 0.0, 2.0, period=0.01))
        msgs = self.joy.since(first)
        deflected = next(m for m in msgs if m.axes[axis] != 0.0)
        centred = next(m for m in msgs if m.axes[axis] == 0.0 and m.header.stamp > deflected.header.stamp)
        return value, (centred.header.stamp - deflected.header.stamp).to_sec()

    def steady_goal(self) -> Tuple[float, float, float]:
        """The goal once it has stopped moving (the stick is centred)."""
        last: List[Tuple[float, float, float]] = [goal_xyz(self.goal.get())]

        def still() -> bool:
            g = goal_xyz(self.goal.get())
            same = distance(g, last[0]) < 1e-6
            last[0] = g
            return same
        self.assertTrue(wait_until(still, 3.0, period=0.2), "the goal keeps moving with the stick centred")
        return last[0]

    def move(self, axis: int, index: int, label: str) -> None:
        """One stick, up / left: the goal moves + along ``index`` only; the vehicle follows."""
        g0 = self.steady_goal()
        p0 = self.probe.position(NAME)
        value, held = self.stick(axis, DEFLECTION, HOLD_S)
        g1 = self.steady_goal()
        moved = [b - a for a, b in zip(g0, g1)]
        expected = SPEED[axis] * value * held
        print("TELEOP_VICON %s: joy %.3f for %.2f s, goal moved %s (expected %+.3f along %s)"
              % (label, value, held, ["%+.3f" % m for m in moved], expected, "xyz"[index]))
        self.assertAlmostEqual(value, self.scaled, delta=0.01, msg="joy value for %s" % label)
        # the goal integrates at the node's rate: allow one period's worth and the event latency
        self.assertGreater(moved[index], 0.0, "stick %s must move the goal +%s" % (label, "xyz"[index]))
        self.assertAlmostEqual(moved[index], expected, delta=0.25 * expected, msg=label)
        for k in range(3):
            if k != index:
                self.assertAlmostEqual(moved[k], 0.0, delta=1e-6, msg="goal %s must not move" % "xyz"[k])
        t0 = self.probe.clock.now()
        reached = self.probe.wait_near(NAME, g1, 0.05, 8.0)
        p1 = self.probe.position(NAME)
        print("TELEOP_VICON %s: vehicle %s -> %s, within 5 cm of the goal after %.1f world s"
              % (label, ["%.3f" % c for c in p0], ["%.3f" % c for c in p1], self.probe.clock.now() - t0))
        self.assertTrue(reached, "%s: vehicle at %s never came within 5 cm of the goal %s" % (label, p1, g1))
        self.assertGreater(p1[index] - p0[index], 0.75 * moved[index], "%s: vehicle did not follow" % label)

    def test_sticks_move_the_goal_and_the_vehicle_follows(self):
        t0 = self.probe.clock.now()
        took_off = self.probe.wait_near(NAME, START, 0.05, 30.0)
        self.assertTrue(took_off, "the autopilot's take-off never reached %s (at %s)"
                        % (START, self.probe.position(NAME)))
        self.assertTrue(self.probe.wait_near(NAME, START, 0.02, 10.0), "never settled at %s" % (START,))
        print("TELEOP_VICON hovering within 2 cm of the start point after %.1f world s" % (self.probe.clock.now() - t0))
        self.assertEqual(self.steady_goal(), START)
        self.move(AXIS_X, 0, "right stick forward")
        self.move(AXIS_Y, 1, "right stick left")
        self.move(AXIS_Z, 2, "left stick up")
        # and it stays at the last goal with the sticks centred
        goal = self.steady_goal()
        self.probe.sleep(2.0)          # of flight: the world's time
        off = distance(self.probe.position(NAME), goal)
        print("TELEOP_VICON 2 s after the last move: %.3f m from the goal %s" % (off, goal))
        self.assertLess(off, 0.02)
        self.assertFalse(self.probe.state(NAME)["on_ground"])


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "teleop_vicon", TeleopVicon, sys.argv)
