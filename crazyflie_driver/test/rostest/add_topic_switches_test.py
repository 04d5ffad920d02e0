#!/usr/bin/env python3
"""crazyflie_add's enable_logging_imu:=false: no imu topic, no imu log block on the firmware, fewer log
packets on the radio than the same Crazyflie with imu on (both judged on the world's truth: the blocks
the firmware runs, and the log packets it sent to the host, counted as they left in the acks); beside
them HEAD's raw pass-through and its console on rosout as 'CF Console:' lines."""
from __future__ import annotations

import unittest

import rospy
import rostest
from sensor_msgs.msg import Imu
from std_msgs.msg import Float32
from std_srvs.srv import Empty

from crazyflie_driver.msg import crtpPacket
from crazyflie_driver.srv import sendPacket
from support.rostest_support import (
    RosoutRecorder,
    TopicRecorder,
    rates_per_world_second,
    start_test_node,
    wait_until,
    world_window,
)

ON, OFF = "radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702"
IMU_VARIABLES = {"acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z"}
LOG_PORT = "5"                  # the log port: block data (and, at connect only, TOC and block control)
IMU_PERIOD_MS = 10              # the imu topic's block period (server.log_plan.FIXED_LOG_TOPICS)


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
        cls.rosout = RosoutRecorder()
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

    def test_console_lines_on_rosout_after_a_reboot(self):
        """A reboot makes the firmware print its boot text again: it reaches rosout line by line as
        HEAD's 'CF Console:' lines, with the Crazyflie's namespace (world truth: it did reboot)."""
        reboots = self.world.crazyflie_state(OFF)["reboots"]
        rospy.ServiceProxy("/crazyflie2/reboot", Empty)()
        self.assertTrue(wait_until(lambda: self.rosout.find("CF Console: [crazyflie2] SYS: Self test passed!"), 20.0),
                        self.rosout.find("CF Console"))
        self.assertGreater(self.world.crazyflie_state(OFF)["reboots"], reboots)
        lines = self.rosout.find("CF Console: [crazyflie2] SYS: ")
        self.assertTrue(any(line.endswith("is up and running!") for line in lines), lines)
        # served again before the other tests use it (its topics and send_packet wait for the link)
        self.assertTrue(wait_until(lambda: self.rosout.find("%s: back after the reboot" % OFF), 20.0))

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

    def test_the_radio_carries_the_difference_on_the_wire(self):
        """Log packets the two Crazyflies sent to the host over a window of simulated time: crazyflie2
        sends the imu block's 100 per second fewer, and each sends what its running blocks produce
        (nothing piles up or is dropped on the way)."""
        def sent():
            states = {uri: self.world.crazyflie_state(uri) for uri in (ON, OFF)}
            return {uri: (s["sent_by_port"].get(LOG_PORT, 0), s["tx_dropped"]) for uri, s in states.items()}
        before = sent()
        window = world_window(self.world, 3.0)
        after = sent()
        rate = {uri: (after[uri][0] - before[uri][0]) / window.world_s for uri in (ON, OFF)}
        self.assertAlmostEqual(rate[ON] - rate[OFF], 1000.0 / IMU_PERIOD_MS, delta=10.0, msg=rate)
        for uri in (ON, OFF):
            self.assertEqual(after[uri][1], before[uri][1], "%s dropped log packets" % uri)
            produced = firmware_packet_rate(self.world.crazyflie_state(uri))
            self.assertAlmostEqual(rate[uri], produced, delta=0.1 * produced, msg=(uri, rate, produced))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "add_topic_switches_test", AddTopicSwitches)
