#!/usr/bin/env python3
"""Safety reactions of crazyflie_server with onboard control, judged on the world's truth.

Each Crazyflie flies by streamed ``cmd_position`` setpoints with the Kalman estimator fed by
``external_position`` (the world's true position, 50 Hz, from this test):

* crazyflie3's battery is drained to the warning level (a warning, once, with the figures; it flies
  on), then to the critical level (the server lands it by the high-level commander although its
  setpoints keep coming; motors off on the floor);
* both Crazyradios are unplugged while crazyflie1 (emergency-stop watchdog keep-alive on) and
  crazyflie2 (off, the default) hover: crazyflie1's motors stop within 1 s of world time (the
  firmware's watchdog), crazyflie2's after the firmware's 2 s setpoint watchdog, as before;
* crazyflie4 is removed by ``/remove_crazyflie`` while it hovers (its setpoints keep coming, and
  another client calls its ``go_to`` every 0.1 s, to where it hovers): the server lands it first, each
  go_to during that landing is refused (one accepted would end the landing in the air), the service
  answers once it rests with its motors off.
"""
from __future__ import annotations

import sys
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped

from crazyflie_driver.msg import Position
from crazyflie_driver.sim.world_clock import WorldClock
from crazyflie_driver.srv import GoTo, RemoveCrazyflie, UpdateParams
from support.rostest_support import RosoutRecorder, TopicRecorder, wait_for_crazyflie, wait_until, world

URIS = {"crazyflie1": "radio://0/80/2M/E7E7E7E701", "crazyflie2": "radio://1/90/2M/E7E7E7E702",
        "crazyflie3": "radio://1/90/2M/E7E7E7E703", "crazyflie4": "radio://0/80/2M/E7E7E7E704"}
HEIGHT = 0.5
PERIOD_S = 0.02
WARNING_V, CRITICAL_V = 3.40, 3.25      # below the server's defaults, 3.45 and 3.30 V
#: The watchdog keep-alive goes out every 0.25 s and the firmware stops 1 s after the last one (at
#: most 1 s after the unplug); a few firmware ticks of margin. Both ends are the world's own stamps
#: (the unplug's and the supervisor lock's world time), so how often the test looks does not count.
WATCHDOG_S = 1.0 + 0.02
SETPOINT_WATCHDOG_S = 2.0
GO_TO_PERIOD_S = 0.1        # another client's go_to during the removal's landing


class Flyer:
    """Streams a position setpoint and the true position of one Crazyflie (until stopped)."""

    def __init__(self, medium, name: str) -> None:
        self.medium, self.name = medium, name
        self.goal = None
        self.setpoints = rospy.Publisher("/%s/cmd_position" % name, Position, queue_size=1)
        self.mocap = rospy.Publisher("/%s/external_position" % name, PointStamped, queue_size=1)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def truth(self):
        return self.medium.control("vehicle_state", uri=self.name)

    def start(self):
        wait_until(lambda: self.setpoints.get_num_connections() and self.mocap.get_num_connections(), 10.0)
        self.thread.start()

    def _run(self):
        while not self._stop.is_set() and not rospy.is_shutdown():
            try:
                p = self.truth()["position"]
            except Exception:       # the world going away at shutdown
                return
            point = PointStamped()
            point.point.x, point.point.y, point.point.z = p
            self.mocap.publish(point)
            if self.goal is not None:
                self.setpoints.publish(Position(x=self.goal[0], y=self.goal[1], z=self.goal[2], yaw=0.0))
            time.sleep(PERIOD_S)

    def stop(self):
        self._stop.set()


