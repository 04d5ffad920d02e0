"""The mission monitor's decisions, ROS-free: its settings, what each report of a vehicle means
(waypoint reached, finished, landed), when the watch ends and what the result says.

``mission_monitor_node`` feeds it from topics, tf and the parameter server and logs the lines it
returns; the per-vehicle bookkeeping (hold error, battery, flight time) is ``mission_summary``'s.
"""
from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from crazyflie_demo.mission_summary import Vec3, VehicleTrack, plot_tracks, summary_lines

LANDED_HEIGHT_M = 0.08          # a finished vehicle below this height has landed...
LANDING_SETTLE_S = 1.0          # ...once this long after its demo finished (it starts its descent then)
PROGRESS_PERIOD_S = 5.0         # one progress line per this much (ROS) time


@dataclass(frozen=True)
class MonitorConfig:
    """The node's private parameters (``~name``), checked."""

    names: Tuple[str, ...]
    frames: Tuple[str, ...]          # each vehicle's tf frame, in the order of ``names``
    world: str                       # the frame poses are read in
    timeout_s: float                 # the watch ends after this long even if a vehicle has not landed
    plot_path: str
    rate_hz: float                   # tf sampling rate
    rest_after_landing_s: float      # battery readings at rest after landing, for the battery figure
    result_file: str                 # "" for none

    @classmethod
    def from_params(cls, get_param: Callable[[str, Any], Any]) -> MonitorConfig:
        """From ``get_param(name, default)`` (rospy.get_param's signature); ValueError says what to fix."""
        names = tuple(str(n) for n in get_param("~vehicles", ["crazyflie1", "crazyflie2"]))
        frames = tuple(str(f) for f in get_param("~frames", [f"vicon/{n}/{n}" for n in names]))
        config = cls(names=names, frames=frames, world=str(get_param("~worldFrame", "world")).strip("/"),
                     timeout_s=_number(get_param, "~timeout", 180.0),
                     plot_path=os.path.expanduser(str(get_param("~plot", "crazyflie_mission.png"))),
                     rate_hz=_number(get_param, "~rate", 50.0),
                     rest_after_landing_s=_number(get_param, "~rest_after_landing", 1.0),
                     result_file=os.path.expanduser(str(get_param("~result_file", ""))))
        config.check()
        return config

    def check(self) -> None:
        if not self.names:
            raise ValueError("~vehicles is empty: name at least one vehicle to watch")
        if len(self.frames) != len(self.names):
            raise ValueError("~frames has %d frames for %d ~vehicles: give one tf frame per vehicle, in order"
                             % (len(self.frames), len(self.names)))
        for key, value in (("~timeout", self.timeout_s), ("~rate", self.rate_hz)):
            if not value > 0:
                raise ValueError("%s must be > 0 seconds or Hz, got %r" % (key, value))
        if not self.rest_after_landing_s >= 0:
            raise ValueError("~rest_after_landing must be >= 0 seconds, got %r" % self.rest_after_landing_s)


def _number(get_param: Callable[[str, Any], Any], key: str, default: float) -> float:
    value = get_param(key, default)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError("%s must be a number, got %r" % (key, value)) from None


