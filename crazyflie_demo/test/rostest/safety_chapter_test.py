#!/usr/bin/env python3
"""Safety reactions of crazyflie_server on the chapter's path (RPYT setpoints from the position
controller, multi_hover_vicon.launch sim:=true), judged on the world's truth:

* the controller of crazyflie1 is killed (SIGKILL) while it hovers: the server's setpoint-silence
  reaction levels it and brings it down at a bounded speed, with its motors off on the floor (before,
  the firmware's watchdog cut the motors after 2 s at 0.5 m: a fall); crazyflie2 hovers on;
* crazyflie1 flies again under a new controller; the server gets Ctrl-C while both hover: both come
  down and stop their motors before the server exits.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import unittest
from xmlrpc.client import ServerProxy

import rosgraph
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from rosgraph_msgs.msg import Log
from std_msgs.msg import String
from std_srvs.srv import Empty

from support.flight_support import Track, WorldProbe, distance, wait_until

#: Fastest descent the reaction may reach (m/s): twice its 0.3 m/s rate plus the hover-thrust
#: estimate's error; the firmware's 2 s cut at 0.5 m hits the floor at about 3 m/s.
MAX_DESCENT_SPEED = 0.8
#: The open-loop descent's whole plan (hold 0.3 s, accelerate 0.3 s, 2.0 m at 0.3 m/s) in world seconds.
PLAN_S = 0.3 + 0.3 + 2.0 / 0.3


def node_pid(name: str) -> int:
    code, _, pid = ServerProxy(rosgraph.Master("/safety_chapter_test").lookupNode(name)).getPid("/safety_chapter_test")
    assert code == 1, "no pid for %s" % name
    return int(pid)


class SafetyChapter(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("safety_chapter_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.vehicles = {v["name"]: tuple(v["target"]) for v in rospy.get_param("~vehicles")}
        cls.probe.wait_ready(list(cls.vehicles))
        cls.rosout = []
        rospy.Subscriber("/rosout", Log, lambda m: cls.rosout.append(m) if m.name == "/crazyflie_server"
                         else None, queue_size=1000)
        cls.status = {n: [] for n in cls.vehicles}
        for n in cls.vehicles:
            rospy.Subscriber("/%s/status" % n, DiagnosticStatus, cls.status[n].append, queue_size=100)
        cls.controller = None

    @classmethod
    def tearDownClass(cls):
        if cls.controller is not None and cls.controller.poll() is None:
            cls.controller.kill()
            cls.controller.wait(5.0)

    def hovering(self, name, timeout=40.0):
        return self.probe.wait_near(name, self.vehicles[name], 0.05, timeout)

    def motors_off(self, name):
        return max(self.probe.state(name)["motors"]) == 0

    def stop_track(self, track, names, t0):
        """Stop ``track`` once it holds a sample of each vehicle with its motors off."""
        wait_until(lambda: all(any(max(s["motors"]) == 0 for s in track.between(n, t0, time.monotonic()))
                               for n in names), 5.0)
        track.stop()

    def descent(self, track, name, t0, t1):
        """(fastest descent m/s, highest z, z when the motors stopped, world s from t0 to motors off)."""
        flight = track.between(name, t0, t1)
        fastest = -min(s["velocity"][2] for s in flight)
        top = max(s["position"][2] for s in flight)
        stopped = [s for s in flight if max(s["motors"]) == 0]
        self.assertTrue(stopped, "%s: motors never stopped" % name)
        return fastest, top, stopped[0]["position"][2], stopped[0]["time"] - flight[0]["time"]

    def test_a_killed_controller_is_a_controlled_descent(self):
        for name in self.vehicles:
            self.assertTrue(self.hovering(name), "%s never hovered: %s" % (name, self.probe.position(name)))
        self.probe.sleep(1.0)
        track = Track(self.probe, list(self.vehicles), period=0.02)
        t0 = time.monotonic()
        os.kill(node_pid("/crazyflie1/controller"), signal.SIGKILL)
        ok, _ = self.probe.clock.wait_until(lambda: self.motors_off("crazyflie1"), PLAN_S + 3.0)
        self.stop_track(track, ["crazyflie1"], t0)
        self.assertTrue(ok, "crazyflie1 motors still on %.1f s of world time after its controller died: %s"
                        % (PLAN_S + 3.0, self.probe.state("crazyflie1")))
        fastest, top, z_off, off_s = self.descent(track, "crazyflie1", t0, time.monotonic())
        print("SAFETY_SILENCE fastest descent %.2f m/s, highest %.3f m, motors off at z %.3f m after %.1f s"
              % (fastest, top, z_off, off_s))
        self.assertLess(fastest, MAX_DESCENT_SPEED, "fell instead of descending")
        self.assertLess(top, self.vehicles["crazyflie1"][2] + 0.1, "climbed after its controller died")
        self.assertLess(z_off, 0.02, "motors stopped above the floor")
        self.assertGreater(off_s, 2.5, "motors stopped at the firmware's watchdog time, not by the descent")
        # the other Crazyflie on the same radio kept its point all along
        other = track.between("crazyflie2", t0, time.monotonic())
        worst = max(other, key=lambda s: distance(s["position"], self.vehicles["crazyflie2"]))
        print("SAFETY_SILENCE crazyflie2 farthest from its point: %.3f m at %s, %.1f world s after the kill"
              % (distance(worst["position"], self.vehicles["crazyflie2"]), worst["position"],
                 worst["time"] - other[0]["time"]))
        for s in other:
            self.assertLess(distance(s["position"], self.vehicles["crazyflie2"]), 0.05, s["position"])
        # said once with the reason, and on the status topic
        said = [m.msg for m in self.rosout if "no setpoint for" in m.msg and "holding level" in m.msg]
        self.assertEqual(len(said), 1, said)
        self.assertTrue(wait_until(lambda: any("safety" in m.message and m.level >= DiagnosticStatus.WARN
                                               for m in self.status["crazyflie1"]), 5.0))

    def test_b_ctrl_c_on_the_server_brings_both_down(self):
        # crazyflie1 flies again under a new controller (its parameters are still on the server)
        type(self).controller = subprocess.Popen(["rosrun", "crazyflie_controller", "controller",
                                                  "__ns:=/crazyflie1", "__name:=controller"])
        state = {"text": ""}
        rospy.Subscriber("/crazyflie1/controller/state", String, lambda m: state.update(text=m.data))
        rospy.wait_for_service("/crazyflie1/takeoff", 30.0)
        takeoff = rospy.ServiceProxy("/crazyflie1/takeoff", Empty)

        def took_off():
            if state["text"].startswith("Idle: ok"):
                takeoff()
            return state["text"] and not state["text"].startswith("Idle")
        self.assertTrue(wait_until(took_off, 30.0, 0.3), state)
        for name in self.vehicles:
            self.assertTrue(self.hovering(name), "%s not hovering: %s" % (name, self.probe.position(name)))
        self.probe.sleep(1.0)
        track = Track(self.probe, list(self.vehicles), period=0.02)
        t0 = time.monotonic()
        server = node_pid("/crazyflie_server")
        os.kill(server, signal.SIGINT)
        ok, _ = self.probe.clock.wait_until(lambda: all(self.motors_off(n) for n in self.vehicles), PLAN_S + 3.0)
        self.assertTrue(ok, "motors still on after the server's Ctrl-C: %s"
                        % {n: self.probe.state(n)["motors"] for n in self.vehicles})
        # the controllers keep streaming (wound up by the descent): nothing may send them up again
        self.probe.sleep(3.0)
        track.stop()
        t1 = time.monotonic()
        for name in self.vehicles:
            flight = track.between(name, t0, t1)
            print("SAFETY_SHUTDOWN_TRUTH %s (world s, z m, motors on): %s" % (name, " ".join(
                "%.2f/%.3f/%d" % (s["time"], s["position"][2], max(s["motors"]) > 0) for s in flight[::5])))
            fastest, top, z_off, off_s = self.descent(track, name, t0, t1)
            print("SAFETY_SHUTDOWN %s fastest descent %.2f m/s, highest %.3f m, motors off at z %.3f m after %.1f s"
                  % (name, fastest, top, z_off, off_s))
            self.assertLess(fastest, MAX_DESCENT_SPEED, "%s fell" % name)
            self.assertLess(top, self.vehicles[name][2] + 0.1, "%s climbed after the server's Ctrl-C" % name)
            self.assertLess(z_off, 0.02, "%s: motors stopped above the floor" % name)
            first_off = next(i for i, s in enumerate(flight) if max(s["motors"]) == 0)
            again = [s for s in flight[first_off:] if max(s["motors"]) > 0]
            self.assertFalse(again, "%s: motors on again after they stopped: %s" % (name, again[:1]))
        self.assertTrue(wait_until(lambda: not _alive(server), 15.0), "the server did not exit")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        return True
    except OSError:
        return False


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "safety_chapter", SafetyChapter, sys.argv)
