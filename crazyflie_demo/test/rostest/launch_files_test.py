#!/usr/bin/env python3
"""Every launch file of crazyflie_demo starts with sim:=true gui:=false and brings up its nodes.

For each launch file: ``roslaunch --nodes`` must list exactly the expected nodes (no rviz with
gui:=false, no joystick driver where auto takes off by itself), then a real start on its own
master port and world address must bring them up, with every Crazyflie added to the server (its
``emergency`` service exists). Then Ctrl-C (SIGINT to roslaunch) must bring everything down
within CTRL_C_S seconds, from that moment of start-up, when nodes are still registering with
the master: roslaunch escalates to SIGTERM only after 15 s, so a node that ignores SIGINT
shows up as a slow shutdown. Two launch files start at a time to keep the run short.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import unittest
from typing import Dict, List, Set, Tuple

import rosgraph
import rospy
import rostest

SIM = ["/crazyflie_sim", "/crazyflie_server"]


def _ns(ns: str, names: List[str]) -> List[str]:
    return ["/%s/%s" % (ns, n) for n in names]


HOVER = ["crazyflie_add", "joystick_controller", "autopilot", "controller", "pose"]
WAYPOINT = ["crazyflie_add", "joystick_controller", "controller", "demo"]
TELEOP = ["crazyflie_add", "joy", "quadrotor_teleop", "crazyflie_demo_controller"]
PAD = ["joy", "quadrotor_teleop"]
BASELINK = ["baselink_broadcaster"]     # the chapter's static tf mocap frame -> <name>/base_link

# launch file -> (expected nodes with sim:=true gui:=false, namespaces of Crazyflies, extra args)
EXPECTED: Dict[str, Tuple[List[str], List[str], List[str]]] = {
    "customLogBlocks.launch": (SIM + ["/crazyflie/crazyflie_add"], ["crazyflie"], []),
    "external_position_vicon.launch": (SIM + _ns("crazyflie", ["crazyflie_add", "pose"] + BASELINK),
                                       ["crazyflie"], []),
    "external_pose_vicon.launch": (SIM + _ns("crazyflie", ["crazyflie_add", "pose"] + BASELINK), ["crazyflie"], []),
    "external_position_vrpn.launch": (SIM + _ns("crazyflie1", ["crazyflie_add", "pose", "vrpn_client_node"]),
                                      ["crazyflie1"], ["port:=19938"]),
    "swarm_external_position_vrpn.launch": (SIM + _ns("crazyflie1", ["crazyflie_add", "pose"])
                                            + _ns("crazyflie2", ["crazyflie_add", "pose"])
                                            + _ns("crazyflie3", ["crazyflie_add", "pose"]) + ["/vrpn_client_node"],
                                            ["crazyflie1", "crazyflie2", "crazyflie3"], ["port:=19939"]),
    "hover.launch": (SIM + _ns("cf1", ["crazyflie_add", "pose"]) + _ns("cf2", ["crazyflie_add", "pose"])
                     + ["/crazyflie_demo_hover"], ["cf1", "cf2"], []),
    "position.launch": (SIM + _ns("crazyflie", ["crazyflie_add", "pose", "crazyflie_demo_hover"]), ["crazyflie"], []),
    "hover_vicon.launch": (SIM + _ns("crazyflie", HOVER + BASELINK), ["crazyflie"], []),
    "hover_vrpn.launch": (SIM + _ns("crazyflie", HOVER), ["crazyflie"], []),
    "teleop_vicon.launch": (SIM + _ns("crazyflie", HOVER + BASELINK), ["crazyflie"], []),
    "multi_hover_vicon.launch": (SIM + _ns("crazyflie1", HOVER + BASELINK) + _ns("crazyflie2", HOVER + BASELINK),
                                 ["crazyflie1", "crazyflie2"], []),
    "multi_hover_vrpn.launch": (SIM + _ns("crazyflie1", HOVER) + _ns("crazyflie2", HOVER),
                                ["crazyflie1", "crazyflie2"], []),
    "multi_waypoint_vicon.launch": (SIM + _ns("crazyflie1", WAYPOINT + BASELINK)
                                    + _ns("crazyflie2", WAYPOINT + BASELINK),
                                    ["crazyflie1", "crazyflie2"], []),
    "teleop_xbox360.launch": (SIM + _ns("crazyflie", TELEOP), ["crazyflie"], []),
    "teleop_ps3.launch": (SIM + _ns("crazyflie", TELEOP), ["crazyflie"], []),
    "multi_teleop_xbox360.launch": (SIM + _ns("crazyflie1", TELEOP + ["crazyflie1_broadcaster"])
                                    + _ns("crazyflie2", TELEOP + ["crazyflie2_broadcaster"]),
                                    ["crazyflie1", "crazyflie2"], []),
    "multi_teleop_ps3.launch": (SIM + _ns("crazyflie1", TELEOP + ["crazyflie1_broadcaster"])
                                + _ns("crazyflie2", TELEOP + ["crazyflie2_broadcaster"]),
                                ["crazyflie1", "crazyflie2"], []),
    "xbox360.launch": (["/" + n for n in PAD], [], []),
    "ps3.launch": (["/" + n for n in PAD], [], []),
    "sim_mission.launch": (SIM + _ns("crazyflie1", WAYPOINT + BASELINK) + _ns("crazyflie2", WAYPOINT + BASELINK)
                           + ["/mission_monitor"], ["crazyflie1", "crazyflie2"], ["plot:={tmp}/mission.png"]),
    "swarm.launch": (SIM + ["/swarm_demo"], ["cf1", "cf2", "cf3", "cf4"], ["n:=4", "vrpn_port:=19936"]),
}
# nodes that finish by design once their work is done (HEAD's Hover.py and Position.py fly, then end)
EXITS = {"crazyflie_add", "crazyflie_demo_hover"}
# Ctrl-C must stop a launch within this many seconds (roslaunch sends SIGTERM after 15 s)
CTRL_C_S = 10.0
# after SIGINT, wait this long before killing roslaunch: past its own escalation (15 s SIGINT,
# 2 s SIGTERM, then SIGKILL), so that roslaunch itself stops every node it started
ESCALATION_S = 25.0


def listed_nodes(launch: str, args: List[str]) -> Set[str]:
    out = subprocess.run(["roslaunch", "--nodes", "crazyflie_demo", launch] + args,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=60, text=True)
    if out.returncode != 0:
        raise AssertionError("roslaunch --nodes %s failed:\n%s" % (launch, out.stdout[-2000:]))
    return {line.strip() for line in out.stdout.splitlines() if line.strip().startswith("/")}


def running_nodes(master: rosgraph.Master) -> Tuple[Set[str], Set[str]]:
    """(node names, service names) as ``rosnode list`` / ``rosservice list`` would show them."""
    pubs, subs, srvs = master.getSystemState()
    nodes = {n for _, ns in pubs + subs + srvs for n in ns}
    return nodes, {s for s, _ in srvs}


class LaunchFiles(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("launch_files_test")
        cls.base_master = int(rospy.get_param("~master_port_base", 11700))
        cls.base_sim = int(rospy.get_param("~sim_port_base", 20010))
        cls.start_timeout = float(rospy.get_param("~start_timeout", 40.0))
        cls.tmp = tempfile.mkdtemp(prefix="cf_launch_")
        cls.failures: Dict[str, str] = {}
        cls.timings: Dict[str, float] = {}
        cls.shutdowns: Dict[str, float] = {}

    def run_one(self, i: int, launch: str) -> None:
        expected, crazyflies, extra = EXPECTED[launch]
        args = ["sim:=true", "gui:=false"] + [a.format(tmp=self.tmp) for a in extra]
        try:
            listed = listed_nodes(launch, args)
            if listed != set(expected):
                raise AssertionError("roslaunch --nodes: missing %s, unexpected %s"
                                     % (sorted(set(expected) - listed), sorted(listed - set(expected))))
            self.start(i, launch, args, expected, crazyflies)
            took = self.shutdowns.get(launch, 0.0)
            if took > CTRL_C_S:
                raise AssertionError("Ctrl-C took %.1f s to stop it (a node did not stop on SIGINT; "
                                     "see %s.log)" % (took, launch))
        except Exception as e:     # collected and reported per launch file
            self.failures[launch] = "%s: %s" % (type(e).__name__, e)

    def start(self, i: int, launch: str, args: List[str], expected: List[str], crazyflies: List[str]) -> None:
        port = self.base_master + i
        sim_address = "127.0.0.1:%d" % (self.base_sim + i)
        env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port)
        log = open(os.path.join(self.tmp, launch + ".log"), "w")
        proc = subprocess.Popen(["roslaunch", "-p", str(port), "crazyflie_demo", launch,
                                 "sim_address:=" + sim_address] + args,
                                stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
        t0 = time.monotonic()
        try:
            master = rosgraph.Master("/launch_files_test", master_uri=env["ROS_MASTER_URI"])
            want_running = {n for n in expected if n.rsplit("/", 1)[-1] not in EXITS}
            want_services = {"/%s/emergency" % ns for ns in crazyflies}
            nodes, services = set(), set()
            while time.monotonic() - t0 < self.start_timeout:
                if proc.poll() is not None:
                    raise AssertionError("roslaunch exited with %s" % proc.returncode)
                try:
                    nodes, services = running_nodes(master)
                except Exception:
                    nodes, services = set(), set()        # master not up yet
                if want_running <= nodes and want_services <= services:
                    self.timings[launch] = time.monotonic() - t0
                    return
                time.sleep(0.25)
            raise AssertionError("after %.0f s: nodes missing %s, Crazyflies not added %s"
                                 % (self.start_timeout, sorted(want_running - nodes),
                                    sorted(want_services - services)))
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
                t_int = time.monotonic()
                try:
                    proc.wait(ESCALATION_S)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait(5.0)
                self.shutdowns[launch] = time.monotonic() - t_int
            log.close()

    def test_every_launch_file_starts_in_the_simulator(self):
        launches = sorted(f for f in os.listdir(os.path.join(os.path.dirname(__file__), "..", "..", "launch"))
                          if f.endswith(".launch"))
        self.assertEqual(sorted(EXPECTED), launches, "the test must know every launch file")
        jobs = list(enumerate(launches))
        lock = threading.Lock()

        def worker():
            while True:
                with lock:
                    if not jobs:
                        return
                    i, launch = jobs.pop(0)
                self.run_one(i, launch)

        threads = [threading.Thread(target=worker) for _ in range(int(rospy.get_param("~parallel", 2)))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        for launch, took in sorted(self.timings.items()):
            print("STARTED %-30s in %.1f s, stopped by Ctrl-C in %.1f s"
                  % (launch, took, self.shutdowns.get(launch, float("nan"))))
        self.assertEqual({}, self.failures, "\n".join("%s: %s" % kv for kv in sorted(self.failures.items())))


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "launch_files", LaunchFiles, sys.argv)