class Mission:
    """Every vehicle's track and waypoints. Thread-safe: ROS calls back on its own threads.

    The ``on_*`` methods take the report's time [s] and return the lines worth logging."""

    def __init__(self, names: Sequence[str]) -> None:
        self._lock = threading.Lock()
        self.tracks: Dict[str, VehicleTrack] = {n: VehicleTrack(n) for n in names}
        self.waypoints: Dict[str, Sequence[Sequence[float]]] = {}

    def wants_waypoints(self, name: str) -> bool:
        with self._lock:
            return name not in self.waypoints

    def set_waypoints(self, name: str, waypoints: Sequence[Sequence[float]]) -> None:
        with self._lock:
            self.waypoints[name] = list(waypoints)
            self.tracks[name].waypoint_count = len(waypoints)

    def on_goal(self, name: str, t: float, goal: Vec3) -> None:
        with self._lock:
            self.tracks[name].add_goal(t, goal)

    def on_battery(self, name: str, t: float, volts: float) -> None:
        with self._lock:
            self.tracks[name].add_battery(t, volts)

    def on_thrust(self, name: str, t: float, thrust: float) -> None:
        with self._lock:
            self.tracks[name].add_thrust(t, thrust)

    def on_waypoint(self, name: str, t: float, flying_to: int) -> List[str]:
        """The demo flies to waypoint ``flying_to`` (0-based): every one before it is reached."""
        with self._lock:
            tr = self.tracks[name]
            lines = []
            for k in range(len(tr.reached_times), flying_to):
                tr.reach_waypoint(t, k)
                lines.append("[%s] waypoint %d/%d reached" % (name, k + 1, tr.waypoint_count))
            lines.append("[%s] flying to waypoint %d/%d" % (name, flying_to + 1, tr.waypoint_count))
            return lines

    def on_finished(self, name: str, t: float, finished: bool) -> List[str]:
        """The demo says it has flown its last waypoint (and lands now): every waypoint is reached."""
        with self._lock:
            tr = self.tracks[name]
            if not finished or tr.finished_time is not None:
                return []
            tr.finished_time = t
            for k in range(len(tr.reached_times), tr.waypoint_count):
                tr.reach_waypoint(t, k)
            return ["[%s] all %d waypoints reached, landing" % (name, tr.waypoint_count)]

    def on_pose(self, name: str, t: float, position: Vec3) -> List[str]:
        """A position sample; a finished vehicle low enough, long enough after finishing, has landed."""
        with self._lock:
            tr = self.tracks[name]
            tr.add_pose(t, position)
            if (tr.finished_time is not None and tr.landed_time is None and position[2] < LANDED_HEIGHT_M
                    and t - tr.finished_time > LANDING_SETTLE_S):
                tr.landed_time = t
                return ["[%s] landed" % name]
            return []

    def progress(self) -> str:
        with self._lock:
            return "  ".join(f"{n}: wp {tr.waypoints_reached}/{tr.waypoint_count} z={tr.positions[-1][2]:.2f}"
                             for n, tr in self.tracks.items() if tr.positions)

    def all_landed(self, now: float, rest_after_landing_s: float) -> bool:
        """Every vehicle landed with its motors off, then ``rest_after_landing_s`` more of battery
        readings at rest."""
        with self._lock:
            return all(tr.landed_time is not None and tr.motors_off_time is not None
                       and now - max(tr.landed_time, tr.motors_off_time) > rest_after_landing_s
                       for tr in self.tracks.values())

    def complete(self) -> bool:
        """Every vehicle reached every one of its waypoints (and had some)."""
        with self._lock:
            return all(tr.waypoints_reached == tr.waypoint_count and tr.waypoint_count > 0
                       for tr in self.tracks.values())

    def report(self, plot_path: str) -> Tuple[List[str], str]:
        """The summary's lines, and the path of the plot it writes."""
        with self._lock:
            tracks = list(self.tracks.values())
            return summary_lines(tracks), plot_tracks(tracks, self.waypoints, plot_path)


class Watch:
    """When the watch prints progress and when it ends, on the (ROS) clock it is given."""

    def __init__(self, start: float, timeout_s: float, progress_period_s: float = PROGRESS_PERIOD_S) -> None:
        self.start, self.timeout_s, self.progress_period_s = start, timeout_s, progress_period_s
        self._last_progress = start

    def progress_due(self, now: float) -> bool:
        """True once per ``progress_period_s``."""
        if now - self._last_progress > self.progress_period_s:
            self._last_progress = now
            return True
        return False

    def verdict(self, now: float, all_landed: bool) -> Optional[str]:
        """None while the watch goes on; "landed" when every vehicle landed, "timeout" after the timeout."""
        if all_landed:
            return "landed"
        return "timeout" if now - self.start > self.timeout_s else None


def result_word(complete: bool) -> str:
    """The ``~result`` parameter and the result file's line: roslaunch's exit code does not tell."""
    return "ok" if complete else "incomplete"


def result_line(complete: bool) -> str:
    return "result: %s" % ("every waypoint reached" if complete else "NOT every waypoint reached")
