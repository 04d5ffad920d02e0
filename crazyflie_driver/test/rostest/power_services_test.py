#!/usr/bin/env python3
"""The supervisor and power services of crazyflie_server against the simulated world, judged on its truth.

crazyflie1: a parameter is set, then the Crazyflie is rebooted through ``reboot``; the firmware restarts
(its reboot count and uptime say so, its parameters are back to their defaults) and the server, by
itself, sets the parameter again and creates its log blocks again: the battery topic flows again.
crazyflie2, a Brushless Crazyflie: a takeoff before ``arm`` leaves its motors at 0 on the floor; armed,
its motors idle, it takes off to 0.5 m, lands, and disarmed its motors stop.
crazyflie2's EEPROM configuration is read and written through ``read_config``/``write_config``: the
simulated firmware holds the written block, a bad channel is refused and changes nothing.
"""
from __future__ import annotations

import math
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import PointStamped
from std_msgs.msg import Float32
from std_srvs.srv import Empty

from crazyflie_driver.sim.world_clock import WorldClock
from crazyflie_driver.srv import Arm, Land, ReadConfig, Stop, Takeoff, UpdateParams, WriteConfig
from support.rostest_support import Repeating, TopicRecorder, start_test_node, wait_connected, wait_until

URIS = {"crazyflie1": "radio://0/80/2M/E7E7E7E701", "crazyflie2": "radio://0/80/2M/E7E7E7E702"}
PARAM = "ring.headlightEnable"
MOCAP_PERIOD_S = 0.02


class PowerServices(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("power_services_test", list(URIS))
        cls.clock = WorldClock(cls.world.ping)
        for name in URIS:
            for s in ("arm", "recover", "reboot", "power_off", "power_on", "read_config", "write_config"):
                rospy.wait_for_service("/%s/%s" % (name, s), 10.0)
        cls.battery = TopicRecorder("/crazyflie1/battery", Float32)
        cls.mocap = rospy.Publisher("/crazyflie2/external_position", PointStamped, queue_size=1)
        wait_connected([cls.mocap], 5.0)
        cls.mocap_stream = Repeating(cls.send_truth, MOCAP_PERIOD_S)

    @classmethod
    def tearDownClass(cls):
        cls.mocap_stream.stop()

    @classmethod
    def truth(cls, name):
        return cls.world.control("vehicle_state", uri=URIS[name])

    @classmethod
    def firmware(cls, name):
        return cls.world.control("state", uri=URIS[name])

    @classmethod
    def send_truth(cls):
        point = PointStamped()
        point.point.x, point.point.y, point.point.z = cls.truth("crazyflie2")["position"]
        cls.mocap.publish(point)

    def update_params(self, name, params):
        for key, value in params.items():
            rospy.set_param("/%s/%s" % (name, key), value)
        rospy.ServiceProxy("/%s/update_params" % name, UpdateParams)(list(params))

    def test_a_reboot_and_the_server_sets_it_up_again(self):
        self.update_params("crazyflie1", {PARAM.replace(".", "/"): 1})
        self.assertTrue(wait_until(lambda: self.firmware("crazyflie1")["params_changed"].get(PARAM) == 1, 5.0))
        self.assertTrue(wait_until(lambda: self.battery.count() > 5, 10.0), "no battery topic before the reboot")
        before = self.firmware("crazyflie1")
        rospy.ServiceProxy("/crazyflie1/reboot", Empty)()
        after = self.firmware("crazyflie1")
        self.assertEqual(after["reboots"], before["reboots"] + 1)
        self.assertLess(after["uptime_ms"], before["uptime_ms"])             # its onboard clock restarted
        rebooted_at = time.monotonic()

        def set_up_again():
            fw = self.firmware("crazyflie1")
            blocks = fw["log_blocks"].values()
            return (fw["params_changed"].get(PARAM) == 1 and blocks and all(b["running"] for b in blocks)
                    and fw["reboots"] == after["reboots"])
        self.assertTrue(wait_until(set_up_again, 15.0), self.firmware("crazyflie1"))
        self.assertTrue(wait_until(lambda: len(self.battery.since(rebooted_at)) > 5, 10.0),
                        "the battery topic did not flow again after the reboot")

    def test_c_config_block_read_and_written(self):
        read = rospy.ServiceProxy("/crazyflie2/read_config", ReadConfig)
        write = rospy.ServiceProxy("/crazyflie2/write_config", WriteConfig)
        got = read()
        self.assertEqual((got.channel, got.datarate, got.address), (80, "2M", "E7E7E7E702"))
        answer = write(channel=80, datarate="2M", address="E7E7E7E702", pitch_trim=-0.5, roll_trim=1.5)
        self.assertEqual(answer.uri_after_reboot, URIS["crazyflie2"])
        block = self.firmware("crazyflie2")["config_block"]
        self.assertEqual((block["channel"], block["datarate"], block["address"], block["pitch_trim"],
                          block["roll_trim"]), (80, 2, 0xE7E7E7E702, -0.5, 1.5))
        with self.assertRaisesRegex(rospy.ServiceException, "channel 126 is out of range"):
            write(channel=126, datarate="2M", address="E7E7E7E702", pitch_trim=0.0, roll_trim=0.0)
        self.assertEqual(self.firmware("crazyflie2")["config_block"]["channel"], 80)
        self.assertEqual(read().roll_trim, 1.5)

    def motors(self, name):
        return self.truth(name)["motors"]

    def test_b_brushless_flies_only_armed(self):
        self.update_params("crazyflie2", {"stabilizer/estimator": 2})
        start = self.truth("crazyflie2")["position"]
        takeoff = rospy.ServiceProxy("/crazyflie2/takeoff", Takeoff)
        takeoff(groupMask=0, height=0.5, duration=rospy.Duration(1.5))
        t0 = self.clock.now()
        highest, loudest = 0.0, 0.0
        while self.clock.now() < t0 + 2.5:                     # longer than the takeoff would take
            state = self.truth("crazyflie2")
            highest, loudest = max(highest, state["position"][2]), max(loudest, max(state["motors"]))
            time.sleep(0.02)
        self.assertEqual(loudest, 0.0, "a Brushless Crazyflie ran its motors before it was armed")
        self.assertLess(highest, 0.02)
        rospy.ServiceProxy("/crazyflie2/stop", Stop)(groupMask=0)   # drop the plan it could not fly
        rospy.ServiceProxy("/crazyflie2/arm", Arm)(arm=True)
        self.assertTrue(wait_until(lambda: min(self.motors("crazyflie2")) > 0.0, 5.0), "armed: no idling motors")
        self.assertLess(self.truth("crazyflie2")["position"][2], 0.02)           # idling lifts nothing
        takeoff(groupMask=0, height=0.5, duration=rospy.Duration(1.5))
        goal = (start[0], start[1], 0.5)
        self.assertTrue(wait_until(lambda: math.dist(self.truth("crazyflie2")["position"], goal) < 0.05, 10.0),
                        self.truth("crazyflie2")["position"])
        rospy.ServiceProxy("/crazyflie2/land", Land)(groupMask=0, height=0.0, duration=rospy.Duration(2.0))
        self.assertTrue(wait_until(lambda: self.truth("crazyflie2")["position"][2] < 0.03, 10.0))
        rospy.ServiceProxy("/crazyflie2/arm", Arm)(arm=False)
        self.assertTrue(wait_until(lambda: max(self.motors("crazyflie2")) == 0.0, 5.0), self.motors("crazyflie2"))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "power_services", PowerServices)
