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
from typing import Dict, List

import rospy
import tf2_ros
from geometry_msgs.msg import PoseStamped, Twist
from std_msgs.msg import Bool, Float32, Int32

from crazyflie_demo.mission_summary import VehicleTrack, plot_tracks, summary_lines
from crazyflie_demo.rosutil import RealTimeFactor
from crazyflie_driver.nodes.ros_signals import init_node


def main() -> None:
    init_node("mission_monitor")
    names: List[str] = list(rospy.get_param("~vehicles", ["crazyflie1", "crazyflie2"]))
    frames: List[str] = list(rospy.get_param("~frames", [f"vicon/{n}/{n}" for n in names]))
    world = str(rospy.get_param("~worldFrame", "world")).strip("/")
    timeout = float(rospy.get_param("~timeout", 180.0))
    plot_path = os.path.expanduser(rospy.get_param("~plot", "crazyflie_mission.png"))
    rate = float(rospy.get_param("~rate", 50.0))
    rest_after_landing = float(rospy.get_param("~rest_after_landing", 1.0))

    lock = threading.Lock()
    tracks: Dict[str, VehicleTrack] = {n: VehicleTrack(n) for n in names}

    def on_goal(name):
        def cb(msg: PoseStamped) -> None:
            p = msg.pose.position
            with lock:
                tracks[name].add_goal(rospy.get_time(), (p.x, p.y, p.z))
        return cb

    def on_battery(name):
        def cb(msg: Float32) -> None:
            with lock:
                tracks[name].add_battery(rospy.get_time(), msg.data)
        return cb

    def on_cmd_vel(name):
        def cb(msg: Twist) -> None:
            with lock:
                tracks[name].add_thrust(rospy.get_time(), msg.linear.z)
        return cb

    def on_waypoint(name):
        def cb(msg: Int32) -> None:
            now = rospy.get_time()
            with lock:
                tr = tracks[name]
                for k in range(len(tr.reached_times), msg.data):   # flying to k: 0..k-1 reached
                    tr.reach_waypoint(now, k)
                    rospy.loginfo("[%s] waypoint %d/%d reached", name, k + 1, tr.waypoint_count)
                rospy.loginfo("[%s] flying to waypoint %d/%d", name, msg.data + 1, tr.waypoint_count)
        return cb

    def on_finished(name):
        def cb(msg: Bool) -> None:
            if msg.data:
                with lock:
                    tr = tracks[name]
                    if tr.finished_time is None:
                        tr.finished_time = rospy.get_time()
                        for k in range(len(tr.reached_times), tr.waypoint_count):
                            tr.reach_waypoint(tr.finished_time, k)
                        rospy.loginfo("[%s] all %d waypoints reached, landing", name, tr.waypoint_count)
        return cb

    for n in names:
        rospy.Subscriber(f"/{n}/goal", PoseStamped, on_goal(n), queue_size=10)
        rospy.Subscriber(f"/{n}/battery", Float32, on_battery(n), queue_size=10)
        rospy.Subscriber(f"/{n}/cmd_vel", Twist, on_cmd_vel(n), queue_size=10)
        rospy.Subscriber(f"/{n}/demo/waypoint", Int32, on_waypoint(n), queue_size=10)
        rospy.Subscriber(f"/{n}/demo/finished", Bool, on_finished(n), queue_size=10)

    buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(buffer)
    start = rospy.get_time()
    pace = RealTimeFactor()
    waypoints: Dict[str, list] = {}
    r = rospy.Rate(rate)
    last_print = start
    while not rospy.is_shutdown():
        now = rospy.get_time()
        for n, f in zip(names, frames):
            if n not in waypoints and rospy.has_param(f"/{n}/demo/waypoints"):
                waypoints[n] = rospy.get_param(f"/{n}/demo/waypoints")
                tracks[n].waypoint_count = len(waypoints[n])
            try:
                t = buffer.lookup_transform(world, f.lstrip("/"), rospy.Time(0))
            except (tf2_ros.LookupException, tf2_ros.ConnectivityException,
                    tf2_ros.ExtrapolationException):
                continue
            p = t.transform.translation
            with lock:
                tr = tracks[n]
                tr.add_pose(now, (p.x, p.y, p.z))
                if tr.finished_time is not None and tr.landed_time is None and p.z < 0.08 \
                        and now - tr.finished_time > 1.0:
                    tr.landed_time = now
                    rospy.loginfo("[%s] landed", n)
        if now - last_print > 5.0:
            last_print = now
            with lock:
                parts = [f"{n}: wp {tr.waypoints_reached}/{tr.waypoint_count} z={tr.positions[-1][2]:.2f}"
                         for n, tr in tracks.items() if tr.positions]
            rospy.loginfo("t=%.0f s  %s", now - start, "  ".join(parts))
        with lock:
            # after the last landing, a second more of battery readings at rest
            done = all(tr.landed_time is not None and tr.motors_off_time is not None
                       and now - max(tr.landed_time, tr.motors_off_time) > rest_after_landing
                       for tr in tracks.values())
        if done or now - start > timeout:
            if not done:
                rospy.logwarn("mission timed out after %.0f s", timeout)
            break
        try:
            r.sleep()
        except rospy.ROSInterruptException:
            break

    with lock:
        lines = summary_lines(list(tracks.values()))
        ok = all(tr.waypoints_reached == tr.waypoint_count and tr.waypoint_count > 0
                 for tr in tracks.values())
        path = plot_tracks(list(tracks.values()), waypoints, plot_path)
    print("\n=== mission summary ===", flush=True)
    for line in lines:
        print(line, flush=True)
    print(pace.line(), flush=True)
    print(f"result: {'every waypoint reached' if ok else 'NOT every waypoint reached'}", flush=True)
    print(f"plot: {os.path.abspath(path)}", flush=True)
    rospy.set_param("~result", "ok" if ok else "incomplete")
    result_file = rospy.get_param("~result_file", "")
    if result_file:   # roslaunch's exit code does not tell: scripts read this
        try:
            with open(os.path.expanduser(result_file), "w") as f:
                f.write("ok\n" if ok else "incomplete\n")
        except OSError as exc:
            rospy.logerr("cannot write the result to %s: %s", result_file, exc)
    rospy.signal_shutdown("mission over")
