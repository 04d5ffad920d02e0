#!/usr/bin/env python3
"""Lost pose during hover (hover_vicon.launch sim:=true): the motion-capture system stops
reporting the vehicle (``/crazyflie_sim/crazyflie/set_mocap false``); the position controller must
take its safe action, visible on its state topic, and the vehicle must come down near where it
was, not fly away, and end with its motors stopped. Judged by the world's true state."""
from __future__ import annotations

import math
import sys
import threading
import time
import unittest

import rospy
import rostest
import rostopic
from std_srvs.srv import SetBool

from support.flight_support import Track, WorldProbe, wait_until

NAME = "crazyflie"
HOVER = (0.0, 0.0, 0.5)


class LostPose(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("lost_pose_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.probe.wait_ready([NAME])
        cls.state_topic = rospy.get_param("~state_topic")
        cls.lock = threading.Lock()
        cls.states = []          # (monotonic time, text of the state message)
        msg_class, real_topic, _ = rostopic.get_topic_class(cls.state_topic, blocking=False)
        deadline = time.monotonic() + 30.0
        while msg_class is None and time.monotonic() < deadline:
            time.sleep(0.2)
            msg_class, real_topic, _ = rostopic.get_topic_class(cls.state_topic, blocking=False)
        if msg_class is None:
            raise AssertionError("nobody publishes the controller state on %s" % cls.state_topic)
        rospy.Subscriber(real_topic, msg_class, cls._on_state, queue_size=100)

    @classmethod
    def _on_state(cls, msg):
        with cls.lock:
            cls.states.append((time.monotonic(), str(msg)))

    def states_since(self, t0):
        with self.lock:
            return [s for t, s in self.states if t >= t0]

    def test_lost_pose_leads_to_a_landing_in_place(self):
        self.assertTrue(self.probe.wait_near(NAME, HOVER, 0.05, 40.0),
                        "never hovered: %s" % (self.probe.position(NAME),))
        self.probe.sleep(1.0)
        track = Track(self.probe, [NAME], period=0.02)
        rospy.wait_for_service("/crazyflie_sim/%s/set_mocap" % NAME, 5.0)
        t0 = time.monotonic()
        self.assertTrue(rospy.ServiceProxy("/crazyflie_sim/%s/set_mocap" % NAME, SetBool)(False).success)
        down = wait_until(lambda: self.probe.state(NAME)["on_ground"], 20.0, 0.05)
        down_s = time.monotonic() - t0
        self.assertTrue(down, "still in the air 20 s after the pose was lost: %s" % (self.probe.position(NAME),))
        stopped = wait_until(lambda: max(self.probe.state(NAME)["motors"]) == 0, 10.0, 0.05)
        track.stop()
        self.assertTrue(stopped, "motors still running after the blind landing: %s" % self.probe.state(NAME)["motors"])
        flight = track.between(NAME, t0, time.monotonic())
        top = max(s["position"][2] for s in flight)
        drift = max(math.hypot(s["position"][0] - HOVER[0], s["position"][1] - HOVER[1]) for s in flight)
        fastest = min(s["velocity"][2] for s in flight)
        print("LOST_POSE on the floor after %.1f s, highest z %.3f m, drift %.3f m, fastest descent %.2f m/s"
              % (down_s, top, drift, fastest))
        self.assertLess(top, HOVER[2] + 0.15, "climbed without a pose")
        self.assertLess(drift, 0.3, "drifted away without a pose")
        self.assertGreater(fastest, -2.5, "fell instead of descending")
        texts = self.states_since(t0)
        self.assertTrue(any("pose" in s.lower() for s in texts),
                        "the controller's state topic never reported the lost pose: %s" % texts[-3:])


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "lost_pose", LostPose, sys.argv)
