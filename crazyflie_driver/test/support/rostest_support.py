"""Helpers for the rostest nodes of crazyflie_driver: topic counters, waits, the world's control API."""
from __future__ import annotations

import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

import rospy
from rosgraph_msgs.msg import Log

from crazyflie_driver.sim.air.medium import RemoteMedium


def wait_until(cond: Callable[[], Any], timeout: float, period: float = 0.02) -> Any:
    """cond()'s first truthy value, or its last value after ``timeout`` s."""
    end = time.monotonic() + timeout
    while True:
        v = cond()
        if v or time.monotonic() >= end or rospy.is_shutdown():
            return v
        time.sleep(period)


class TopicRecorder:
    """Keeps every message of a topic with its arrival time (monotonic)."""

    def __init__(self, topic: str, msg_type) -> None:
        self.topic = topic
        self._lock = threading.Lock()
        self.messages: List[Tuple[float, Any]] = []
        self._sub = rospy.Subscriber(topic, msg_type, self._on_msg, queue_size=1000)

    def _on_msg(self, msg) -> None:
        with self._lock:
            self.messages.append((time.monotonic(), msg))

    def since(self, t0: float) -> List[Tuple[float, Any]]:
        with self._lock:
            return [m for m in self.messages if m[0] >= t0]

    def rate(self, duration: float) -> float:
        """Messages per second over the next ``duration`` seconds."""
        t0 = time.monotonic()
        time.sleep(duration)
        return len(self.since(t0)) / duration

    def latest(self) -> Optional[Any]:
        with self._lock:
            return self.messages[-1][1] if self.messages else None

    def count(self) -> int:
        with self._lock:
            return len(self.messages)


class RosoutRecorder:
    """Log lines of one node as seen on /rosout."""

    def __init__(self, node: str = "/crazyflie_server") -> None:
        self.node = node
        self._lock = threading.Lock()
        self.lines: List[Tuple[int, str]] = []
        self._sub = rospy.Subscriber("/rosout", Log, self._on_log, queue_size=1000)

    def _on_log(self, msg: Log) -> None:
        if msg.name == self.node:
            with self._lock:
                self.lines.append((msg.level, msg.msg))

    def find(self, text: str, min_level: int = Log.DEBUG) -> List[str]:
        with self._lock:
            return [m for lvl, m in self.lines if text in m and lvl >= min_level]


def rates_per_world_second(recorders: Dict[str, "TopicRecorder"], medium: RemoteMedium,
                           seconds: float, during: Optional[Callable[[], Any]] = None) -> Dict[str, float]:
    """Messages per second of simulated time, per recorder, over ``seconds`` of wall time.

    The firmware's log timers run on world time; on a busy machine the world thread may fall
    behind real time (it lets go after 0.25 s), and then a 10 ms log block yields fewer than 100
    packets per wall second however well the driver serves it. Dividing by the world time that
    passed asks the driver for exactly what the firmware produced. ``during()``, if given, is
    called repeatedly until the time is up (the load to measure under).
    """
    w0, t0 = medium.ping(), time.monotonic()
    while time.monotonic() - t0 < seconds and not rospy.is_shutdown():
        if during is not None:
            during()
        else:
            time.sleep(min(0.05, max(0.0, seconds - (time.monotonic() - t0))))
    t1, w1 = time.monotonic(), medium.ping()
    elapsed = max(w1 - w0, 1e-3)
    return {name: len([m for m in r.since(t0) if m[0] < t1]) / elapsed for name, r in recorders.items()}


def world(address: str) -> RemoteMedium:
    """The simulated world's control API (the same server the fake dongles talk to)."""
    host, _, port = address.rpartition(":")
    return RemoteMedium(host, int(port))


def wait_for_crazyflie(tf_prefix: str, timeout: float = 60.0) -> None:
    """Until crazyflie_add finished for this Crazyflie (its services exist)."""
    rospy.wait_for_service("/%s/update_params" % tf_prefix, timeout=timeout)
