#!/usr/bin/env python3
"""crazyflie_add's enable_logging_imu:=false: no imu topic, no imu log block on the firmware, fewer log
packets on the radio than the same Crazyflie with imu on (both judged on the world's truth)."""
from __future__ import annotations

import unittest

import rospy
import rostest
from sensor_msgs.msg import Imu
from std_msgs.msg import Float32

from crazyflie_driver.msg import crtpPacket
from crazyflie_driver.srv import sendPacket
from support.rostest_support import TopicRecorder, rates_per_world_second, start_test_node, wait_until

ON, OFF = "radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702"
IMU_VARIABLES = {"acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z"}


def running_blocks(state) -> list:
    return [b for b in state["log_blocks"].values() if b["running"]]


def firmware_packet_rate(state) -> float:
    """Log packets per simulated second the firmware's running blocks send (one per block per period)."""
    return sum(1000.0 / b["period_ms"] for b in running_blocks(state))


class AddTopicSwitches(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("add_topic_switches_test", ["crazyflie1", "crazyflie2"])
        cls.packets = TopicRecorder("/crazyflie1/packets", crtpPacket)
        cls.recorders = {"imu1": TopicRecorder("/crazyflie1/imu", Imu),
                         "imu2": TopicRecorder("/crazyflie2/imu", Imu),
                         "battery1": TopicRecorder("/crazyflie1/battery", Float32),
                         "battery2": TopicRecorder("/crazyflie2/battery", Float32)}
        wait_until(lambda: cls.recorders["battery2"].latest() is not None
                   and cls.recorders["imu1"].latest() is not None, 20.0)

    def test_send_packet_and_the_packets_topic(self):
        """A raw link echo (port 15, channel 0) through send_packet comes back on packets (nothing in the
        server reads it); a raw setpoint is refused with nothing sent; crazyflie2 has no packets topic."""
        send = rospy.ServiceProxy("/crazyflie1/send_packet", sendPacket)
        text = b"raw echo"
        data = list(text) + [0] * (30 - len(text))
        send(crtpPacket(size=len(text), header=0xFC, data=data))
        echoed = lambda: [m for _, m in self.packets.since(0.0)
                          if m.header >> 4 == 15 and bytes(m.data[:m.size]) == text]
        self.assertTrue(wait_until(echoed, 5.0), [m for _, m in self.packets.since(0.0)][:5])
        with self.assertRaises(rospy.ServiceException) as refused:
            send(crtpPacket(size=14, header=0x3C, data=[0] * 30))       # an RPYT setpoint (port 3)
        self.assertIn("steers the motors", str(refused.exception))
        topics = {t for t, _ in rospy.get_published_topics()}
        self.assertIn("/crazyflie1/packets", topics)
        self.assertNotIn("/crazyflie2/packets", topics)

    def test_no_imu_topic_but_the_others(self):
        rates = rates_per_world_second(self.recorders, self.world, 2.0)
        self.assertGreater(rates["imu1"], 50.0, rates)
        self.assertEqual(rates["imu2"], 0.0, rates)
        self.assertGreater(rates["battery2"], 5.0, rates)
        published = {name for name, _ in rospy.get_published_topics()}
        self.assertNotIn("/crazyflie2/imu", published)
        self.assertIn("/crazyflie1/imu", published)

    def test_firmware_has_no_imu_block_and_the_radio_carries_less(self):
        on, off = self.world.crazyflie_state(ON), self.world.crazyflie_state(OFF)
        on_vars = {v for b in running_blocks(on) for v in b["variables"]}
        off_vars = {v for b in running_blocks(off) for v in b["variables"]}
        self.assertTrue(IMU_VARIABLES <= on_vars, on["log_blocks"])
        self.assertFalse(IMU_VARIABLES & off_vars, off["log_blocks"])
        self.assertIn("pm.vbat", off_vars)
        # the 10 ms block goes: 100 log packets per simulated second fewer
        self.assertAlmostEqual(firmware_packet_rate(on) - firmware_packet_rate(off), 100.0, delta=1.0)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "add_topic_switches_test", AddTopicSwitches)
