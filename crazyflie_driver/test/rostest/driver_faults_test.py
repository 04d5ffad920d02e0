#!/usr/bin/env python3
"""Faults never take the server down and never disturb the other Crazyflies."""
from __future__ import annotations

import sys
import time
import unittest

import rospy
import rostest
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import Imu

from crazyflie_driver.msg import LogBlock
from crazyflie_driver.srv import AddCrazyflie, AddCrazyflieRequest, UpdateParams
from support.rostest_support import RosoutRecorder, TopicRecorder, rates_per_world_second, start_test_node, wait_until

NAMES = ("crazyflie1", "crazyflie2", "crazyflie3")


def add_request(uri: str, tf_prefix: str, blocks=()) -> AddCrazyflieRequest:
    req = AddCrazyflieRequest()
    req.uri, req.tf_prefix = uri, tf_prefix
    req.enable_logging = req.enable_parameters = True
    req.log_blocks = list(blocks)
    return req


class DriverFaults(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("driver_faults_test", NAMES)
        cls.rosout = RosoutRecorder("/crazyflie_server")
        cls.imu = {n: TopicRecorder("/%s/imu" % n, Imu) for n in NAMES}
        cls.add = rospy.ServiceProxy("/add_crazyflie", AddCrazyflie)
        wait_until(lambda: all(r.count() > 10 for r in cls.imu.values()), 10.0)

    def rates(self, seconds: float, during=None):
        """IMU messages per second of world time (see rates_per_world_second)."""
        return rates_per_world_second(self.imu, self.world, seconds, during)

    def test_a_absent_crazyflie_is_a_clear_error_and_others_keep_flowing(self):
        # One attempt takes ~0.1 s, too short to measure a 100 Hz rate (one message is 10 Hz and
        # the ROS pipeline's jitter is several): the absent Crazyflie is tried again and again
        # for 3 s and crazyflie1, on the same dongle, is measured over all of it. Each attempt
        # is 10 unacked greetings of 4.3 ms (3 retransmissions + an address switch), and the
        # dongle's FIFO gives it every third round trip; back to back (~7 attempts/s) it would
        # hold ~30 % of the dongle, and the two Crazyflies' 2 x 120 log packets/s at 2.3 ms need
        # 55 %, which with the host's ~0.5 ms per round trip saturates it. A pause of 0.2 s
        # between attempts (the ghost holds ~15 %) asks what the test means: an absent
        # Crazyflie being added does not starve the ones already served.
        errors, took = [], []

        def try_absent():
            t = time.monotonic()
            try:
                self.add(add_request("radio://0/80/2M/E7E7E7E7AA", "ghost"))
                errors.append(None)
            except rospy.ServiceException as e:
                errors.append(str(e))
            took.append(time.monotonic() - t)
            time.sleep(0.2)

        rates = self.rates(3.0, during=try_absent)
        print("IMU per world second while an absent Crazyflie is tried %d times: %s" % (len(errors), rates))
        self.assertTrue(errors)
        for e in errors:
            self.assertIsNotNone(e, "adding an absent Crazyflie succeeded")
            self.assertIn("E7E7E7E7AA", e)
            self.assertIn("no answer", e)
        self.assertLess(max(took), 10.0)
        # served while the absent one was being tried (its greetings take a third of the dongle)
        self.assertGreater(rates["crazyflie1"], 70.0, (rates, len(errors)))
        self.assertFalse(rospy.has_param("/ghost/ring/headlightEnable"))

    def test_b_bad_custom_blocks_are_refused_with_the_reason(self):
        too_big = LogBlock(topic_name="big", frequency=10,
                           variables=["acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z", "pm.vbat"])
        with self.assertRaises(rospy.ServiceException) as ctx:
            self.add(add_request("radio://0/80/2M/E7E7E7E701", "again"))
        self.assertIn("already served", str(ctx.exception))
        self.world.add_crazyflie("radio://0/80/2M/E7E7E7E704", name="crazyflie4", position=(1.0, 1.0, 0.0))
        with self.assertRaises(rospy.ServiceException) as ctx:
            self.add(add_request("radio://0/80/2M/E7E7E7E704", "crazyflie4", [too_big]))
        self.assertIn("26", str(ctx.exception))
        unknown = LogBlock(topic_name="u", frequency=10, variables=["nosuch.var"])
        with self.assertRaises(rospy.ServiceException) as ctx:
            self.add(add_request("radio://0/80/2M/E7E7E7E704", "crazyflie4", [unknown]))
        self.assertIn("nosuch.var", str(ctx.exception))

    def test_c_packet_loss_30_percent(self):
        try:
            self.world.set_dongle_faults(0, packet_loss=30.0)
            rates = self.rates(4.0)
            print("IMU per world second with 30 %% loss on dongle 0: %s" % rates)
            self.assertGreater(rates["crazyflie3"], 85.0)      # the other dongle: unaffected
            for name in ("crazyflie1", "crazyflie2"):
                self.assertGreater(rates[name], 40.0, rates)   # degraded but served
            self.assertTrue(wait_until(lambda: self.rosout.find("link quality", Log.WARN), 5.0))
            rospy.ServiceProxy("/crazyflie1/update_params", UpdateParams)([])   # server answers
        finally:
            self.world.set_dongle_faults(0, packet_loss=0.0)
        rates = self.rates(2.0)
        self.assertGreater(min(rates.values()), 85.0, rates)

    def test_d_dongle_unplugged_mid_run(self):
        try:
            self.world.set_dongle_faults(1, unplugged=True)
            lost = wait_until(lambda: self.rosout.find("radio://1/90/2M/E7E7E7E703: link lost", Log.ERROR), 5.0)
            self.assertTrue(lost, self.rosout.lines[-5:])
            rates = self.rates(3.0)
            self.assertLess(rates["crazyflie3"], 1.0)
            self.assertGreater(rates["crazyflie1"], 85.0, rates)
            self.assertGreater(rates["crazyflie2"], 85.0, rates)
            rospy.ServiceProxy("/crazyflie3/update_params", UpdateParams)([])   # still answering
        finally:
            self.world.set_dongle_faults(1, unplugged=False)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "driver_faults", DriverFaults, sys.argv)
