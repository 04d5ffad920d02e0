#!/usr/bin/env python3
"""Crazyswarm scripts run unchanged (test/pycrazyswarm_scripts/scripts, their YAML in ../launch):
hello world and a figure-8 from a CSV, each as a user runs it, in a subprocess from its directory;
against the running swarm also full-state and velocity streaming, group masks, a nice hover, one
Crazyflie after the other, timed waypoints from a CSV and a two-group swap; in both, Crazyswarm2's
hover setpoints (cmd_hover.py). Where a script waits for
the operator's go-ahead, the test gives it (a line on the script's stdin) once the world shows what
the script was to do before it.

~mode "sim": each script runs with --sim and starts its own simulated world and swarm server (on
this test's master, at ~sim_address), which must be gone when the script ends. ~mode "swarm": the
.test file runs swarm.launch sim:=true with the scripts' YAML; the scripts run without --sim, and
hello world once more with --sim, which joins that world.

Judged on the world's truth (the world server's vehicle state), never on what the API says.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import time
import unittest

import numpy as np
import rospy
import rostest

from crazyflie_driver.nodes.ros_signals import init_node
from support.flight_support import Track, WorldProbe
from uav_trajectory import Trajectory

SCRIPTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "pycrazyswarm_scripts", "scripts")
CRAZYSWARM2_DIR = os.path.join(SCRIPTS, "..", "crazyswarm2", "launch")    # crazyflies.yaml in Crazyswarm2's form
NAMES = ("cf1", "cf2")
INITIAL = {"cf1": (0.0, 0.0, 0.0), "cf2": (0.0, 1.5, 0.0)}
SCRIPT_TIMEOUT_S = 240.0          # wall: a world start-up and the flight on a loaded machine
HEIGHT_M = 1.0
HOVER_BOUND_M = 0.05              # hello world's hover height and place
LANDED_Z_M = 0.08                 # landing target 4-6 cm above the floor, then motors off
ON_GROUND_Z_M = 0.02
CLIMB_EXCLUDED_M = 0.05           # below this under 1 m: still climbing (or landing), not on the figure-8's plane
STREAM_HEIGHT_M = 0.5             # cmd_full_state.py's take-off height and figure-8 plane
PATH_BOUND_M = 0.10               # every flown point near the planned figure-8, every planned point flown
# velocity_circle.py steers by streamed velocities with a 1/s pull toward its planned point, so its path
# is off by about the onboard velocity error times 1 s; the Kalman filter's velocity error reaches
# 0.15 m/s at worst on bench_onboard's figure-8 (docs/simulation.md, "Onboard estimator"). Measured
# with it: 3.8 cm mean, 12.1 cm at worst. The mean tells the circle was flown, the worst a runaway.
VELOCITY_PATH_MEAN_BOUND_M = 0.06
VELOCITY_PATH_MAX_BOUND_M = 0.20
WAYPOINT_BOUND_M = 0.05           # each timed waypoint reached this close
SEPARATION_M = 0.5                # the swap's lanes keep the two this far apart
PRESS_TIMEOUT_S = 60.0            # world s for what a script does before the operator's go-ahead
HOLD_S = 3.0                      # world s a nice hover is held before the go-ahead (the script waits from ~2.5 s)
LANDING_TIMEOUT_S = 10.0          # world s for a landing a script sent just before it ended
HOVER_SETPOINT_Z_M = 0.8          # cmd_hover.py's height on hover setpoints (it takes off to 0.5 m)
HOVER_SIDE_M = 0.5                # its square's side: 0.25 m/s forward for 2 s, then a quarter turn left
HOVER_CORNER_BOUND_M = 0.10       # each corner passed this close (the sides' errors add up round the square)
HOVER_MOVING_M_S = 0.15           # faster than this on a side (its 0.25 m/s), the motion shows the heading
HOVER_HEADING_BOUND_DEG = 15.0    # the direction it moves in, off where it faces
HOVER_TURN_DEG = 360.0            # four quarter turns, counterclockwise
HOVER_TURN_BOUND_DEG = 15.0


class Recording:
    """The world's truth of both Crazyflies while a script runs (started before it, so the
    script's own world is caught as soon as it answers)."""

    def __init__(self, probe_address: str) -> None:
        self.address = probe_address
        self.track = None

    def start_when_world_answers(self, process_alive) -> None:
        deadline = time.monotonic() + SCRIPT_TIMEOUT_S
        while time.monotonic() < deadline and process_alive():
            try:
                probe = WorldProbe(self.address)
                for n in NAMES:
                    probe.state(n)
            except Exception:
                time.sleep(0.2)
                continue
            self.track = Track(probe, NAMES, period=0.05)
            return

    def positions(self, name):
        return np.array([s["position"] for _, s, _ in self.track.samples[name]]) if self.track else np.zeros((0, 3))

    def velocities(self, name):
        """True velocity (m/s, world frame) of ``positions(name)``'s samples."""
        samples = self.track.samples[name] if self.track else []
        return np.array([s["velocity"] for _, s, _ in samples]).reshape(-1, 3)

    def yaws_deg(self, name):
        """True yaw (deg) of ``positions(name)``'s samples."""
        from crazyflie_driver.mocap.frames import yaw_of
        samples = self.track.samples[name] if self.track else []
        return np.degrees([yaw_of(s["quaternion"]) for _, s, _ in samples])

    def times(self, name):
        """Monotonic stamps of ``positions(name)``."""
        return np.array([t for t, _, _ in self.track.samples[name]]) if self.track else np.zeros(0)


