#!/usr/bin/env python3
"""An unexpected error in a worker's loop: logged, status and /diagnostics say it, setpoints stop,
the worker restarts and flies on; an error that keeps coming removes the Crazyflie."""
from __future__ import annotations

import sys
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist

from crazyflie_driver.nodes.crazyflie_server import start_server
from crazyflie_driver.srv import AddCrazyflieRequest
from support.rostest_support import (
    Repeating,
    TopicRecorder,
    add_crazyflies,
    service_registered,
    start_test_node,
    wait_until,
)

URI = "radio://0/80/2M/E7E7E7E701"
THRUST = 20000.0        # below hover: the vehicle stays on the floor


class InjectedBug(RuntimeError):
    """Stands for a bug in the loop."""


class DriverWorkerFault(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("driver_worker_fault_test")
        cls.server = start_server(timeout=1.0, add_timeout=30.0)
        cls.status = TopicRecorder("/crazyflie1/status", DiagnosticStatus)
        cls.diagnostics = TopicRecorder("/diagnostics", DiagnosticArray)
        add_crazyflies([AddCrazyflieRequest(uri=URI, tf_prefix="crazyflie1", enable_logging=True,
                                            enable_parameters=False)])
        cls.worker = cls.server.registry.get(URI)
        cls.pub = rospy.Publisher("/crazyflie1/cmd_vel", Twist, queue_size=1)
        setpoint = Twist()
        setpoint.linear.z = THRUST
        cls.streamer = Repeating(lambda: cls.pub.publish(setpoint), 0.02)

    @classmethod
    def tearDownClass(cls):
        cls.streamer.stop()

    def firmware(self):
        return self.world.crazyflie_state(URI)

    def my_diagnostic(self):
        def mine(arr):
            return [s for s in arr.status if s.hardware_id == URI]
        arr = self.diagnostics.latest_where(mine)      # the server's, not the world's
        return mine(arr)[0] if arr else None

    def inject(self, times):
        """The next ``times`` setpoint sends raise (a bug's stand-in); returns the count raised."""
        cf = self.worker.cf
        real = cf.send_setpoint
        raised = []

        def buggy(*args):
            if len(raised) < times:
                raised.append(1)
                raise InjectedBug("injected bug %d" % len(raised))
            return real(*args)
        cf.send_setpoint = buggy
        return raised

    def test_a_error_is_reported_and_the_worker_restarts(self):
        self.assertTrue(wait_until(lambda: (self.firmware()["last_setpoint"] or [0])[-1] == THRUST, 10.0))
        self.assertTrue(wait_until(lambda: self.my_diagnostic() is not None, 5.0))
        self.assertEqual(self.my_diagnostic().level, DiagnosticStatus.OK)
        raised = self.inject(1)
        self.assertTrue(wait_until(lambda: raised, 5.0))
        # status: an error while restarting, then a warning that names the error (latched topic)
        self.assertTrue(wait_until(lambda: any(m.level == DiagnosticStatus.ERROR and "injected bug 1" in m.message
                                               for _, m in self.status.messages), 5.0),
                        [m.message for _, m in self.status.messages])
        self.assertTrue(wait_until(lambda: self.status.latest().level == DiagnosticStatus.WARN, 5.0))
        self.assertIn("restarted 1 time", self.status.latest().message)
        diag = wait_until(lambda: (lambda d: d if d and d.level == DiagnosticStatus.WARN else None)(
            self.my_diagnostic()), 5.0)
        self.assertIsNotNone(diag)
        self.assertEqual({kv.key: kv.value for kv in diag.values}["restarts"], "1")
        # and the Crazyflie is flown again: new setpoints reach the firmware
        before = self.firmware()["setpoints"]
        self.assertTrue(wait_until(lambda: self.firmware()["setpoints"] > before + 20, 5.0))
        self.assertEqual(self.firmware()["last_setpoint"][-1], THRUST)

    def test_b_an_error_that_keeps_coming_removes_the_crazyflie(self):
        self.inject(1000)
        self.assertTrue(wait_until(lambda: (lambda d: d is not None and d.message.startswith("removed"))(
            self.my_diagnostic()), 10.0), self.my_diagnostic())
        self.assertEqual(self.my_diagnostic().level, DiagnosticStatus.ERROR)
        self.assertTrue(wait_until(lambda: not service_registered("/crazyflie1/emergency"), 5.0))
        with self.assertRaises(KeyError):
            self.server.registry.get(URI)
        # nothing reaches the firmware any more: its watchdog takes it
        packets = sum(self.firmware()["packets_by_port"].values())
        rospy.sleep(0.5)
        self.assertEqual(sum(self.firmware()["packets_by_port"].values()), packets)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "driver_worker_fault", DriverWorkerFault, sys.argv)
