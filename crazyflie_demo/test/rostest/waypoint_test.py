#!/usr/bin/env python3
"""multi_waypoint_vicon.launch sim:=true: both Crazyflies fly every waypoint in order, then land.

Watches ``/<name>/demo/waypoint`` (index of the waypoint being flown to), ``/<name>/demo/reached``
(the position that decided each hand-over, stamped with its pose's time) and ``/<name>/demo/finished``,
and checks each hand-over against the world's true position: the position that decided that
waypoint k was reached is within the demo's 0.3 m of it on each axis, and it is where the vehicle
truly was at that pose's time. (Judged at the message's arrival instead, a hand-over on the way
through a waypoint has only millimetres of margin: the vehicle enters the 0.3 m box, and the
arrival comes a mocap latency and a demo loop later.) Private params: ``sim_address``, ``vehicles``
(names), ``timeout`` (s for the whole mission).
"""
from __future__ import annotations

import sys
import threading
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import PointStamped
from std_msgs.msg import Bool, Int32

from support.flight_support import Track, WorldProbe, distance, wait_until

#: The demo's tolerance per axis [m].
TOLERANCE = 0.3
#: How far the position that decided a hand-over may be from the world's truth at its stamp [m]: the
#: motion capture's noise (0.5 mm) and the test's own sampling times, good to a state query's round
#: trip (20 ms is 1 cm at 0.5 m/s). Measured: at most 0.7 mm, also with three busy loops.
MOCAP_MATCH = 0.01


class MultiWaypoint(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("waypoint_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.names = list(rospy.get_param("~vehicles"))
        cls.probe.wait_ready(cls.names)
        cls.timeout = float(rospy.get_param("~timeout", 90.0))
        cls.lock = threading.Lock()
        cls.indices = {n: [] for n in cls.names}      # (monotonic time, index) as published
        cls.finished = {n: None for n in cls.names}
        cls.finished_ros = {n: None for n in cls.names}     # ROS time of `finished` (world time in simulation)
        cls.reached = {n: [] for n in cls.names}      # PointStamped, as published
        cls.track = Track(cls.probe, cls.names, period=0.05)
        for n in cls.names:
            rospy.Subscriber("/%s/demo/waypoint" % n, Int32, cls._on_index(n), queue_size=20)
            rospy.Subscriber("/%s/demo/finished" % n, Bool, cls._on_finished(n), queue_size=5)
            rospy.Subscriber("/%s/demo/reached" % n, PointStamped, cls.reached[n].append, queue_size=20)

    @classmethod
    def _on_index(cls, name):
        def cb(msg):
            with cls.lock:
                cls.indices[name].append((time.monotonic(), msg.data))
        return cb

    @classmethod
    def _on_finished(cls, name):
        def cb(msg):
            with cls.lock:
                if msg.data and cls.finished[name] is None:
                    cls.finished[name] = time.monotonic()
                    cls.finished_ros[name] = rospy.get_time()
        return cb

    def test_every_waypoint_in_order_then_land(self):
        t0, t0_ros = time.monotonic(), rospy.get_time()
        done = wait_until(lambda: all(self.finished[n] is not None for n in self.names), self.timeout, 0.2)
        with self.lock:
            indices = {n: list(v) for n, v in self.indices.items()}
        self.assertTrue(done, "not finished after %.0f s; waypoints seen: %s"
                        % (self.timeout, {n: [i for _, i in v] for n, v in indices.items()}))
        for n in self.names:
            waypoints = rospy.get_param("/%s/demo/waypoints" % n)
            seen = [i for _, i in indices[n]]
            self.assertEqual(seen, list(range(len(waypoints))), "%s flew the waypoints out of order" % n)
            # the last one may come after `finished`: another topic, another connection
            wait_until(lambda: len(self.reached[n]) >= len(waypoints), 5.0)
            reached = list(self.reached[n])
            self.assertEqual(len(reached), len(waypoints), "%s: %d reached messages for %d waypoints"
                             % (n, len(reached), len(waypoints)))
            sim_time = rospy.get_param("/use_sim_time", False)         # stamps in world time, else wall time
            wall_minus_monotonic = time.time() - time.monotonic()
            times, worst = [], 0.0
            for k, (w, r) in enumerate(zip(waypoints, reached)):
                seen = (r.point.x, r.point.y, r.point.z)
                for axis in range(3):
                    self.assertLess(abs(seen[axis] - w[axis]), TOLERANCE,
                                    "%s: waypoint %d %s counted as reached at %s" % (n, k + 1, w, seen))
                if sim_time:
                    truth = self.track.position_at_world_time(n, r.header.stamp.to_sec())
                    t = r.header.stamp.to_sec() - t0_ros           # world seconds since the test started
                else:
                    truth = self.track.position_at(n, r.header.stamp.to_sec() - wall_minus_monotonic)
                    t = r.header.stamp.to_sec() - wall_minus_monotonic - t0
                worst = max(worst, distance(truth, seen))
                gap = self.track.world_gap(n, r.header.stamp.to_sec()) if sim_time else float("nan")
                self.assertLess(distance(truth, seen), MOCAP_MATCH, "%s: waypoint %d decided at %s, truly at %s "
                                "(truth sampled %.3f world s apart there)" % (n, k + 1, seen, truth, gap))
                times.append(t)
            # and in order: each hand-over after the one before, the last one not after `finished` (in
            # world time both can carry the same tick's stamp)
            self.assertEqual(times, sorted(times), n)
            finished = (self.finished_ros[n] - t0_ros) if sim_time else (self.finished[n] - t0)
            self.assertLessEqual(times[-1], finished, n)
            print("WAYPOINTS %s: the positions that decided the hand-overs at most %.1f mm from the truth"
                  % (n, 1e3 * worst))
            print("WAYPOINTS %s reached at %s s after the test started" % (n, ["%.1f" % x for x in times]))
        for n in self.names:
            landed = wait_until(lambda: self.probe.state(n)["on_ground"], 20.0, 0.1)
            s = self.probe.state(n)
            self.assertTrue(landed, "%s did not land: %s" % (n, s["position"]))
            self.assertLess(s["position"][2], 0.05)
            self.assertTrue(wait_until(lambda: max(self.probe.state(n)["motors"]) == 0, 10.0, 0.1),
                            "%s motors still running after landing: %s" % (n, self.probe.state(n)["motors"]))
        print("MISSION landed %.1f s after the test started" % (time.monotonic() - t0))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "multi_waypoint", MultiWaypoint, sys.argv)