def press_when(p, presses, pressed):
    """The operator's go-ahead: a line on the script's stdin as soon as each condition on the world's
    truth holds (in order); ``pressed`` gets the monotonic time of each."""
    probe = WorldProbe(rospy.get_param("~sim_address"))
    for condition in presses:
        ok = probe.clock.wait_until(lambda c=condition: p.poll() is not None or c(probe), PRESS_TIMEOUT_S)[0]
        if not ok or p.poll() is not None:
            p.stdin.close()         # no go-ahead: end of input, the script goes on (and the test fails)
            return
        pressed.append(time.monotonic())
        p.stdin.write("\n")
        p.stdin.flush()


def near(name, target, tolerance):
    """A condition: the vehicle within ``tolerance`` m of ``target`` (world truth)."""
    return lambda probe: float(np.linalg.norm(np.array(probe.position(name)) - target)) < tolerance


def held_near(targets, tolerance, hold_s):
    """A condition: every vehicle within ``tolerance`` m of its target, for ``hold_s`` s of world time."""
    since = []

    def condition(probe):
        if not all(near(n, target, tolerance)(probe) for n, target in targets.items()):
            since.clear()
            return False
        if not since:
            since.append(probe.clock.now())
        return probe.clock.now() - since[0] >= hold_s
    return condition


def wait_all_down(probe, names):
    """Until every vehicle is on the ground (world truth), up to LANDING_TIMEOUT_S of world time."""
    return probe.clock.wait_until(lambda: all(probe.state(n)["on_ground"] for n in names), LANDING_TIMEOUT_S)[0]


