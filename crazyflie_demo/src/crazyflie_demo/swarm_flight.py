"""The swarm demo's flight: its phases, each Crazyflie's planned path, and the tracking error against it.

ROS-free. The demo node announces each phase (``Phase``) just before it sends the command; the
monitor anchors the phase at the world time it hears of it, then, once the command had time to
arrive, at the world time each Crazyflie's high-level commander began it (``set_start``: the
moment the broadcast or unicast reached that Crazyflie; the delivery itself is not tracking
error). It rebuilds every Crazyflie's plan as the firmware's high-level commander flies it:
takeoff, go_to and land are the planner's degree-7 rest-to-rest polynomials (zero velocity,
acceleration and jerk at both ends) from where the previous phase ended, and the figure-8 is the
uploaded trajectory relative to its start. The error is the distance from the world's true
position to that plan.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

from crazyflie_demo.figure8 import figure8_pieces, hermite7, position_at, trajectory_duration

Vec3 = Tuple[float, float, float]

TAKEOFF_HEIGHT_M = 1.0
TAKEOFF_S = 2.5
FORMATION_S = 3.0
LAND_S = 3.0
SETTLE_S = 1.0                 # hover after each phase before the next command
TRAJECTORY_ID = 1
#: The formation: a stepped pyramid over the grid, the centre this much higher per ring inwards.
PYRAMID_STEP_M = 0.15
PHASES = ("takeoff", "figure8", "formation", "land")


@dataclass(frozen=True)
class Phase:
    """One command of the flight as the demo announces it (JSON on the wire)."""

    name: str                                   # takeoff | figure8 | formation | land | done
    duration: float = 0.0
    height: float = 0.0                         # takeoff, land
    goals: Dict[str, Vec3] = field(default_factory=dict)     # formation: absolute goal per Crazyflie

    def to_json(self) -> str:
        return json.dumps({"phase": self.name, "duration": self.duration, "height": self.height,
                           "goals": {k: list(v) for k, v in self.goals.items()}})

    @staticmethod
    def from_json(text: str) -> Phase:
        d = json.loads(text)
        return Phase(str(d["phase"]), float(d.get("duration", 0.0)), float(d.get("height", 0.0)),
                     {k: tuple(float(c) for c in v) for k, v in (d.get("goals") or {}).items()})


def pyramid_goals(positions: Dict[str, Vec3], height: float = TAKEOFF_HEIGHT_M,
                  step: float = PYRAMID_STEP_M) -> Dict[str, Vec3]:
    """Each Crazyflie over its own start, the inner rings of the grid higher: a formation change that
    never crosses paths. Rings count outwards from the grid's centre in units of the grid spacing."""
    if not positions:
        return {}
    xs = [p[0] for p in positions.values()]
    ys = [p[1] for p in positions.values()]
    cx, cy = (min(xs) + max(xs)) / 2.0, (min(ys) + max(ys)) / 2.0
    gaps = sorted({round(abs(a - b), 3) for a in xs + ys for b in xs + ys if abs(a - b) > 1e-3})
    spacing = gaps[0] if gaps else 1.0
    rings = {n: int(math.floor(max(abs(p[0] - cx), abs(p[1] - cy)) / spacing + 1e-6)) for n, p in positions.items()}
    top = max(rings.values())
    return {n: (p[0], p[1], height + step * (top - rings[n])) for n, p in positions.items()}


def _rest_to_rest(a: Vec3, b: Vec3, duration: float, t: float) -> Vec3:
    """The planner's path from rest at a to rest at b over duration, at t (held outside)."""
    if duration <= 0 or t >= duration:
        return b
    if t <= 0:
        return a
    out = []
    for k in range(3):
        c = hermite7(duration, (a[k], 0.0, 0.0, 0.0), (b[k], 0.0, 0.0, 0.0))
        out.append(sum(ci * t ** i for i, ci in enumerate(c)))
    return tuple(out)


@dataclass
class _Segment:
    kind: str
    start_time: float
    duration: float
    start: Vec3
    end: Vec3


class Plan:
    """One Crazyflie's planned path, built phase by phase; ``at(t)`` in world time."""

    def __init__(self, initial: Vec3, figure8=None) -> None:
        self.initial = tuple(float(v) for v in initial)
        self.figure8 = figure8 if figure8 is not None else figure8_pieces()
        self.segments: List[_Segment] = []

    @property
    def end(self) -> Vec3:
        return self.segments[-1].end if self.segments else self.initial

    def set_start(self, phase_index: int, start_time: float) -> None:
        """When the Crazyflie's commander began the ``phase_index``-th segment (world time)."""
        if 0 <= phase_index < len(self.segments):
            self.segments[phase_index].start_time = float(start_time)

    def add(self, phase: Phase, anchor: float, name: str) -> None:
        start = self.end
        if phase.name == "takeoff":
            end = (start[0], start[1], phase.height)
        elif phase.name == "land":
            end = (start[0], start[1], phase.height)
        elif phase.name == "formation":
            end = phase.goals.get(name, start)
        elif phase.name == "figure8":
            rel = position_at(self.figure8, trajectory_duration(self.figure8))
            end = (start[0] + rel[0], start[1] + rel[1], start[2] + rel[2])
        else:
            return
        self.segments.append(_Segment(phase.name, anchor, phase.duration, start, end))

    def at(self, t: float) -> Vec3:
        current: Optional[_Segment] = None
        for s in self.segments:
            if t >= s.start_time:
                current = s
        if current is None:
            return self.initial
        dt = t - current.start_time
        if current.kind == "figure8":
            rel = position_at(self.figure8, dt)
            return (current.start[0] + rel[0], current.start[1] + rel[1], current.start[2] + rel[2])
        return _rest_to_rest(current.start, current.end, current.duration, dt)


