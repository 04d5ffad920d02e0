"""mission_monitor: watches a simulated multi-Crazyflie waypoint mission and reports on it.

Prints progress while the vehicles fly, then a summary per vehicle (waypoints reached, flight
time, RMS error while holding at waypoints, battery used) and writes a PNG of the flown paths
against the waypoints. Exits when every vehicle has finished its waypoints and landed, or
after ~timeout; as a required node it then ends the launch. ``~result_file`` (optional) gets
"ok" or "incomplete", since roslaunch's exit code does not say how the mission went.
"""
from __future__ import annotations

import os
import threading
from typing import Dict, List, Tuple

import rospy
import tf2_ros
from geometry_msgs.msg import PoseStamped, Twist
from std_msgs.msg import Bool, Float32, Int32

from crazyflie_demo.mission_summary import VehicleTrack, plot_tracks, summary_lines
from crazyflie_demo.rosutil import RealTimeFactor
from crazyflie_driver.nodes.ros_signals import init_node


class MissionMonitor:
    """The vehicles' tracks, fed by their topics (callbacks on rospy's threads) and by tf."""

    def __init__(self, names: List[str], frames: List[str], world: str) -> None:
        self.names, self.frames, self.world = names, frames, world
        self.lock = threading.Lock()
        self.tracks: Dict[str, VehicleTrack] = {n: VehicleTrack(n) for n in names}
        self.waypoints: Dict[str, list] = {}
        self.buffer = tf2_ros.Buffer()
        self._listener = tf2_ros.TransformListener(self.buffer)

    def subscribe(self) -> None:
        for n in self.names:
            rospy.Subscriber(f"/{n}/goal", PoseStamped, lambda msg, n=n: self._on_goal(n, msg), queue_size=10)
            rospy.Subscriber(f"/{n}/battery", Float32, lambda msg, n=n: self._on_battery(n, msg), queue_size=10)
            rospy.Subscriber(f"/{n}/cmd_vel", Twist, lambda msg, n=n: self._on_cmd_vel(n, msg), queue_size=10)
            rospy.Subscriber(f"/{n}/demo/waypoint", Int32, lambda msg, n=n: self._on_waypoint(n, msg),
                             queue_size=10)
            rospy.Subscriber(f"/{n}/demo/finished", Bool, lambda msg, n=n: self._on_finished(n, msg),
                             queue_size=10)

    def _on_goal(self, name: str, msg: PoseStamped) -> None:
        p = msg.pose.position
        with self.lock:
            self.tracks[name].add_goal(rospy.get_time(), (p.x, p.y, p.z))

    def _on_battery(self, name: str, msg: Float32) -> None:
        with self.lock:
            self.tracks[name].add_battery(rospy.get_time(), msg.data)

    def _on_cmd_vel(self, name: str, msg: Twist) -> None:
        with self.lock:
            self.tracks[name].add_thrust(rospy.get_time(), msg.linear.z)

    def _on_waypoint(self, name: str, msg: Int32) -> None:
        now = rospy.get_time()
        with self.lock:
            tr = self.tracks[name]
            for k in range(len(tr.reached_times), msg.data):   # flying to k: 0..k-1 reached
                tr.reach_waypoint(now, k)
                rospy.loginfo("[%s] waypoint %d/%d reached", name, k + 1, tr.waypoint_count)
            rospy.loginfo("[%s] flying to waypoint %d/%d", name, msg.data + 1, tr.waypoint_count)

    def _on_finished(self, name: str, msg: Bool) -> None:
        if not msg.data:
            return
        with self.lock:
            tr = self.tracks[name]
            if tr.finished_time is None:
                tr.finished_time = rospy.get_time()
                for k in range(len(tr.reached_times), tr.waypoint_count):
                    tr.reach_waypoint(tr.finished_time, k)
                rospy.loginfo("[%s] all %d waypoints reached, landing", name, tr.waypoint_count)

    def sample(self, now: float) -> None:
        """Each vehicle's pose from tf (and its waypoints, once its demo has set them)."""
        for n, f in zip(self.names, self.frames):
            if n not in self.waypoints and rospy.has_param(f"/{n}/demo/waypoints"):
                self.waypoints[n] = rospy.get_param(f"/{n}/demo/waypoints")
                self.tracks[n].waypoint_count = len(self.waypoints[n])
            try:
                t = self.buffer.lookup_transform(self.world, f.lstrip("/"), rospy.Time(0))
            except (tf2_ros.LookupException, tf2_ros.ConnectivityException,
                    tf2_ros.ExtrapolationException):
                continue
            p = t.transform.translation
            with self.lock:
                tr = self.tracks[n]
                tr.add_pose(now, (p.x, p.y, p.z))
                if tr.finished_time is not None and tr.landed_time is None and p.z < 0.08 \
                        and now - tr.finished_time > 1.0:
                    tr.landed_time = now
                    rospy.loginfo("[%s] landed", n)

    def progress(self) -> str:
        with self.lock:
            return "  ".join(f"{n}: wp {tr.waypoints_reached}/{tr.waypoint_count} z={tr.positions[-1][2]:.2f}"
                             for n, tr in self.tracks.items() if tr.positions)

    def all_landed(self, now: float, rest_after_landing: float) -> bool:
        """Every vehicle landed with its motors off, then ``rest_after_landing`` s more of battery
        readings at rest."""
        with self.lock:
            return all(tr.landed_time is not None and tr.motors_off_time is not None
                       and now - max(tr.landed_time, tr.motors_off_time) > rest_after_landing
                       for tr in self.tracks.values())

    def report(self, plot_path: str) -> Tuple[bool, str]:
        """Prints the summary, writes the plot; whether every vehicle reached every waypoint."""
        with self.lock:
            tracks = list(self.tracks.values())
            lines = summary_lines(tracks)
            ok = all(tr.waypoints_reached == tr.waypoint_count and tr.waypoint_count > 0 for tr in tracks)
            path = plot_tracks(tracks, self.waypoints, plot_path)
        print("\n=== mission summary ===", flush=True)
        for line in lines:
            print(line, flush=True)
        return ok, path


