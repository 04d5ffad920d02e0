#!/usr/bin/env python3
"""HEAD's execute_trajectory.py in the simulator, on external_position_vicon.launch's Crazyflie: the
script streams ``up_move_down.csv`` (up to 0.5 m, 1 s hold, 0.3 m along x, 1 s hold, down to the
ground, 8 s) to /crazyflie/cmd_full_state, and the world's truth must pass through the file's
points and end on the ground at its last one with the motors stopped by the script's cmd_stop
(unlocked: not the firmware's setpoint watchdog).

Private params: ``sim_address``; ``name`` (the world's vehicle); ``trajectory`` (the CSV's path).
"""
from __future__ import annotations

import subprocess
import sys
import unittest

import rospy
import rostest
from geometry_msgs.msg import PointStamped

from crazyflie_driver.msg import GenericLogData
from support.flight_support import Track, WorldProbe, distance, wait_until

VIA = [(0.0, 0.0, 0.5), (0.3, 0.0, 0.5)]   # the file's holds
END = (0.3, 0.0)
VIA_BOUND_M = 0.05
END_BOUND_M = 0.05
SCRIPT_TIMEOUT_S = 120.0                   # wall s for the 8 s trajectory on a loaded machine


class ExecuteTrajectory(unittest.TestCase):
    def test_the_file_is_flown(self):
        rospy.init_node("execute_trajectory_test")
        probe = WorldProbe(rospy.get_param("~sim_address"))
        name = rospy.get_param("~name")
        probe.wait_ready([name])
        estimate = {}
        rospy.Subscriber("/crazyflie/log1", GenericLogData, lambda m: estimate.update(v=tuple(m.values)))
        rospy.wait_for_message("/crazyflie/external_position", PointStamped, timeout=30.0)
        start = probe.position(name)
        self.assertTrue(wait_until(lambda: "v" in estimate and distance(estimate["v"], start) < 0.01, 20.0),
                        "the onboard estimate %s never reached the truth %s" % (estimate.get("v"), start))
        track = Track(probe, [name], period=0.05)
        try:
            run = subprocess.run(["rosrun", "crazyflie_demo", "execute_trajectory.py", rospy.get_param("~trajectory")],
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                 timeout=SCRIPT_TIMEOUT_S)
            self.assertEqual(run.returncode, 0, run.stdout[-2000:])
            landed = wait_until(lambda: (lambda s: s["on_ground"] and max(s["motors"]) == 0)(probe.state(name)), 10.0)
            self.assertTrue(landed, "not on the ground with its motors stopped: %s" % (probe.state(name),))
        finally:
            track.stop()
        rows = track.between(name, float("-inf"), float("inf"))
        for via in VIA:
            closest = min(distance(s["position"], via) for s in rows)
            print("VIA %s closest %.4f m" % (via, closest))
            self.assertLess(closest, VIA_BOUND_M, "the Crazyflie never came within %.2f m of %s" % (VIA_BOUND_M, via))
        end = rows[-1]["position"]
        print("END %s" % (end,))
        self.assertLess(distance(end[:2], END), END_BOUND_M, "landed at %s, not at %s" % (end, END))
        airborne = next(i for i, s in enumerate(rows) if s["position"][2] > 0.1)
        stopped = next(s for s in rows[airborne:] if max(s["motors"]) == 0)
        self.assertIsNone(stopped["locked_at"], "locked when its motors stopped: the watchdog, not cmd_stop")


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "execute_trajectory", ExecuteTrajectory, sys.argv)