@dataclass
class Track:
    """The world's truth for one Crazyflie and its plan; errors against the plan as it stands."""

    name: str
    plan: Plan
    times: List[float] = field(default_factory=list)
    positions: List[Vec3] = field(default_factory=list)

    def add(self, t: float, p: Sequence[float]) -> None:
        self.times.append(t)
        self.positions.append(tuple(float(v) for v in p))

    @property
    def errors(self) -> List[float]:
        at = self.plan.at
        return [math.dist(p, at(t)) for t, p in zip(self.times, self.positions)]


class Flight:
    """Tracks of every Crazyflie and the phases' world-time windows."""

    def __init__(self, initial: Dict[str, Vec3]) -> None:
        fig = figure8_pieces()
        self.tracks = {n: Track(n, Plan(p, fig)) for n, p in initial.items()}
        self.windows: List[Tuple[str, float, float]] = []      # (phase, start, end incl. settle)

    def phase(self, phase: Phase, anchor: float) -> int:
        """Adds the phase to every plan, anchored at ``anchor``; returns its index (for ``set_start``)."""
        index = len(self.windows)
        for name, track in self.tracks.items():
            track.plan.add(phase, anchor, name)
        if self.windows:
            name, start, _ = self.windows[-1]
            self.windows[-1] = (name, start, anchor)
        if phase.name in PHASES:
            self.windows.append((phase.name, anchor, anchor + phase.duration + SETTLE_S))
        return index

    def set_start(self, index: int, name: str, start_time: float) -> None:
        track = self.tracks.get(name)
        if track is not None:
            track.plan.set_start(index, start_time)

    def sample(self, t: float, positions: Dict[str, Sequence[float]]) -> None:
        for name, p in positions.items():
            track = self.tracks.get(name)
            if track is not None:
                track.add(t, p)

    def errors_in(self, phase: str) -> Dict[str, List[float]]:
        """Each Crazyflie's errors inside the (first) window of ``phase``."""
        window = next((w for w in self.windows if w[0] == phase), None)
        if window is None:
            return {}
        _, a, b = window
        out = {}
        for n, tr in self.tracks.items():
            at = tr.plan.at
            out[n] = [math.dist(p, at(t)) for t, p in zip(tr.times, tr.positions) if a <= t <= b]
        return out

    def means(self, phase: str) -> Dict[str, float]:
        """Each Crazyflie's mean error over the phase (m)."""
        return {n: sum(e) / len(e) for n, e in self.errors_in(phase).items() if e}

    def stats(self) -> Dict[str, object]:
        """Everything the summary says, as plain data (for benchmarks)."""
        return {"phases": {name: self.phase_stats(name) for name, _, _ in self.windows},
                "means": {name: self.means(name) for name, _, _ in self.windows},
                "windows": [list(w) for w in self.windows]}

    def phase_stats(self, phase: str) -> Optional[Dict[str, float]]:
        """Mean error per Crazyflie over the phase: the swarm's mean, worst mean, and the largest error."""
        per = {n: e for n, e in self.errors_in(phase).items() if e}
        if not per:
            return None
        means = {n: sum(e) / len(e) for n, e in per.items()}
        worst = max(means, key=means.get)
        return {"crazyflies": len(per), "mean": sum(means.values()) / len(means), "worst_mean": means[worst],
                "worst": worst, "max": max(max(e) for e in per.values())}

    def summary_lines(self) -> List[str]:
        out = []
        for name, a, b in self.windows:
            st = self.phase_stats(name)
            if st is None:
                out.append("%-9s no samples" % name)
                continue
            out.append("%-9s %5.1f s  %d Crazyflies  tracking error mean %.1f cm (worst Crazyflie %s %.1f cm), "
                       "max %.1f cm" % (name, b - a, st["crazyflies"], 100 * st["mean"], st["worst"],
                                        100 * st["worst_mean"], 100 * st["max"]))
        return out


def plot_flight(flight: Flight, path: str, title: str = "") -> str:
    """Paths seen from above and the tracking error per Crazyflie over time, as a PNG (matplotlib, Agg)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, err) = plt.subplots(1, 2, figsize=(15, 6.5), gridspec_kw={"width_ratios": [1, 1.4]})
    t0 = flight.windows[0][1] if flight.windows else 0.0
    for tr in flight.tracks.values():
        if not tr.positions:
            continue
        top.plot([p[0] for p in tr.positions], [p[1] for p in tr.positions], lw=0.6)
        top.plot(tr.plan.initial[0], tr.plan.initial[1], "k.", ms=3)
        err.plot([t - t0 for t in tr.times], [100 * e for e in tr.errors], lw=0.5)
    top.set_aspect("equal")
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m]")
    top.set_title("paths seen from above (world truth; dots: start)")
    colours = {"takeoff": "#dde8f7", "figure8": "#f7eadd", "formation": "#e2f2df", "land": "#eeeeee"}
    for name, a, b in flight.windows:
        err.axvspan(a - t0, b - t0, color=colours.get(name, "#f4f4f4"), zorder=0)
        err.text((a + b) / 2 - t0, 0.98, name, transform=err.get_xaxis_transform(), ha="center", va="top",
                 fontsize=8)
    err.set_xlabel("time since takeoff [s] (world time)")
    err.set_ylabel("distance truth - plan [cm]")
    err.set_title("tracking error per Crazyflie (%d)" % len(flight.tracks))
    err.set_ylim(bottom=0)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
