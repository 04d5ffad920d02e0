"""Waypoint sequencing for demo.py: which goal to fly to now.

A waypoint is ``[x, y, z, yaw_deg, sleep_s]``. The follower moves on to the next one once the
vehicle has been within the tolerance of the current one (on every axis and in yaw) and has
stayed there for ``sleep`` seconds. Unlike a blocking sleep, the goal keeps being published
and a vehicle that drifts out of tolerance restarts the wait.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Sequence


@dataclass(frozen=True)
class Waypoint:
    x: float
    y: float
    z: float
    yaw_deg: float
    sleep: float

    @classmethod
    def from_list(cls, values: Sequence[float]) -> Waypoint:
        if len(values) != 5:
            raise ValueError(f"a waypoint is [x, y, z, yaw_deg, sleep_s], got {list(values)}")
        return cls(*(float(v) for v in values))


def angle_difference_deg(a: float, b: float) -> float:
    """Smallest signed difference a - b in degrees, in (-180, 180]."""
    d = math.fmod(a - b, 360.0)
    if d > 180.0:
        d -= 360.0
    elif d <= -180.0:
        d += 360.0
    return d


class WaypointFollower:
    """Keeps the index of the current waypoint and decides when to advance."""

    def __init__(self, waypoints: Sequence[Sequence[float]], tolerance: float = 0.3,
                 yaw_tolerance_deg: float = 10.0) -> None:
        if not waypoints:
            raise ValueError("no waypoints given")
        self.waypoints: List[Waypoint] = [Waypoint.from_list(w) for w in waypoints]
        self.tolerance = tolerance
        self.yaw_tolerance_deg = yaw_tolerance_deg
        self.index = 0
        self._reached_since: Optional[float] = None
        self.reached_times: List[float] = []

    @property
    def current(self) -> Waypoint:
        return self.waypoints[self.index]

    @property
    def finished(self) -> bool:
        """True once the last waypoint has been reached and held for its sleep time."""
        return len(self.reached_times) == len(self.waypoints)

    def within(self, position: Sequence[float], yaw_deg: float) -> bool:
        w = self.current
        return (abs(position[0] - w.x) < self.tolerance
                and abs(position[1] - w.y) < self.tolerance
                and abs(position[2] - w.z) < self.tolerance
                and abs(angle_difference_deg(yaw_deg, w.yaw_deg)) < self.yaw_tolerance_deg)

    def update(self, now: float, position: Sequence[float], yaw_deg: float) -> Waypoint:
        """Feed the latest pose; returns the waypoint to fly to."""
        if self.finished:
            return self.current
        if not self.within(position, yaw_deg):
            self._reached_since = None
            return self.current
        if self._reached_since is None:
            self._reached_since = now
        if now - self._reached_since >= self.current.sleep:
            self.reached_times.append(now)
            if self.index < len(self.waypoints) - 1:
                self.index += 1
            self._reached_since = None
        return self.current