class SafetyOnboard(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("safety_onboard_test")
        cls.world = world(rospy.get_param("~sim_address"))
        cls.clock = WorldClock(cls.world.ping)
        cls.rosout = RosoutRecorder("/crazyflie_server")
        cls.status = {n: TopicRecorder("/%s/status" % n, DiagnosticStatus) for n in URIS}
        cls.flyers = {}
        for name in URIS:
            wait_for_crazyflie(name, 60.0)
            rospy.set_param("/%s/stabilizer/estimator" % name, 2)
            rospy.ServiceProxy("/%s/update_params" % name, UpdateParams)(["stabilizer/estimator"])
            cls.flyers[name] = Flyer(cls.world, name)
            cls.flyers[name].start()

    @classmethod
    def tearDownClass(cls):
        for f in cls.flyers.values():
            f.stop()

    def take_off(self, name):
        flyer = self.flyers[name]
        start = flyer.truth()["position"]
        for k in range(1, 26):              # a 1 s ramp up to HEIGHT
            flyer.goal = (start[0], start[1], HEIGHT * k / 25.0)
            self.clock.sleep(0.04)
        ok, _ = self.clock.wait_until(lambda: abs(flyer.truth()["position"][2] - HEIGHT) < 0.05, 10.0)
        self.assertTrue(ok, "%s did not reach %.1f m: %s" % (name, HEIGHT, flyer.truth()["position"]))
        self.clock.sleep(1.0)

    def motors_on(self, name):
        return max(self.flyers[name].truth()["motors"]) > 0

    def track(self, name, until, seconds):
        """The truth of ``name`` until ``until()`` or ``seconds`` of world time: [(world s, z, vz, motors on)]."""
        rows = []

        def sample():
            s = self.flyers[name].truth()
            rows.append((s["time"], s["position"][2], s["velocity"][2], max(s["motors"]) > 0))
            return until()
        self.clock.wait_until(sample, seconds)
        return rows

    def test_a_battery_warning_then_critical_lands(self):
        name = "crazyflie3"
        self.take_off(name)
        self.world.control("set_battery", uri=URIS[name], voltage=WARNING_V)
        self.assertTrue(wait_until(lambda: self.rosout.find("below the warning level"), 10.0),
                        self.rosout.lines[-5:])
        warned = self.rosout.find("below the warning level")[0]
        self.assertIn("3.4", warned)            # the figures: the voltage and the level
        self.assertTrue(wait_until(lambda: (self.status[name].latest() or DiagnosticStatus()).level
                                   == DiagnosticStatus.WARN, 5.0))
        self.clock.sleep(1.0)
        self.assertLess(abs(self.flyers[name].truth()["position"][2] - HEIGHT), 0.05, "a warning is not a landing")
        self.world.control("set_battery", uri=URIS[name], voltage=CRITICAL_V)
        rows = self.track(name, lambda: not self.motors_on(name), 15.0)
        ok = not self.motors_on(name)
        state = self.flyers[name].truth()
        print("SAFETY_BATTERY truth (world s, z m, motors on): %s; off at z %.3f m"
              % (" ".join("%.2f/%.3f/%d" % (t, z, m) for t, z, _, m in rows[::10]), state["position"][2]))
        self.assertTrue(ok, "still flying on a critical battery: %s" % state)
        self.assertLess(state["position"][2], 0.03, "motors stopped above the floor")
        self.assertEqual(len(self.rosout.find("below the critical level")), 1)
        self.assertTrue(self.rosout.find("landing by the onboard high-level commander"), self.rosout.lines[-5:])
        self.assertTrue(any("battery critical" in m.message and m.level == DiagnosticStatus.ERROR
                            for _, m in self.status[name].messages))
        self.assertEqual(len(self.rosout.find("warning level")), 1)
        self.flyers[name].goal = None

    def test_b_removed_while_flying_is_landed_first(self):
        name = "crazyflie4"
        self.take_off(name)
        answered = threading.Event()
        hover = self.flyers[name].truth()["position"]
        go_to = rospy.ServiceProxy("/%s/go_to" % name, GoTo)
        go_to.wait_for_service(5.0)
        outcomes = []       # (world s, "ok" or the refusal) of each go_to while the removal lands it

        def go_to_meanwhile():
            req = GoTo._request_class(groupMask=0, relative=False, yaw=0.0, duration=rospy.Duration(1.0))
            req.goal.x, req.goal.y, req.goal.z = hover
            while not answered.is_set():
                try:
                    go_to(req)
                    outcomes.append((self.clock.now(), "ok"))
                except (rospy.ServiceException, rospy.ROSException) as e:
                    outcomes.append((self.clock.now(), str(e)))
                time.sleep(GO_TO_PERIOD_S)

        def remove():
            rospy.ServiceProxy("/remove_crazyflie", RemoveCrazyflie)(uri=URIS[name])
            answered.set()
        threading.Thread(target=remove, daemon=True).start()
        threading.Thread(target=go_to_meanwhile, daemon=True).start()
        rows = self.track(name, lambda: answered.is_set() and not self.motors_on(name), 15.0)
        self.assertTrue(answered.is_set(), "/remove_crazyflie did not answer within 15 s of world time")
        on = [r for r in rows if r[3]]
        print("SAFETY_REMOVE truth (world s, z m, motors on): %s"
              % " ".join("%.2f/%.3f/%d" % (t, z, m) for t, z, _, m in rows[::10]))
        self.assertFalse(self.motors_on(name), "motors still on after the removal")
        off = next(r for r in rows if not r[3])
        self.assertLess(off[1], 0.03, "motors stopped above the floor: %s" % (off,))
        self.assertGreater(off[0] - rows[0][0], 1.0, "motors stopped at once: a drop, not a landing")
        self.assertLess(-min(vz for _, _, vz, _ in on), 0.8, "fell instead of landing")
        self.assertTrue(self.rosout.find("removed by /remove_crazyflie"), self.rosout.lines[-5:])
        refused = [t for t, text in outcomes if "refused, nothing sent: the server is bringing it down" in text]
        print("SAFETY_REMOVE go_to calls during the removal: %d, refused: %d" % (len(outcomes), len(refused)))
        self.assertGreater(len(refused), 5, outcomes[:5])
        self.flyers[name].goal = None

    def test_c_radio_lost_watchdog_keepalive_on_and_off(self):
        for name in ("crazyflie1", "crazyflie2"):
            self.take_off(name)
        try:
            self.world.set_dongle_faults(0, unplugged=True)
            self.world.set_dongle_faults(1, unplugged=True)
            unplugged_at = {name: self.world.control("dongle_faults", dongle=dongle)[0]["plug_changed_at"]
                            for name, dongle in (("crazyflie1", 0), ("crazyflie2", 1))}
            off_at = {}

            def both_off():
                for name in ("crazyflie1", "crazyflie2"):
                    if name not in off_at:
                        s = self.flyers[name].truth()
                        if max(s["motors"]) == 0:
                            self.assertIsNotNone(s["locked_at"], s)      # stopped by its supervisor
                            off_at[name] = s["locked_at"] - unplugged_at[name]
                return len(off_at) == 2
            ok = both_off()
            while not ok and self.clock.now() < max(unplugged_at.values()) + 5.0:
                time.sleep(0.01)
                ok = both_off()
            print("SAFETY_LINK motors off after the unplug (world s): %s" % off_at)
            self.assertTrue(ok, off_at)
            self.assertLess(off_at["crazyflie1"], WATCHDOG_S, "keep-alive on: the firmware stops within 1 s")
            self.assertGreater(off_at["crazyflie2"], SETPOINT_WATCHDOG_S - 0.1, "keep-alive off: as before")
            self.assertLess(off_at["crazyflie2"], SETPOINT_WATCHDOG_S + 0.1)
        finally:
            self.world.set_dongle_faults(0, unplugged=False)
            self.world.set_dongle_faults(1, unplugged=False)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "safety_onboard", SafetyOnboard, sys.argv)
