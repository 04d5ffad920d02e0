"""mission_monitor: watches a simulated multi-Crazyflie waypoint mission and reports on it.

Prints progress while the vehicles fly, then a summary per vehicle (waypoints reached, flight
time, RMS error while holding at waypoints, battery used) and writes a PNG of the flown paths
against the waypoints. Exits when every vehicle has finished its waypoints and landed, or
after ~timeout; as a required node it then ends the launch. ``~result_file`` (optional) gets
"ok" or "incomplete", since roslaunch's exit code does not say how the mission went.

An adapter: topics, tf and parameters in, log lines out; what they mean is decided in
``crazyflie_demo.mission_monitor``.
"""
from __future__ import annotations

import os
from typing import List

import rospy
import tf2_ros
from geometry_msgs.msg import PoseStamped, Twist
from std_msgs.msg import Bool, Float32, Int32

from crazyflie_demo.mission_monitor import Mission, MonitorConfig, Watch, result_line, result_word
from crazyflie_demo.rosutil import RealTimeFactor
from crazyflie_driver.nodes.ros_signals import init_node


class MissionMonitor:
    """Feeds the mission from the vehicles' topics (callbacks on rospy's threads) and from tf."""

    def __init__(self, config: MonitorConfig) -> None:
        self.config = config
        self.mission = Mission(config.names)
        self.buffer = tf2_ros.Buffer()
        self._listener = tf2_ros.TransformListener(self.buffer)

    def subscribe(self) -> None:
        m = self.mission
        for n in self.config.names:
            rospy.Subscriber(f"/{n}/goal", PoseStamped, lambda msg, n=n: m.on_goal(
                n, rospy.get_time(), (msg.pose.position.x, msg.pose.position.y, msg.pose.position.z)), queue_size=10)
            rospy.Subscriber(f"/{n}/battery", Float32, lambda msg, n=n: m.on_battery(n, rospy.get_time(), msg.data),
                             queue_size=10)
            rospy.Subscriber(f"/{n}/cmd_vel", Twist, lambda msg, n=n: m.on_thrust(n, rospy.get_time(), msg.linear.z),
                             queue_size=10)
            rospy.Subscriber(f"/{n}/demo/waypoint", Int32,
                             lambda msg, n=n: _log(m.on_waypoint(n, rospy.get_time(), msg.data)), queue_size=10)
            rospy.Subscriber(f"/{n}/demo/finished", Bool,
                             lambda msg, n=n: _log(m.on_finished(n, rospy.get_time(), msg.data)), queue_size=10)

    def sample(self, now: float) -> None:
        """Each vehicle's pose from tf (and its waypoints, once its demo has set them)."""
        for n, f in zip(self.config.names, self.config.frames):
            if self.mission.wants_waypoints(n) and rospy.has_param(f"/{n}/demo/waypoints"):
                self.mission.set_waypoints(n, rospy.get_param(f"/{n}/demo/waypoints"))
            try:
                t = self.buffer.lookup_transform(self.config.world, f.lstrip("/"), rospy.Time(0))
            except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException):
                continue
            p = t.transform.translation
            _log(self.mission.on_pose(n, now, (p.x, p.y, p.z)))


def _log(lines: List[str]) -> None:
    for line in lines:
        rospy.loginfo(line)


def _watch(monitor: MissionMonitor) -> None:
    """Samples until every vehicle has landed and rested, the timeout, or shutdown."""
    config = monitor.config
    watch = Watch(rospy.get_time(), config.timeout_s)
    r = rospy.Rate(config.rate_hz)
    while not rospy.is_shutdown():
        now = rospy.get_time()
        monitor.sample(now)
        if watch.progress_due(now):
            rospy.loginfo("t=%.0f s  %s", now - watch.start, monitor.mission.progress())
        verdict = watch.verdict(now, monitor.mission.all_landed(now, config.rest_after_landing_s))
        if verdict == "timeout":
            rospy.logwarn("mission timed out after %.0f s", config.timeout_s)
        if verdict is not None:
            return
        try:
            r.sleep()
        except rospy.ROSInterruptException:
            return


def _report(monitor: MissionMonitor, pace: RealTimeFactor) -> bool:
    """Prints the summary and where the plot went; whether every vehicle reached every waypoint."""
    lines, path = monitor.mission.report(monitor.config.plot_path)
    complete = monitor.mission.complete()
    print("\n=== mission summary ===", flush=True)
    for line in lines + [pace.line(), result_line(complete), f"plot: {os.path.abspath(path)}"]:
        print(line, flush=True)
    return complete


def _write_result(complete: bool, result_file: str) -> None:
    rospy.set_param("~result", result_word(complete))
    if not result_file:
        return
    try:
        with open(result_file, "w") as f:
            f.write(result_word(complete) + "\n")
    except OSError as exc:
        rospy.logerr("cannot write the result to %s: %s", result_file, exc)


def main() -> None:
    init_node("mission_monitor")
    try:
        config = MonitorConfig.from_params(rospy.get_param)
    except ValueError as exc:
        rospy.logfatal("mission_monitor: %s", exc)
        rospy.signal_shutdown("bad parameters")
        raise SystemExit(2) from None
    monitor = MissionMonitor(config)
    monitor.subscribe()
    pace = RealTimeFactor()
    _watch(monitor)
    _write_result(_report(monitor, pace), config.result_file)
    rospy.signal_shutdown("mission over")
