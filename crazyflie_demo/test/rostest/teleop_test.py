#!/usr/bin/env python3
"""teleop_xbox360.launch sim:=true flown by a simulated pilot through a joystick device.

The test writes Linux joystick events (struct js_event) into the FIFO the launch file's joy_dev
points at, laid out as the xpad driver reports an Xbox 360 pad: axis 0/1 left stick x/y, 3/4
right stick x/y; pushing a stick up or left gives a negative raw value. The chain under test is
joy node -> teleop node -> crazyflie_server -> fake radio -> simulated Crazyflie.

Like a human pilot, the test holds the height itself with the thrust stick (from the world's
true height) while it checks each stick moves the vehicle the right way, judged by the world's
true state: thrust stick up climbs; right stick forward flies +x; right stick left flies +y;
left stick left turns counter-clockwise (positive yaw rate). Then a stick held still, as a pilot
holding a steady climb does: no joystick event for longer than the firmware's 2 s setpoint watchdog,
and the Crazyflie must keep flying (the joy node repeats the state, so setpoints keep flowing).
"""
from __future__ import annotations

import math
import os
import struct
import sys
import threading
import time
import unittest

import rospy
import rostest
from sensor_msgs.msg import Joy

from support.flight_support import WorldProbe, wait_until

NAME = "crazyflie"
JS_EVENT_BUTTON, JS_EVENT_AXIS, JS_EVENT_INIT = 0x01, 0x02, 0x80
YAW_STICK, THRUST_STICK, ROLL_STICK, PITCH_STICK = 0, 1, 3, 4     # xpad: left x, left y, right x, right y
AXES, BUTTONS = 8, 11
STILL_THRUST = 37500.0      # counts: a little above the ~36300 a hover needs
STILL_S = 3.5               # world s without a joystick event: longer than the firmware's 2 s watchdog


def js_event(ms: int, value: int, kind: int, number: int) -> bytes:
    """struct js_event { __u32 time; __s16 value; __u8 type; __u8 number; }"""
    return struct.pack("<IhBB", ms & 0xFFFFFFFF, int(max(-32767, min(32767, value))), kind, number)


class Pad:
    """A joystick device: a FIFO the test holds open for reading and writing, so the joy node
    never sees end-of-file, whenever it opens it (it retries a missing device every second)."""

    def __init__(self, path: str, deadzone: float) -> None:
        if os.path.exists(path):
            os.unlink(path)
        os.mkfifo(path)
        self.path = path
        self.deadzone = deadzone
        self.fd = os.open(path, os.O_RDWR | os.O_NONBLOCK)
        self.t0 = time.monotonic()
        self.lock = threading.Lock()
        for n in range(AXES):
            self._write(0, JS_EVENT_AXIS | JS_EVENT_INIT, n)
        for n in range(BUTTONS):
            self._write(0, JS_EVENT_BUTTON | JS_EVENT_INIT, n)

    def _write(self, value: int, kind: int, number: int) -> None:
        with self.lock:
            os.write(self.fd, js_event(int((time.monotonic() - self.t0) * 1000), value, kind, number))

    def stick(self, axis: int, deflection: float) -> None:
        """deflection in -1..1 with +1 = up or left: the raw value is then negative, and outside
        the joy node's deadzone by as much as the node scales it back."""
        d = max(-1.0, min(1.0, deflection))
        raw = 0.0 if d == 0 else math.copysign(self.deadzone + abs(d) * (1.0 - self.deadzone), d)
        self._write(int(round(-raw * 32767)), JS_EVENT_AXIS, axis)

    def close(self) -> None:
        os.close(self.fd)
        os.unlink(self.path)


class HeightPilot:
    """Holds a height with the thrust stick, as a pilot watching the vehicle would."""

    def __init__(self, pad: Pad, probe: WorldProbe, thrust_max: float, target: float) -> None:
        self.pad, self.probe, self.thrust_max, self.target = pad, probe, thrust_max, target
        self.hover = 36000.0          # thrust counts; the integrator finds the real value
        self.integral = 0.0
        self.stop = threading.Event()
        self.error: Exception | None = None
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        try:
            while not self.stop.is_set():
                s = self.probe.state(NAME)
                z, vz = s["position"][2], s["velocity"][2]
                err = self.target - z
                if not s["on_ground"]:
                    self.integral = max(-0.5, min(0.5, self.integral + err * 0.02))
                thrust = self.hover + 8000.0 * err - 6000.0 * vz + 8000.0 * self.integral
                self.pad.stick(THRUST_STICK, max(0.0, min(1.0, thrust / self.thrust_max)))
                self.stop.wait(0.02)
        except Exception as e:   # reported by the test
            self.error = e