def run_and_record(name, *args, presses=None, pressed=None, cwd=SCRIPTS):
    """Run a script of SCRIPTS from ``cwd`` (whose ../launch/crazyflies.yaml it then flies, if there is one)."""
    env = dict(os.environ)
    env["CRAZYFLIE_SIM_ADDRESS"] = rospy.get_param("~sim_address")
    t0 = time.monotonic()
    p = subprocess.Popen([sys.executable, os.path.join(SCRIPTS, name)] + list(args), cwd=cwd, env=env,
                         stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, stdin=subprocess.PIPE if presses else subprocess.DEVNULL,
                         universal_newlines=True)
    rec = Recording(rospy.get_param("~sim_address"))
    import threading
    out = []
    reader = threading.Thread(target=lambda: out.append(p.stdout.read()), daemon=True)
    reader.start()
    if presses:
        threading.Thread(target=press_when, args=(p, presses, pressed if pressed is not None else []),
                         daemon=True).start()
    rec.start_when_world_answers(lambda: p.poll() is None)
    try:
        code = p.wait(SCRIPT_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        p.kill()
        code = p.wait()
    if rec.track is not None:
        rec.track.stop()
    reader.join(5.0)
    print("%s %s: exit %d in %.1f s\n%s" % (name, " ".join(args), code, time.monotonic() - t0,
                                           "".join(out)[-3000:]), flush=True)
    return code, rec


def figure8_curve(start):
    traj = Trajectory().loadcsv(os.path.join(SCRIPTS, "figure8.csv"))
    return np.array([np.array(start) + traj.eval(t).pos for t in np.linspace(0, traj.duration, 800)])


class PycrazyswarmScripts(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        init_node("pycrazyswarm_test")
        cls.mode = rospy.get_param("~mode")
        cls.sim_args = ("--sim",) if cls.mode == "sim" else ()

    def world_gone(self):
        import rosgraph
        pubs, subs, services = rosgraph.Master("/pycrazyswarm_test").getSystemState()
        return "/crazyflie_sim" not in {n for _, ns in list(pubs) + list(subs) + list(services) for n in ns}

    def check_hello_world(self, code, rec):
        self.assertEqual(code, 0, "hello_world.py failed")
        cf1, cf2 = rec.positions("cf1"), rec.positions("cf2")
        self.assertGreater(len(cf1), 100, "too few samples of the world")
        top = cf1[np.argmax(cf1[:, 2])]
        hover = cf1[np.abs(cf1[:, 2] - HEIGHT_M) < 2 * HOVER_BOUND_M]
        self.assertGreater(len(hover), 40, "cf1 never hovered near 1 m: highest %s" % top)   # >= 2 s of the 5 s hover
        self.assertLess(np.abs(hover[:, 2] - HEIGHT_M).mean(), HOVER_BOUND_M / 2)
        self.assertLess(np.abs(hover[:, :2] - INITIAL["cf1"][:2]).max(), HOVER_BOUND_M, "cf1 drifted off its place")
        self.assertLess(cf1[-1][2], LANDED_Z_M, "cf1 did not land: %s" % cf1[-1])
        self.assertLess(cf2[:, 2].max(), ON_GROUND_Z_M, "cf2 was not told to fly but rose to %.3f m" % cf2[:, 2].max())
        print("hello_world: cf1 hovered at %.3f m (mean of %d samples), landed at %.3f m"
              % (hover[:, 2].mean(), len(hover), cf1[-1][2]))

    def check_figure8(self, code, rec, script="figure8_csv.py", names=NAMES, height=HEIGHT_M, min_samples=200):
        self.assertEqual(code, 0, "%s failed" % script)
        for name in names:
            flown = rec.positions(name)
            start = np.array(INITIAL[name]) + [0, 0, height]
            curve = figure8_curve(start)
            high = flown[flown[:, 2] > height - CLIMB_EXCLUDED_M]     # the figure-8, the hovers before and after
            self.assertGreater(len(high), min_samples, "%s: too little flight at height" % name)
            off = np.min(np.linalg.norm(high[:, None, :] - curve[None, :, :], axis=2), axis=1)
            missed = np.min(np.linalg.norm(curve[:, None, :] - high[None, :, :], axis=2), axis=1)
            worst = int(np.argmax(off))
            print("figure8 %s: %d samples at height; flown off the curve max %.3f m (at %s, sample %d of %d) mean "
                  "%.3f m; curve missed by at most %.3f m" % (name, len(high), off.max(), np.round(high[worst], 3),
                                                              worst, len(high), off.mean(), missed.max()))
            self.assertLess(off.max(), PATH_BOUND_M, "%s strayed from the figure-8" % name)
            self.assertLess(missed.max(), PATH_BOUND_M, "%s did not fly the whole figure-8" % name)
            self.assertLess(flown[-1][2], LANDED_Z_M, "%s did not land" % name)

    def test_1_hello_world(self):
        code, rec = run_and_record("hello_world.py", *self.sim_args)
        self.check_hello_world(code, rec)
        if self.mode == "sim":
            self.assertTrue(self.world_gone(), "the world the script started is still running")

    def test_2_figure8_from_csv(self):
        code, rec = run_and_record("figure8_csv.py", *self.sim_args)
        self.check_figure8(code, rec)
        if self.mode == "sim":
            self.assertTrue(self.world_gone(), "the world the script started is still running")

    def test_2b_a_crazyswarm2_yaml_flies_its_enabled_robots(self):
        """hello_world.py with the same swarm in Crazyswarm2's form, run from that file's folder (a script
        looks for ../launch/crazyflies.yaml from its working directory first: that very file)."""
        if self.mode != "sim":
            return
        code, rec = run_and_record("hello_world.py", *self.sim_args, cwd=CRAZYSWARM2_DIR)
        self.check_hello_world(code, rec)
        self.assertTrue(self.world_gone(), "the world the script started is still running")

    def test_3_sim_joins_a_running_world(self):
        if self.mode != "swarm":
            return
        code, rec = run_and_record("hello_world.py", "--sim")
        self.check_hello_world(code, rec)
        self.assertFalse(self.world_gone(), "the joined world must keep running")


    def test_4_a_csv_uploaded_by_the_tool_flies(self):
        """upload_trajectory takeoff.csv to cf2, start it on cf2 alone (relative): it rises 1 m."""
        if self.mode != "swarm":
            return
        from crazyflie_driver.srv import Land, StartTrajectory
        tool = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "upload_trajectory")
        takeoff_csv = os.path.join(SCRIPTS, "..", "..", "..", "trajectories", "takeoff.csv")
        p = subprocess.run([sys.executable, tool, takeoff_csv, "cf2", "--id", "2"], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, timeout=60)
        print(p.stdout)
        self.assertEqual(p.returncode, 0, p.stdout)
        duration = Trajectory().loadcsv(takeoff_csv).duration
        probe = WorldProbe(rospy.get_param("~sim_address"))
        track = Track(probe, ["cf2"], period=0.05)
        try:
            rospy.ServiceProxy("/cf2/start_trajectory", StartTrajectory)(0, 2, 1.0, False, True)
            probe.sleep(duration + 1.0)
            at_top = probe.position("cf2")
            rospy.ServiceProxy("/cf2/land", Land)(0, 0.03, rospy.Duration(2.0))
            probe.sleep(3.0)
            landed = probe.position("cf2")
        finally:
            track.stop()
        z = [s["position"][2] for _, s, _ in track.samples["cf2"]]
        print("takeoff.csv on cf2: %.3f m after %.1f s (highest %.3f m), landed at %.3f m"
              % (at_top[2], duration + 1.0, max(z), landed[2]))
        self.assertLess(abs(at_top[2] - HEIGHT_M), HOVER_BOUND_M, "cf2 did not rise the file's 1 m")
        self.assertLess(max(z), HEIGHT_M + HOVER_BOUND_M, "cf2 overshot the file's 1 m")
        self.assertLess(np.abs(np.array(at_top[:2]) - INITIAL["cf2"][:2]).max(), HOVER_BOUND_M)
        self.assertLess(landed[2], LANDED_Z_M)

    def test_5_full_state_streaming(self):
        """cmd_full_state.py streams the figure-8 at 30 Hz 0.5 m up, then notifySetpointsStop and land."""
        if self.mode != "swarm":
            return
        code, rec = run_and_record("cmd_full_state.py")
        self.check_figure8(code, rec, "cmd_full_state.py", names=("cf1",), height=STREAM_HEIGHT_M, min_samples=120)

    def test_6_group_masks(self):
        """group_mask.py: each broadcast reaches its group only."""
        if self.mode != "swarm":
            return
        code, rec = run_and_record("group_mask.py")
        self.assertEqual(code, 0, "group_mask.py failed")
        cf1, cf2 = rec.positions("cf1"), rec.positions("cf2")
        print("group masks: cf1 highest %.3f m, furthest x %.3f m; cf2 highest %.3f m, x range %.3f m; landed %.3f, "
              "%.3f m" % (cf1[:, 2].max(), cf1[:, 0].max(), cf2[:, 2].max(), np.ptp(cf2[:, 0]), cf1[-1][2], cf2[-1][2]))
        self.assertLess(abs(cf1[:, 2].max() - 0.5), HOVER_BOUND_M, "cf1 took group 2's takeoff (or none)")
        self.assertLess(abs(cf2[:, 2].max() - 1.0), HOVER_BOUND_M, "cf2 did not take off with group 2")
        self.assertLess(abs(cf1[:, 0].max() - 0.5), HOVER_BOUND_M, "cf1 did not move with group 1's goTo")
        self.assertLess(np.ptp(cf2[:, 0]), HOVER_BOUND_M, "cf2 moved with group 1's goTo")
        self.assertLess(max(cf1[-1][2], cf2[-1][2]), LANDED_Z_M, "the land for all did not land both")

    def hover_point(self, name, height=HEIGHT_M):
        return np.array(INITIAL[name]) + [0, 0, height]

    def check_landed_home(self, rec, names=NAMES):
        for name in names:
            last = rec.positions(name)[-1]
            self.assertLess(last[2], LANDED_Z_M, "%s did not land: %s" % (name, last))
            self.assertLess(np.abs(last[:2] - INITIAL[name][:2]).max(), HOVER_BOUND_M, "%s landed off its place" % name)

    def test_7_nice_hover(self):
        """nice_hover.py: all take off, straighten up above their starts and hold there until the
        go-ahead, given once both have held their places for HOLD_S of world time; then all land."""
        if self.mode != "swarm":
            return
        pressed = []
        code, rec = run_and_record("nice_hover.py", pressed=pressed,
                                   presses=[held_near({n: self.hover_point(n) for n in NAMES}, HOVER_BOUND_M, HOLD_S)])
        self.assertEqual(code, 0, "nice_hover.py failed")
        self.assertEqual(len(pressed), 1, "the Crazyflies never held their places above their starts together")
        for name in NAMES:
            xyz, t = rec.positions(name), rec.times(name)
            held = xyz[(t > pressed[0] - HOLD_S + 0.5) & (t <= pressed[0])]
            err = np.linalg.norm(held - self.hover_point(name), axis=1)
            print("nice hover %s: %d samples in the %.1f s before the go-ahead, off the hover point at most %.3f m; "
                  "landed at %s" % (name, len(held), HOLD_S - 0.5, err.max(), np.round(xyz[-1], 3)))
            self.assertGreater(len(held), 10)
            self.assertLess(err.max(), HOVER_BOUND_M, "%s did not hold its place until the go-ahead" % name)
        self.check_landed_home(rec)

    def test_8_individual_hover(self):
        """individual_hover.py: one after the other, each up at 1 m while the next waits on the ground."""
        if self.mode != "swarm":
            return
        pressed = []
        code, rec = run_and_record("individual_hover.py", pressed=pressed,
                                   presses=[near(n, self.hover_point(n), HOVER_BOUND_M) for n in NAMES])
        self.assertEqual(code, 0, "individual_hover.py failed")
        self.assertEqual(len(pressed), 2, "not every Crazyflie reached 1 m in its turn: %d go-aheads" % len(pressed))
        cf2, t2 = rec.positions("cf2"), rec.times("cf2")
        cf2_before = cf2[t2 <= pressed[0]]
        cf2_left = t2[cf2[:, 2] > ON_GROUND_Z_M]
        print("individual hover: cf2 highest %.3f m while cf1 was up; cf2 left the ground %.2f s after cf1's "
              "go-ahead" % (cf2_before[:, 2].max(), cf2_left[0] - pressed[0]))
        self.assertLess(cf2_before[:, 2].max(), ON_GROUND_Z_M, "cf2 took off before its turn")
        self.assertGreater(cf2_left[0], pressed[0], "cf2 took off before cf1's go-ahead")
        probe = WorldProbe(rospy.get_param("~sim_address"))        # the script ends as cf2's landing starts
        self.assertTrue(wait_all_down(probe, NAMES), "not both landed after the script sent their lands: %s"
                        % ([probe.position(n) for n in NAMES],))
        for name in NAMES:
            final = np.array(probe.position(name))
            self.assertLess(np.abs(final[:2] - INITIAL[name][:2]).max(), HOVER_BOUND_M, "%s landed off its place"
                            % name)

    def test_9_timed_waypoints(self):
        """waypoints.py: each Crazyflie reaches every waypoint of waypoints.csv, in order, and lands home."""
        if self.mode != "swarm":
            return
        code, rec = run_and_record("waypoints.py")
        self.assertEqual(code, 0, "waypoints.py failed")
        rows = np.loadtxt(os.path.join(SCRIPTS, "waypoints.csv"), skiprows=1, delimiter=",", ndmin=2)
        for cf_id in (1, 2):
            name = "cf%d" % cf_id
            flown = rec.positions(name)
            points = rows[rows[:, 0] == cf_id][:, 1:4]
            reached = []
            start = 0
            for wp in points:       # the first pass within the bound after the previous waypoint's
                d = np.linalg.norm(flown[start:] - wp, axis=1)
                hits = np.nonzero(d < WAYPOINT_BOUND_M)[0]
                self.assertTrue(len(hits), "%s missed waypoint %s after the one before (closest %.3f m)"
                                % (name, wp, d.min() if len(d) else np.inf))
                reached.append(d[hits].min())
                start += int(hits[0])
            print("waypoints %s: %d reached in order, each within %.3f m" % (name, len(points), max(reached)))
        self.check_landed_home(rec)

    def test_10_group_swap(self):
        """group_swap.py: groups 1 and 2 swap places by broadcast goTos and swap back, never closer than their lanes."""
        if self.mode != "swarm":
            return
        code, rec = run_and_record("group_swap.py")
        self.assertEqual(code, 0, "group_swap.py failed")
        cf1, cf2 = rec.positions("cf1"), rec.positions("cf2")
        n = min(len(cf1), len(cf2))
        cf1, cf2 = cf1[:n], cf2[:n]
        swapped = (np.linalg.norm(cf1 - self.hover_point("cf2"), axis=1) < HOVER_BOUND_M) & \
                  (np.linalg.norm(cf2 - self.hover_point("cf1"), axis=1) < HOVER_BOUND_M)
        flying = (cf1[:, 2] > 0.5) | (cf2[:, 2] > 0.5)
        closest = np.linalg.norm(cf1 - cf2, axis=1)[flying].min()
        print("group swap: %d samples with both at each other's place; closest %.3f m while flying" %
              (swapped.sum(), closest))
        self.assertGreater(swapped.sum(), 5, "the two never stood at each other's place")
        self.assertGreater(closest, SEPARATION_M - HOVER_BOUND_M, "the lanes did not keep them apart")
        self.check_landed_home(rec)

    def test_11_velocity_streaming(self):
        """velocity_circle.py: cf1 flies two circles on streamed world velocities, then the HL lands it."""
        if self.mode != "swarm":
            return
        code, rec = run_and_record("velocity_circle.py")
        self.assertEqual(code, 0, "velocity_circle.py failed")
        flown = rec.positions("cf1")
        centre = self.hover_point("cf1") + [-0.5, 0, 0]
        a = np.linspace(0, 2 * np.pi, 400)
        curve = centre + 0.5 * np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
        high = flown[flown[:, 2] > HEIGHT_M - CLIMB_EXCLUDED_M]
        off = np.min(np.linalg.norm(high[:, None, :] - curve[None, :, :], axis=2), axis=1)
        missed = np.min(np.linalg.norm(curve[:, None, :] - high[None, :, :], axis=2), axis=1)
        print("velocity circle: %d samples at height; off the circle max %.3f m mean %.3f m; circle missed by at "
              "most %.3f m; cf2 highest %.3f m" % (len(high), off.max(), off.mean(), missed.max(),
                                                   rec.positions("cf2")[:, 2].max()))
        self.assertGreater(len(high), 100)
        self.assertLess(off.mean(), VELOCITY_PATH_MEAN_BOUND_M, "cf1 flew off the circle")
        self.assertLess(off.max(), VELOCITY_PATH_MAX_BOUND_M, "cf1 strayed from the circle")
        self.assertLess(missed.max(), PATH_BOUND_M, "cf1 did not fly the whole circle")
        self.check_landed_home(rec)

    def test_12_all_notify_setpoints_stop(self):
        """/all/notify_setpoints_stop hands every Crazyflie back to its high-level commander: with both
        streaming a position 5 cm up (motors running), one call, and the idle planners' null setpoints
        stop every motor, no land needed (world truth)."""
        if self.mode != "swarm":
            return
        from crazyflie_driver.msg import Position
        from crazyflie_driver.srv import NotifySetpointsStop
        probe = WorldProbe(rospy.get_param("~sim_address"))
        pubs = {n: rospy.Publisher("/%s/cmd_position" % n, Position, queue_size=1) for n in NAMES}
        stop_streaming = []

        def stream():
            while not stop_streaming and not rospy.is_shutdown():
                for n, pub in pubs.items():
                    x, y, _ = INITIAL[n]
                    pub.publish(Position(x=x, y=y, z=0.05, yaw=0.0))
                time.sleep(0.02)
        import threading
        streamer = threading.Thread(target=stream, daemon=True)
        streamer.start()
        try:
            spinning = probe.clock.wait_until(lambda: all(min(probe.state(n)["motors"]) > 0 for n in NAMES), 10.0)[0]
            self.assertTrue(spinning, "the streamed positions never ran the motors: %s"
                            % {n: probe.state(n)["motors"] for n in NAMES})
            stop_streaming.append(True)
            streamer.join(1.0)
            rospy.ServiceProxy("/all/notify_setpoints_stop", NotifySetpointsStop)(0, 100)
            t0 = probe.clock.now()
            stopped = probe.clock.wait_until(lambda: all(max(probe.state(n)["motors"]) == 0 for n in NAMES), 1.0)[0]
            print("all/notify_setpoints_stop: motors %s %.2f s after the call" % (
                "off" if stopped else "still on", probe.clock.now() - t0))
            self.assertTrue(stopped, "a Crazyflie's motors kept running after /all/notify_setpoints_stop: %s"
                            % {n: probe.state(n)["motors"] for n in NAMES})
            self.assertTrue(wait_all_down(probe, NAMES))
        finally:
            stop_streaming.append(True)

    def test_13_hover_setpoints(self):
        """cmd_hover.py (Crazyswarm2's cmdHover): cf1 holds the absolute height of its hover setpoints and
        flies a square by its own frame alone (forward, a quarter turn left, four times): each side goes
        where it faces, the corners come in order, it turns a full circle; then it lands home. In both
        modes (with --sim, in the script's own world)."""
        code, rec = run_and_record("cmd_hover.py", *self.sim_args)
        self.assertEqual(code, 0, "cmd_hover.py failed")
        xyz, vel, yaw = rec.positions("cf1"), rec.velocities("cf1"), rec.yaws_deg("cf1")
        high = np.abs(xyz[:, 2] - HOVER_SETPOINT_Z_M) < HOVER_BOUND_M
        self.assertGreater(high.sum(), 100, "cf1 never held the hover setpoints' %.1f m: highest %.3f m"
                           % (HOVER_SETPOINT_Z_M, xyz[:, 2].max()))
        first = int(np.nonzero(high)[0][0])
        corners = xyz[first, :2] + HOVER_SIDE_M * np.array([[1, 0], [1, 1], [0, 1], [0, 0]])     # (height: above)
        start, reached = first, []
        for corner in corners:              # each the first pass within the bound after the one before
            d = np.linalg.norm(xyz[start:, :2] - corner, axis=1)
            hits = np.nonzero(d < HOVER_CORNER_BOUND_M)[0]
            self.assertTrue(len(hits), "cf1 missed the square's corner %s after the one before (closest %.3f m)"
                            % (np.round(corner, 3), d.min() if len(d) else np.inf))
            reached.append(float(d[hits].min()))
            start += int(hits[0])
        speed = np.linalg.norm(vel[:, :2], axis=1)
        moving = high & (speed > HOVER_MOVING_M_S)
        off_heading = (np.degrees(np.arctan2(vel[:, 1], vel[:, 0])) - yaw + 180.0) % 360.0 - 180.0
        turned = np.unwrap(np.radians(yaw[first:]))
        turn_deg = math.degrees(turned.max() - turned[0])
        print("hover setpoints: %d samples at %.3f m (mean; setpoint %.1f m); corners reached within %s m; moving "
              "(%d samples) off its heading by at most %.1f deg; turned %.1f deg; landed at %s; cf2 highest %.3f m"
              % (high.sum(), xyz[high, 2].mean(), HOVER_SETPOINT_Z_M, np.round(reached, 3), moving.sum(),
                 np.abs(off_heading[moving]).max() if moving.any() else float("nan"), turn_deg,
                 np.round(xyz[-1], 3), rec.positions("cf2")[:, 2].max()))
        self.assertLess(np.abs(xyz[high, 2] - HOVER_SETPOINT_Z_M).mean(), HOVER_BOUND_M / 2)
        self.assertGreater(moving.sum(), 20, "cf1 hardly moved on its hover setpoints")
        self.assertLess(np.abs(off_heading[moving]).max(), HOVER_HEADING_BOUND_DEG,
                        "cf1 moved other than where it faced (the hover setpoint's velocities are in its own frame)")
        self.assertLess(abs(turn_deg - HOVER_TURN_DEG), HOVER_TURN_BOUND_DEG, "cf1 did not turn a full circle left")
        self.check_landed_home(rec, names=("cf1",))
        self.assertLess(rec.positions("cf2")[:, 2].max(), ON_GROUND_Z_M, "cf2 was not told to fly")
        if self.mode == "sim":
            self.assertTrue(self.world_gone(), "the world the script started is still running")

if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "pycrazyswarm", PycrazyswarmScripts, sys.argv)