def _watch(monitor: MissionMonitor, rate: float, timeout: float, rest_after_landing: float) -> None:
    """Samples until every vehicle has landed and rested, the timeout, or shutdown."""
    start = rospy.get_time()
    r = rospy.Rate(rate)
    last_print = start
    while not rospy.is_shutdown():
        now = rospy.get_time()
        monitor.sample(now)
        if now - last_print > 5.0:
            last_print = now
            rospy.loginfo("t=%.0f s  %s", now - start, monitor.progress())
        done = monitor.all_landed(now, rest_after_landing)
        if done or now - start > timeout:
            if not done:
                rospy.logwarn("mission timed out after %.0f s", timeout)
            return
        try:
            r.sleep()
        except rospy.ROSInterruptException:
            return


def _write_result(ok: bool) -> None:
    rospy.set_param("~result", "ok" if ok else "incomplete")
    result_file = rospy.get_param("~result_file", "")
    if result_file:   # roslaunch's exit code does not tell: scripts read this
        try:
            with open(os.path.expanduser(result_file), "w") as f:
                f.write("ok\n" if ok else "incomplete\n")
        except OSError as exc:
            rospy.logerr("cannot write the result to %s: %s", result_file, exc)


def main() -> None:
    init_node("mission_monitor")
    names: List[str] = list(rospy.get_param("~vehicles", ["crazyflie1", "crazyflie2"]))
    frames: List[str] = list(rospy.get_param("~frames", [f"vicon/{n}/{n}" for n in names]))
    world = str(rospy.get_param("~worldFrame", "world")).strip("/")
    timeout = float(rospy.get_param("~timeout", 180.0))
    plot_path = os.path.expanduser(rospy.get_param("~plot", "crazyflie_mission.png"))
    rate = float(rospy.get_param("~rate", 50.0))
    rest_after_landing = float(rospy.get_param("~rest_after_landing", 1.0))

    monitor = MissionMonitor(names, frames, world)
    monitor.subscribe()
    pace = RealTimeFactor()
    _watch(monitor, rate, timeout, rest_after_landing)
    ok, path = monitor.report(plot_path)
    print(pace.line(), flush=True)
    print(f"result: {'every waypoint reached' if ok else 'NOT every waypoint reached'}", flush=True)
    print(f"plot: {os.path.abspath(path)}", flush=True)
    _write_result(ok)
    rospy.signal_shutdown("mission over")
