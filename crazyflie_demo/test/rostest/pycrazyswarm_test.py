#!/usr/bin/env python3
"""Crazyswarm scripts run unchanged (test/pycrazyswarm_scripts/scripts, their YAML in ../launch):
hello world and a figure-8 from a CSV, each as a user runs it, in a subprocess from its directory.

~mode "sim": each script runs with --sim and starts its own simulated world and swarm server (on
this test's master, at ~sim_address), which must be gone when the script ends. ~mode "swarm": the
.test file runs swarm.launch sim:=true with the scripts' YAML; the scripts run without --sim, and
hello world once more with --sim, which joins that world.

Judged on the world's truth (the world server's vehicle state), never on what the API says.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
import unittest

import numpy as np
import rospy
import rostest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))  # test/: the support package
from support.flight_support import Track, WorldProbe  # noqa: E402

from crazyflie_driver.nodes.ros_signals import init_node  # noqa: E402
from uav_trajectory import Trajectory  # noqa: E402

SCRIPTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "pycrazyswarm_scripts", "scripts")
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


def run_and_record(name, *args):
    env = dict(os.environ)
    env["CRAZYFLIE_SIM_ADDRESS"] = rospy.get_param("~sim_address")
    t0 = time.monotonic()
    p = subprocess.Popen([sys.executable, name] + list(args), cwd=SCRIPTS, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, universal_newlines=True)
    rec = Recording(rospy.get_param("~sim_address"))
    import threading
    out = []
    reader = threading.Thread(target=lambda: out.append(p.stdout.read()), daemon=True)
    reader.start()
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


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "pycrazyswarm", PycrazyswarmScripts, sys.argv)
