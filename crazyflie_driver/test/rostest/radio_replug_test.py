#!/usr/bin/env python3
"""Unplug the Crazyradio while a Crazyflie flies, plug it back in, with the reader's command
(``rosrun crazyflie_tools fault unplug 0`` / ``replug 0``).

What a reader sees: one error when the radio goes, saying to plug it back in and that the firmware's
watchdog takes the flying Crazyflie (it does: motors off 2 s after the last setpoint, on the world's
truth); one line when the link is back, with how long it was down; imu and battery data again within
about a second of world time; and the Crazyflie, locked by its supervisor, does not take off again
although the pilot's cmd_vel kept asking for thrust all along.
"""
from __future__ import annotations

import re
import subprocess
import sys
import threading
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Twist
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import Imu
from std_msgs.msg import Float32

from crazyflie_driver.sim.world_clock import WorldClock
from support.rostest_support import RosoutRecorder, TopicRecorder, start_test_node, wait_until

URI = "radio://0/80/2M/E7E7E7E701"
THRUST = 42000            # counts: climbs (a hover needs about 36 300)
BACK_WITHIN_S = 1.0       # world seconds from the re-plug to the first imu and battery message


class RadioReplug(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("radio_replug_test", ["crazyflie1"])
        cls.clock = WorldClock(cls.world.ping)
        cls.rosout = RosoutRecorder("/crazyflie_server")
        cls.imu = TopicRecorder("/crazyflie1/imu", Imu)
        cls.battery = TopicRecorder("/crazyflie1/battery", Float32)
        cls.status = TopicRecorder("/crazyflie1/status", DiagnosticStatus)
        cls.cmd_vel = rospy.Publisher("/crazyflie1/cmd_vel", Twist, queue_size=1)
        assert wait_until(lambda: cls.imu.count() > 10 and cls.battery.count() > 0, 20.0)

    def state(self):
        return self.world.control("vehicle_state", uri=URI)

    def fault(self, *words: str) -> str:
        """The reader's command against this test's world; its one line of output."""
        out = subprocess.run(["rosrun", "crazyflie_tools", "fault", "--address", rospy.get_param("~sim_address")]
                             + list(words), capture_output=True, text=True, timeout=30.0)
        self.assertEqual(out.returncode, 0, out.stderr)
        return out.stdout.strip()

    def test_unplug_while_flying_then_replug(self):
        stop = threading.Event()
        twist = Twist()
        twist.linear.z = THRUST

        def pilot():      # the stick held up the whole time, as a pilot who has not noticed yet
            while not stop.is_set():
                self.cmd_vel.publish(twist)
                stop.wait(0.02)

        flying = threading.Thread(target=pilot, daemon=True)
        flying.start()
        try:
            self.assertTrue(self.clock.wait_until(lambda: self.state()["position"][2] > 0.3, 10.0)[0],
                            "did not take off: %s" % (self.state(),))
            command_at = self.clock.now()
            self.assertIn("dongle 0: unplugged", self.fault("unplug", "0"))
            unplugged_at = self.clock.now()     # out by now: the last setpoint went out after command_at

            lost = wait_until(lambda: self.rosout.find("link lost", Log.ERROR), 5.0)
            self.assertEqual(len(lost), 1, lost)
            self.assertIn("plug it back in", lost[0])
            self.assertIn("it was flying", lost[0])
            # the firmware's watchdog: motors off 2 s after the last setpoint, locked by its supervisor
            plug_pulled_at = self.world.control("dongle_faults", dongle=0)[0]["plug_changed_at"]
            cut = self.clock.wait_until(lambda: max(self.state()["motors"]) == 0, 5.0)[0]
            self.assertTrue(cut, "motors still running: %s" % (self.state(),))
            t_cut = self.state()["locked_at"]          # the lock's own world time, not this poll's
            self.assertIsNotNone(t_cut, self.state())
            self.assertTrue(command_at <= plug_pulled_at <= unplugged_at, (command_at, plug_pulled_at, unplugged_at))
            print("REPLUG motors off %.2f s (world) after the dongle was pulled (the command ran %.2f s)"
                  % (t_cut - plug_pulled_at, unplugged_at - command_at))
            self.assertLess(t_cut - plug_pulled_at, 2.2)
            self.assertGreater(t_cut - command_at, 1.9)        # the watchdog's 2 s, not an earlier stop
            self.assertEqual(self.state()["locked"], "setpoint watchdog")
            said = wait_until(lambda: self.rosout.find("watchdog stopped the motors", Log.WARN), 5.0)
            self.assertEqual(len(said), 1, said)
            self.assertIn("radio link is down", said[0])
            self.assertIn("restart it", said[0])
            self.assertTrue(wait_until(lambda: "link lost" in (self.status.latest() or DiagnosticStatus()).message,
                                       3.0), self.status.latest())

            self.clock.sleep(3.0 - (self.clock.now() - unplugged_at))
            imu0, battery0 = self.imu.count(), self.battery.count()
            self.assertIn("dongle 0: plugged in", self.fault("replug", "0"))
            # from the moment the world plugged it in (rosrun starting the tool is no part of the driver's time)
            replugged_at = self.world.control("dongle_faults", dongle=0)[0]["plug_changed_at"]
            self.assertIsNotNone(replugged_at)
            back, t_back = self.clock.wait_until(
                lambda: self.imu.count() > imu0 and self.battery.count() > battery0, 5.0)
            self.assertTrue(back, "no imu or battery data after the re-plug")
            print("REPLUG imu and battery back %.2f s (world) after the re-plug" % (t_back - replugged_at))
            self.assertLess(t_back - replugged_at, BACK_WITHIN_S)
            restored = wait_until(lambda: self.rosout.find("link restored", Log.WARN), 5.0)
            self.assertEqual(len(restored), 1, restored)
            down = float(re.search(r"link restored after ([0-9.]+) s", restored[0]).group(1))
            self.assertGreater(down, 2.5)
            self.assertLess(down, 10.0)

            # the pilot's stick still asks for thrust: the locked Crazyflie stays down, nothing more is said
            self.clock.sleep(2.0)
            s = self.state()
            self.assertEqual(max(s["motors"]), 0, s)
            self.assertEqual(s["locked"], "setpoint watchdog")
            self.assertEqual(len(self.rosout.find("link lost")), 1)
            self.assertEqual(len(self.rosout.find("watchdog stopped the motors")), 1)
            self.assertIn("motors stopped", self.status.latest().message)
        finally:
            stop.set()
            flying.join(1.0)
            self.world.set_dongle_faults(0, unplugged=False)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "radio_replug", RadioReplug, sys.argv)
