"""Bookkeeping of a waypoint mission: tracking error while holding, timing, battery, plot.

ROS-free so it can be tested directly; mission_monitor_node feeds it from tf and topics.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

Vec3 = Tuple[float, float, float]

HOLD_TOLERANCE = 0.1   # m: a vehicle this close to its waypoint is holding it


@dataclass
class VehicleTrack:
    """Everything recorded about one vehicle during the mission."""

    name: str
    waypoint_count: int = 0
    times: List[float] = field(default_factory=list)
    positions: List[Vec3] = field(default_factory=list)
    goals: List[Vec3] = field(default_factory=list)
    goal_changes: List[Tuple[float, Vec3]] = field(default_factory=list)
    hold_errors: List[float] = field(default_factory=list)
    battery: List[Tuple[float, float]] = field(default_factory=list)
    takeoff_time: Optional[float] = None
    finished_time: Optional[float] = None
    landed_time: Optional[float] = None
    waypoints_reached: int = 0
    reached_times: List[float] = field(default_factory=list)   # when each waypoint counted as reached
    motors_on_time: Optional[float] = None    # first thrust command above zero
    motors_off_time: Optional[float] = None   # thrust back to zero after flying
    _holding: bool = False

    def add_goal(self, t: float, goal: Vec3) -> None:
        if not self.goal_changes or _dist(self.goal_changes[-1][1], goal) > 1e-6:
            self.goal_changes.append((t, goal))
            self._holding = False

    def add_pose(self, t: float, p: Vec3, tolerance: float = HOLD_TOLERANCE,
                 takeoff_height: float = 0.05) -> None:
        """A position sample. The vehicle holds a waypoint from the moment it first comes within
        ``tolerance`` (3-D distance) of it until the goal moves on; its hold error is the distance
        to the goal over that time (excursions after arriving count too)."""
        self.times.append(t)
        self.positions.append(p)
        goal = self.goal_changes[-1][1] if self.goal_changes else None
        self.goals.append(goal if goal is not None else (math.nan,) * 3)
        if self.takeoff_time is None and p[2] > takeoff_height:
            self.takeoff_time = t
        if goal is None:
            return
        if _dist(p, goal) < tolerance:
            self._holding = True
        if self._holding and self.finished_time is None:
            self.hold_errors.append(_dist(p, goal))

    def add_battery(self, t: float, volts: float) -> None:
        self.battery.append((t, volts))

    def rms_hold_error(self) -> float:
        if not self.hold_errors:
            return math.nan
        return math.sqrt(sum(e * e for e in self.hold_errors) / len(self.hold_errors))

    def reach_waypoint(self, t: float, index: int) -> None:
        """Waypoint ``index`` (0-based) counted as reached at ``t``; repeats are ignored."""
        if index == len(self.reached_times):
            self.reached_times.append(t)
            self.waypoints_reached = len(self.reached_times)

    def add_thrust(self, t: float, thrust: float) -> None:
        """The thrust commanded (cmd_vel linear.z): tells when the motors run."""
        if thrust > 0.0:
            if self.motors_on_time is None:
                self.motors_on_time = t
            self.motors_off_time = None
        elif self.motors_on_time is not None and self.motors_off_time is None:
            self.motors_off_time = t

    def battery_used(self, settle: float = 0.3, samples: int = 5) -> float:
        """Drop of the resting voltage, from before the motors start to after they stop (volts).

        Readings under load sag by the battery's internal resistance, so only readings taken with
        the motors off count: the last ``samples`` before the first thrust command and the first
        ``samples`` taken ``settle`` s or more after the thrust went back to zero. NaN until both
        exist."""
        if self.motors_on_time is None or self.motors_off_time is None:
            return math.nan
        before = [v for t, v in self.battery if t < self.motors_on_time][-samples:]
        after = [v for t, v in self.battery if t > self.motors_off_time + settle][:samples]
        if not before or not after:
            return math.nan
        return sum(before) / len(before) - sum(after) / len(after)

    def flight_time(self) -> float:
        if self.takeoff_time is None:
            return math.nan
        end = self.landed_time or self.finished_time or (self.times[-1] if self.times else None)
        return (end - self.takeoff_time) if end is not None else math.nan


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(a, b)))


def summary_lines(tracks: Sequence[VehicleTrack]) -> List[str]:
    """The summary table, then per vehicle when each waypoint was reached (s after take-off)."""
    lines = [f"{'vehicle':<12} {'waypoints':>9} {'flight s':>9} {'hold RMS m':>11} {'battery V':>10}"]
    for tr in tracks:
        lines.append(f"{tr.name:<12} {tr.waypoints_reached:>4}/{tr.waypoint_count:<4} "
                     f"{tr.flight_time():>9.1f} {tr.rms_hold_error():>11.3f} {tr.battery_used():>10.3f}")
    for tr in tracks:
        if tr.reached_times and tr.takeoff_time is not None:
            times = "  ".join(f"{k + 1}:{t - tr.takeoff_time:.1f}" for k, t in enumerate(tr.reached_times))
            lines.append(f"{tr.name}: waypoint reached at (s after take-off) {times}")
    lines.append(f"hold RMS: distance to the waypoint from first coming within {HOLD_TOLERANCE:.2f} m of it "
                 "until the next; battery: resting voltage before the motors start minus after they stop")
    return lines


def plot_tracks(tracks: Sequence[VehicleTrack], waypoints: Dict[str, Sequence[Sequence[float]]],
                path: str) -> str:
    """Top view and height over time of the flown paths against the waypoints; returns path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, height) = plt.subplots(1, 2, figsize=(12, 5.5))
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"]
    for i, tr in enumerate(tracks):
        c = colours[i % len(colours)]
        if tr.positions:
            xs, ys, zs = zip(*tr.positions)
            top.plot(xs, ys, color=c, lw=1.2, label=f"{tr.name} flown")
            t0 = tr.times[0]
            height.plot([t - t0 for t in tr.times], zs, color=c, lw=1.2, label=f"{tr.name} z")
            gz = [g[2] for g in tr.goals]
            height.plot([t - t0 for t in tr.times], gz, color=c, lw=0.8, ls="--",
                        label=f"{tr.name} goal z")
        wps = waypoints.get(tr.name, [])
        if wps:
            wx, wy = [w[0] for w in wps], [w[1] for w in wps]
            top.plot(wx, wy, color=c, ls=":", marker="o", ms=7, mfc="none", label=f"{tr.name} waypoints")
            for k, (x, y) in enumerate(zip(wx, wy)):
                top.annotate(str(k + 1), (x, y), textcoords="offset points", xytext=(5, 5), color=c)
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m]")
    top.set_title("flown paths (top view)")
    top.axis("equal")
    top.grid(True, alpha=0.3)
    top.legend(fontsize=8)
    height.set_xlabel("time [s]")
    height.set_ylabel("z [m]")
    height.set_title("height")
    height.grid(True, alpha=0.3)
    height.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
