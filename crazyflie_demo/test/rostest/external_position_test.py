#!/usr/bin/env python3
"""HEAD's external-position launch files in the simulator: motion capture reaches the onboard
estimator, and the Crazyflies then fly on it.

Private params: ``sim_address``; ``vehicles`` ([{name: world vehicle, ns: Crazyflie namespace}],
started away from the origin); ``forwarded`` (the forwarder's topic in each namespace,
external_position or external_pose); ``check_estimate`` (each namespace's ``log1`` streams
stateEstimate.x/y/z first: it must converge on the truth).

The flight goes through crazyflie_demo's ``crazyflie.py`` wrapper (HEAD's ``Crazyflie(prefix, tf)``):
take off to 0.5 m above the start, go to an absolute point, hold it, land. The high-level commander
flies on the onboard estimate, so the world's truth only reaches those points if the estimator
takes the motion capture (the complementary estimator, the firmware's automatic choice, keeps x/y
at 0 and would fly to the origin's neighbourhood instead).
"""
from __future__ import annotations

import sys
import unittest

import rospy
import rostest
from geometry_msgs.msg import PointStamped, PoseStamped

from crazyflie_demo.crazyflie_wrapper import Crazyflie
from crazyflie_driver.msg import GenericLogData
from support.flight_support import WorldProbe, distance, hold_errors, wait_until

ESTIMATE_BOUND_M = 0.05   # onboard estimate vs truth, per axis
REACH_BOUND_M = 0.05      # truth vs a commanded point
HOLD_MAX_M = 0.03         # truth vs the goal over the hold, after settling
HOLD_S = 1.0              # world s
SETTLE_S = 1.0            # world s after the goTo's end before the hold is judged
GOTO_S = 2.0              # s, the goTo's duration
HEIGHT = 0.5              # m
OFFSET = (0.3, -0.2)      # m, the goal relative to the start


class ExternalPosition(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("external_position_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.vehicles = rospy.get_param("~vehicles")
        cls.forwarded = rospy.get_param("~forwarded", "external_position")
        cls.check_estimate = bool(rospy.get_param("~check_estimate", True))
        cls.probe.wait_ready([v["name"] for v in cls.vehicles])
        cls.starts = {v["name"]: cls.probe.position(v["name"]) for v in cls.vehicles}
        cls.estimates = {}
        cls.subs = [rospy.Subscriber(v["ns"] + "/log1", GenericLogData, cls._on_log, callback_args=v["name"],
                                     queue_size=10) for v in cls.vehicles]

    @classmethod
    def _on_log(cls, msg, name):
        cls.estimates[name] = tuple(msg.values)

    def test_a_forwarded_poses_are_the_truth(self):
        kind = PoseStamped if self.forwarded == "external_pose" else PointStamped
        for v in self.vehicles:
            msg = rospy.wait_for_message(v["ns"] + "/" + self.forwarded, kind, timeout=30.0)
            p = msg.pose.position if kind is PoseStamped else msg.point
            true = self.probe.position(v["name"])
            self.assertLess(distance((p.x, p.y, p.z), true), ESTIMATE_BOUND_M,
                            "%s/%s %s, truth %s" % (v["ns"], self.forwarded, (p.x, p.y, p.z), true))
            self.assertGreater(distance(true[:2], (0.0, 0.0)), 0.3, "%s must start away from the origin" % v["name"])

    def test_b_the_onboard_estimate_converges_on_the_truth(self):
        if not self.check_estimate:
            self.skipTest("no log1 estimate in this launch file")
        for v in self.vehicles:
            name = v["name"]
            true = self.probe.position(name)

            def close():
                e = self.estimates.get(name)
                return e is not None and len(e) >= 3 and all(abs(a - b) < ESTIMATE_BOUND_M for a, b in zip(e[:3], true))
            self.assertTrue(wait_until(close, 20.0, 0.1), "%s: onboard estimate %s never came within %.2f m of the "
                            "truth %s" % (name, self.estimates.get(name), ESTIMATE_BOUND_M, true))
            print("ESTIMATE %s %s truth %s" % (name, self.estimates[name], true))

    def test_c_they_fly_on_it(self):
        cfs = {v["name"]: Crazyflie(v["ns"], None) for v in self.vehicles}
        for cf in cfs.values():
            cf.takeoff(HEIGHT, 2.5)
        for name in cfs:
            up = (self.starts[name][0], self.starts[name][1], HEIGHT)
            self.assertTrue(self.probe.wait_near(name, up, REACH_BOUND_M, 15.0),
                            "%s never reached %s after takeoff: at %s" % (name, up, self.probe.position(name)))
        goals = {}
        for name, cf in cfs.items():
            goals[name] = (self.starts[name][0] + OFFSET[0], self.starts[name][1] + OFFSET[1], HEIGHT)
            cf.goTo(goals[name], 0.0, GOTO_S)
        for name in cfs:
            self.assertTrue(self.probe.wait_near(name, goals[name], REACH_BOUND_M, 10.0),
                            "%s never reached %s: at %s" % (name, goals[name], self.probe.position(name)))
        self.probe.sleep(GOTO_S + SETTLE_S)
        track = self.probe.sample(list(cfs), HOLD_S)
        for name in cfs:
            rms, worst = hold_errors(track[name], goals[name])
            print("HOLD %s rms %.4f max %.4f m" % (name, rms, worst))
            self.assertLess(worst, HOLD_MAX_M, "%s strayed %.3f m from %s while holding" % (name, worst, goals[name]))
        for cf in cfs.values():
            cf.land(0.0, 2.5)
        for name in cfs:
            landed = wait_until(lambda: self.probe.state(name)["on_ground"], 15.0, 0.1)
            self.assertTrue(landed, "%s did not land: at %s" % (name, self.probe.position(name)))
        for cf in cfs.values():
            cf.stop()


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "external_position", ExternalPosition, sys.argv)
