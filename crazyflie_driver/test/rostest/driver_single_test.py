#!/usr/bin/env python3
"""One simulated Crazyflie behind crazyflie_server: topics, rates, params, cmd_vel, custom logs, emergency."""
from __future__ import annotations

import statistics
import sys
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import Twist
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import Float32
from std_srvs.srv import Empty

from crazyflie_driver.msg import GenericLogData
from crazyflie_driver.srv import UpdateParams
from support.rostest_support import TopicRecorder, rates_per_world_second, start_test_node, wait_until, world_window

NS = "/crazyflie1"


def twist(x=0.0, y=0.0, z=0.0, yaw=0.0) -> Twist:
    t = Twist()
    t.linear.x, t.linear.y, t.linear.z, t.angular.z = x, y, z, yaw
    return t


class DriverSingle(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("driver_single_test", ["crazyflie1"])
        cls.uri = rospy.get_param("~uri")
        cls.imu = TopicRecorder(NS + "/imu", Imu)
        cls.battery = TopicRecorder(NS + "/battery", Float32)
        cls.log1 = TopicRecorder(NS + "/log1", GenericLogData)
        cls.motors = TopicRecorder(NS + "/motors", GenericLogData)
        cls.cmd_vel = rospy.Publisher(NS + "/cmd_vel", Twist, queue_size=1)
        wait_until(lambda: cls.imu.count() > 10 and cls.cmd_vel.get_num_connections() > 0, 10.0)

    def state(self):
        return self.world.crazyflie_state(self.uri)

    def send_for(self, msg: Twist, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.cmd_vel.publish(msg)
            time.sleep(0.02)

    def send_until(self, msg: Twist, cond, timeout: float):
        """Publishes ``msg`` every 20 ms until cond() is true (its value) or ``timeout`` s passed."""
        end = time.monotonic() + timeout
        while True:
            self.cmd_vel.publish(msg)
            v = cond()
            if v or time.monotonic() >= end:
                return v
            time.sleep(0.02)

    def test_a_topics_have_the_right_types(self):
        expected = {NS + "/imu": "sensor_msgs/Imu", NS + "/temperature": "sensor_msgs/Temperature",
                    NS + "/magnetic_field": "sensor_msgs/MagneticField", NS + "/pressure": "std_msgs/Float32",
                    NS + "/battery": "std_msgs/Float32", NS + "/rssi": "std_msgs/Float32",
                    NS + "/log1": "crazyflie_driver/GenericLogData",
                    NS + "/motors": "crazyflie_driver/GenericLogData"}
        published = dict(rospy.get_published_topics())
        for topic, type_name in expected.items():
            self.assertEqual(published.get(topic), type_name, topic)
        for topic, msg_type in ((NS + "/temperature", Temperature), (NS + "/magnetic_field", MagneticField),
                                (NS + "/pressure", Float32), (NS + "/rssi", Float32)):
            rospy.wait_for_message(topic, msg_type, timeout=3.0)

    def test_b_sensor_rates_and_units(self):
        # per second of world time: the firmware's log timers set these rates, not the wall clock
        rates = rates_per_world_second({"imu": self.imu, "battery": self.battery}, self.world, 3.0)
        imu_rate, battery = rates["imu"], rates["battery"]
        self.assertGreater(imu_rate, 85.0)
        self.assertLess(imu_rate, 115.0)
        self.assertGreater(battery, 8.0)
        self.assertLess(battery, 12.0)
        msg = self.imu.latest()
        self.assertEqual(msg.header.frame_id, "crazyflie1/base_link")
        self.assertEqual(msg.orientation_covariance[0], -1.0)
        self.assertAlmostEqual(msg.linear_acceleration.z, 9.81, delta=0.5)   # resting on the ground: 1 g
        self.assertLess(abs(msg.angular_velocity.z), 0.1)
        vbat = self.battery.latest().data
        self.assertTrue(3.0 < vbat < 4.3, vbat)

    def test_c_parameters_mirrored(self):
        self.assertIn(rospy.get_param(NS + "/ring/headlightEnable"), (0, 1))
        self.assertAlmostEqual(float(rospy.get_param(NS + "/pid_rate/roll_kp")),
                               float(self.state()["params"]["pid_rate.roll_kp"]), places=3)
        # the whole real-size table (ids past 255), e.g. the position controller's gains at id 262
        held = self.state()["params"]
        self.assertGreater(len(held), 380)
        mirrored = rospy.get_param(NS)
        missing = [n for n in held if n.partition(".")[2] not in mirrored.get(n.partition(".")[0], {})]
        self.assertEqual(missing, [])
        self.assertAlmostEqual(float(rospy.get_param(NS + "/posCtlPid/zKp")), float(held["posCtlPid.zKp"]), places=3)

    def test_d_update_params_reaches_the_crazyflie(self):
        update = rospy.ServiceProxy(NS + "/update_params", UpdateParams)
        rospy.set_param(NS + "/ring/headlightEnable", 1)
        update(["ring/headlightEnable"])
        self.assertEqual(self.state()["params"]["ring.headlightEnable"], 1)
        rospy.set_param(NS + "/ring/headlightEnable", 0)
        with self.assertRaises(rospy.ServiceException) as ctx:
            update(["ring/headlightEnable", "nosuch/param"])
        self.assertIn("nosuch", str(ctx.exception))
        self.assertEqual(self.state()["params"]["ring.headlightEnable"], 0)   # the known one went through
        rospy.set_param(NS + "/sound/freq", 4321)                              # id past 255 (16-bit on the wire)
        update(["sound/freq"])
        self.assertEqual(self.state()["params"]["sound.freq"], 4321)

    def test_e_cmd_vel_reaches_the_crazyflie_with_trims_and_pitch_sign(self):
        self.send_for(twist(x=2.0, y=3.0, z=12000.0, yaw=10.0), 0.3)
        sp = wait_until(lambda: (lambda s: s if s and s[3] == 12000 else None)(self.state()["last_setpoint"]), 2.0)
        self.assertIsNotNone(sp)
        roll, pitch, yaw, thrust = sp
        self.assertAlmostEqual(roll, 3.0 + 1.5, places=4)        # linear.y + roll_trim
        self.assertAlmostEqual(pitch, -(2.0 - 0.5), places=4)    # -(linear.x + pitch_trim)
        self.assertAlmostEqual(yaw, 10.0, places=4)
        self.send_for(twist(z=70000.0), 0.2)
        self.assertEqual(wait_until(lambda: self.state()["last_setpoint"][3] == 60000, 2.0), True)
        self.send_for(twist(), 0.2)

    def test_f_custom_log_blocks_at_their_period(self):
        window = world_window(self.world, 2.0)                     # 2 s of the firmware's (world) time
        log1 = self.log1.between(window.t0, window.t1)
        motors = self.motors.between(window.t0, window.t1)
        per_2s = 2.0 / window.world_s
        self.assertTrue(15 <= len(log1) * per_2s <= 25, (len(log1), window.world_s))          # 100 ms
        self.assertTrue(80 <= len(motors) * per_2s <= 120, (len(motors), window.world_s))     # 20 ms
        periods = [b.onboard_timestamp - a.onboard_timestamp for a, b in zip(log1, log1[1:])]
        self.assertEqual(statistics.median(periods), 100)
        periods = [b.onboard_timestamp - a.onboard_timestamp for a, b in zip(motors, motors[1:])]
        self.assertEqual(statistics.median(periods), 20)
        self.assertEqual(len(log1[-1].values), 2)
        self.assertTrue(3.0 < log1[-1].values[0] < 4.3)
        self.assertAlmostEqual(log1[-1].values[1], 1.0, delta=0.01)   # stateEstimate.qw, id past 255: live, level
        self.assertEqual(len(motors[-1].values), 4)
        stamp_age = rospy.Time.now() - log1[-1].header.stamp
        self.assertLess(abs(stamp_age.to_sec()), 1.0)

    def test_g_emergency_stops_the_motors_for_good(self):
        # precondition: the motors spin, as reported by the motors log block (wait for it, the
        # setpoint and the next 20 ms log packet take a moment on a busy machine)
        spinning = self.send_until(twist(z=30000.0), lambda: self.motors.latest() is not None
                                   and all(v > 0 for v in self.motors.latest().values), 5.0)
        self.assertTrue(spinning, self.motors.latest().values)
        rospy.ServiceProxy(NS + "/emergency", Empty)()
        self.assertTrue(self.state()["emergency"])
        rospy.ServiceProxy(NS + "/emergency", Empty)()            # idempotent
        self.send_for(twist(z=45000.0), 0.5)                        # ignored from now on
        # samples the Crazyflie took from here on (by their stamps, the sampling time: on a busy
        # radio a sample from before the emergency may still arrive now)
        after = rospy.Time.now()
        self.send_for(twist(z=45000.0), 0.5)
        sampled_after = lambda: [m.values for _, m in self.motors.since(0.0) if m.header.stamp >= after]
        self.assertTrue(wait_until(sampled_after, 3.0), "no motors sample taken after the emergency")
        late = sampled_after()
        self.assertTrue(all(v == 0 for vals in late for v in vals), late[-1])
        self.assertEqual(self.state()["last_setpoint"][3], 0)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "driver_single", DriverSingle, sys.argv)