class TeleopXbox360(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("teleop_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.probe.wait_ready([NAME])
        cls.thrust_max = float(rospy.get_param("~thrust_max", 60000.0))
        rospy.wait_for_service("/%s/emergency" % NAME, 60.0)      # the Crazyflie is on the server
        cls.pad = Pad(rospy.get_param("~joy_dev"), float(rospy.get_param("/%s/joy/deadzone" % NAME, 0.05)))
        cls.joy = []
        rospy.Subscriber("/%s/joy" % NAME, Joy, cls.joy.append, queue_size=100)
        cls.pad.stick(YAW_STICK, 0.0)
        if not wait_until(lambda: cls.joy, 10.0):
            raise AssertionError("the joy node never published what the pad sent")

    @classmethod
    def tearDownClass(cls):
        cls.pad.close()

    def hold(self, axis: int, deflection: float, seconds: float) -> dict:
        """Deflect a stick for ``seconds`` of flight (world time); the true state before and after."""
        before = self.probe.state(NAME)
        self.pad.stick(axis, deflection)
        self.probe.sleep(seconds)
        self.pad.stick(axis, 0.0)
        return {"before": before, "after": self.probe.state(NAME)}

    def test_still_stick_keeps_flying(self):
        """After test_each_...: one thrust setting a little above hover, then no event for 3.5 s."""
        self.assertTrue(wait_until(lambda: self.probe.state(NAME)["on_ground"], 15.0), "not back on the ground")
        self.pad.stick(THRUST_STICK, STILL_THRUST / self.thrust_max)
        self.assertTrue(wait_until(lambda: not self.probe.state(NAME)["on_ground"], 10.0), "did not lift off")
        t0 = rospy.Time.now()
        z0 = self.probe.state(NAME)["position"][2]
        self.probe.sleep(STILL_S)          # world seconds (the watchdog's clock); nothing written meanwhile
        s = self.probe.state(NAME)
        repeats = [m for m in self.joy if m.header.stamp > t0]
        print("TELEOP still stick: %d Joy messages in %.1f s, z %.2f -> %.2f m, motors %s, lock %r"
              % (len(repeats), STILL_S, z0, s["position"][2], s["motors"], s["locked"]))
        try:
            self.assertFalse(s["on_ground"], "the Crazyflie came down with the stick held still")
            self.assertGreater(min(s["motors"]), 0, "motors cut with the stick held still")
            self.assertEqual(s["locked"], "", "the firmware locked the Crazyflie with the stick held still")
            self.assertGreater(s["position"][2], z0, "a thrust above hover must keep climbing")
            span = (repeats[-1].header.stamp - repeats[0].header.stamp).to_sec() if len(repeats) > 1 else 0.0
            self.assertGreater(span, STILL_S - 1.0, "Joy messages stopped while the stick was still")
        finally:
            pilot = HeightPilot(self.pad, self.probe, self.thrust_max, 0.0)   # bring it down gently
            wait_until(lambda: self.probe.state(NAME)["position"][2] < 0.1, 10.0)
            pilot.stop.set()
            pilot.thread.join(2.0)
            self.pad.stick(THRUST_STICK, 0.0)

    def test_each_stick_moves_the_vehicle_the_right_way(self):
        # resting on the ground with the sticks centred: nothing moves
        self.probe.sleep(1.0)
        s = self.probe.state(NAME)
        self.assertTrue(s["on_ground"])
        self.assertEqual(max(s["motors"]), 0)

        # thrust stick up: climbs (the pilot then holds 0.5 m)
        pilot = HeightPilot(self.pad, self.probe, self.thrust_max, 0.5)
        try:
            climbed = wait_until(lambda: self.probe.state(NAME)["position"][2] > 0.3, 10.0)
            self.assertTrue(climbed, "thrust stick up did not climb: %s" % (self.probe.state(NAME)["position"],))
            self.assertTrue(wait_until(lambda: abs(self.probe.state(NAME)["velocity"][2]) < 0.1
                                       and abs(self.probe.state(NAME)["position"][2] - 0.5) < 0.1, 10.0))
            print("TELEOP thrust: climbed to %.2f m" % self.probe.state(NAME)["position"][2])

            # right stick forward, then back as much to stop: +x, then slowed down
            r = self.hold(PITCH_STICK, 0.3, 1.0)
            v = r["after"]["velocity"]
            print("TELEOP pitch forward: velocity %s" % ["%.2f" % c for c in v])
            self.assertGreater(v[0], 0.3, "right stick forward should fly +x")
            self.assertLess(abs(v[1]), 0.5 * v[0])
            r = self.hold(PITCH_STICK, -0.3, 1.0)
            self.assertLess(r["after"]["velocity"][0], v[0] - 0.3, "right stick back should brake")

            # right stick left: +y
            r = self.hold(ROLL_STICK, 0.3, 1.0)
            v = r["after"]["velocity"]
            dv_y = v[1] - r["before"]["velocity"][1]
            print("TELEOP roll left: velocity change in y %.2f" % dv_y)
            self.assertGreater(dv_y, 0.3, "right stick left should fly +y")
            self.hold(ROLL_STICK, -0.3, 1.0)

            # left stick left: counter-clockwise, positive yaw rate
            yaw0 = self.probe.yaw(NAME)
            self.hold(YAW_STICK, 0.5, 0.5)
            dyaw = math.remainder(self.probe.yaw(NAME) - yaw0, 2 * math.pi)
            print("TELEOP yaw left: yaw changed %.1f deg" % math.degrees(dyaw))
            self.assertGreater(math.degrees(dyaw), 10.0, "left stick left should turn counter-clockwise")
            self.assertIsNone(pilot.error)
        finally:
            pilot.stop.set()
            pilot.thread.join(2.0)
            self.pad.stick(THRUST_STICK, 0.0)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "teleop", TeleopXbox360, sys.argv)
