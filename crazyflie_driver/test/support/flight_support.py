"""Helpers for the flight rostests: the simulated world's true state, waits, hold-error figures.

Flight tests judge the vehicles by the world's ground truth (``vehicle_state`` over the world
server's control API), not by what the stack under test believes, so a wrong pose or frame in
the stack cannot hide a bad flight. Flight times (settling, holding, "within N s") are measured
on the world's clock: on a busy machine the world may fall behind real time, and N wall seconds
are then fewer seconds of flight.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable, Dict, List, Sequence, Tuple

import rospy

from crazyflie_driver.clock import wait_for

Vec3 = Tuple[float, float, float]


def wait_until(cond: Callable[[], Any], timeout: float, period: float = 0.05) -> Any:
    """cond()'s first truthy value, or its last value after ``timeout`` seconds of ROS time (world time
    under /use_sim_time: a slowed-down world is waited for, not judged; ``clock.wait_for``)."""
    return wait_for(cond, timeout, ros_time, period, rospy.is_shutdown)


def ros_time() -> float:
    """ROS time [s] once this process is a node, the wall clock before."""
    return rospy.get_time() if rospy.rostime.is_rostime_initialized() else time.monotonic()


def inbound_connected(node: str, topic: str, caller: str = "/flight_support") -> bool:
    """Whether ``node`` holds a live subscription connection on ``topic`` (by its getBusInfo).

    A node publishing once (the joy node's initial stick state) loses that message to a
    subscriber whose connection is still being set up; tests wait for this before triggering it.
    """
    from xmlrpc.client import ServerProxy

    import rosgraph
    try:
        uri = rosgraph.Master(caller).lookupNode(node)
        code, _, connections = ServerProxy(uri).getBusInfo(caller)
    except Exception:                # node not registered yet, or its XML-RPC server starting
        return False
    return code == 1 and any(c[2] == "i" and c[4] == topic and c[5] for c in connections)


def distance(a: Sequence[float], b: Sequence[float]) -> float:
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(a, b)))


def hold_errors(positions: Sequence[Sequence[float]], target: Sequence[float]) -> Tuple[float, float]:
    """(RMS, max) of the 3-D distance between each position and the target, in metres."""
    if not positions:
        raise ValueError("no positions to measure the hold error from")
    d = [distance(p, target) for p in positions]
    return math.sqrt(sum(e * e for e in d) / len(d)), max(d)


class WorldProbe:
    """Reads the simulated vehicles' true state from the world server (``sim_address`` host:port)."""

    def __init__(self, address: str) -> None:
        from crazyflie_driver.sim.air.medium import RemoteMedium
        from crazyflie_driver.sim.world_clock import WorldClock

        self.medium = RemoteMedium(address)
        self.clock = WorldClock(self.medium.ping)

    def sleep(self, world_s: float) -> None:
        """Until ``world_s`` seconds of world time have passed."""
        self.clock.sleep(world_s)

    def wait_ready(self, names: Sequence[str], timeout: float = 30.0) -> None:
        """Until the world server answers for every vehicle (it starts with the launch file)."""
        last: Exception = TimeoutError("no answer")
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                for n in names:
                    self.state(n)
                return
            except Exception as e:   # WorldNotRunning, or the vehicle not added yet
                last = e
                time.sleep(0.2)
        raise AssertionError("simulated world not ready after %.0f s: %s" % (timeout, last))

    def state(self, name: str) -> Dict[str, Any]:
        """position, velocity, quaternion, motors, on_ground, thrust_locked, locked, vbat."""
        return self.medium.control("vehicle_state", uri=name)

    def position(self, name: str) -> Vec3:
        return tuple(self.state(name)["position"])

    def yaw(self, name: str) -> float:
        from crazyflie_driver.mocap.frames import yaw_of
        return yaw_of(self.state(name)["quaternion"])

    def firmware(self, name: str) -> Dict[str, Any]:
        """The simulated firmware's view (emergency flag, last setpoint, ...)."""
        return self.medium.crazyflie_state(name)

    def sample(self, names: Sequence[str], duration: float, period: float = 0.02) -> Dict[str, List[Vec3]]:
        """Positions of each vehicle over ``duration`` s of world time, one per ``period`` s of world time.

        Each sample is taken at a distinct world time at least ``period`` after the previous one,
        so every stretch of flight weighs the same in a figure (RMS) however the world's pace varies.
        """
        out: Dict[str, List[Vec3]] = {n: [] for n in names}
        last: Dict[str, float] = {n: -math.inf for n in names}
        start = self.clock.now()
        end = start + duration
        while True:
            for n in names:
                s = self.state(n)
                if s["time"] - last[n] >= period - 1e-9 and start <= s["time"] <= end:
                    out[n].append(tuple(s["position"]))
                    last[n] = s["time"]
            if min(last.values()) >= end - period or self.clock.now() >= end:
                return out
            time.sleep(period / 2)

    def wait_near(self, name: str, target: Sequence[float], tolerance: float, timeout: float) -> bool:
        """Whether the vehicle comes within ``tolerance`` m of ``target`` within ``timeout`` s of world time."""
        return bool(self.clock.wait_until(lambda: distance(self.position(name), target) < tolerance, timeout)[0])


class Track:
    """Samples vehicles' true positions in a background thread (world time-stamped by monotonic)."""

    # A sample is stamped with the middle of its question and answer, so it is only as precise as
    # that round trip; on a busy machine the test's thread may read an answer long after the world
    # gave it. Interpolation uses the samples answered within this many seconds when they exist.
    PRECISE_S = 0.01
    # Interpolation spans at most this many sampling periods.
    MAX_GAP_PERIODS = 3

    def __init__(self, probe: WorldProbe, names: Sequence[str], period: float = 0.05) -> None:
        self.probe, self.names, self.period = probe, list(names), period
        self.samples: Dict[str, List[Tuple[float, Dict[str, Any], float]]] = {n: [] for n in names}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="track", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            for n in self.names:
                asked = time.monotonic()
                try:
                    s = self.probe.state(n)
                except Exception:   # the world going away at shutdown
                    return
                answered = time.monotonic()
                # the world answered somewhere between the question and the answer: stamp the middle
                with self._lock:
                    self.samples[n].append(((asked + answered) / 2.0, s, answered - asked))
            self._stop.wait(self.period)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def at(self, name: str, t: float) -> Dict[str, Any]:
        """The sample of ``name`` closest to monotonic time ``t``."""
        with self._lock:
            rows = list(self.samples[name])
        if not rows:
            raise ValueError("no samples of %s yet" % name)
        return min(rows, key=lambda r: abs(r[0] - t))[1]

    def position_at(self, name: str, t: float) -> Vec3:
        """The true position of ``name`` at monotonic time ``t``, interpolated between the samples around it.

        A vehicle moving at 0.5 m/s covers 25 mm in half a sampling period: the closest sample
        alone is too coarse to judge a 0.3 m tolerance while it flies through a waypoint. A sample
        whose answer took 0.1 s could be 50 ms off in time, so precise samples are preferred, but
        only around ``t``: on a busy machine the precise ones may lie a second apart, and a straight
        line across a second of a decelerating flight trails the vehicle by centimetres.
        """
        with self._lock:
            rows = list(self.samples[name])
        for usable in ([r for r in rows if r[2] <= self.PRECISE_S], rows):
            before = [r for r in usable if r[0] <= t]
            after = [r for r in usable if r[0] > t]
            if before and after and after[0][0] - before[-1][0] <= self.MAX_GAP_PERIODS * self.period:
                (t0, s0, _), (t1, s1, _) = before[-1], after[0]
                f = (t - t0) / (t1 - t0)
                return tuple(a + f * (b - a) for a, b in zip(s0["position"], s1["position"]))
        return tuple(self.at(name, t)["position"])

    def position_at_world_time(self, name: str, world_t: float) -> Vec3:
        """The true position of ``name`` at world time ``world_t`` (a ROS stamp under /use_sim_time),
        interpolated between the samples the world stamped just before and after it."""
        with self._lock:
            rows = sorted((r[1] for r in self.samples[name]), key=lambda s: s["time"])
        before = [s for s in rows if s["time"] <= world_t]
        after = [s for s in rows if s["time"] > world_t]
        if before and after and after[0]["time"] - before[-1]["time"] <= self.MAX_GAP_PERIODS * self.period:
            s0, s1 = before[-1], after[0]
            f = (world_t - s0["time"]) / (s1["time"] - s0["time"])
            return tuple(a + f * (b - a) for a, b in zip(s0["position"], s1["position"]))
        if not rows:
            raise ValueError("no samples of %s yet" % name)
        return tuple(min(rows, key=lambda s: abs(s["time"] - world_t))["position"])

    def world_gap(self, name: str, world_t: float) -> float:
        """World seconds between the samples around ``world_t`` (inf where one side has none): what a
        judgement by ``position_at_world_time`` was good to."""
        with self._lock:
            times = [r[1]["time"] for r in self.samples[name]]
        before = [t for t in times if t <= world_t]
        after = [t for t in times if t > world_t]
        return min(after) - max(before) if before and after else float("inf")

    def between(self, name: str, t0: float, t1: float) -> List[Dict[str, Any]]:
        with self._lock:
            return [s for t, s, _ in self.samples[name] if t0 <= t <= t1]
