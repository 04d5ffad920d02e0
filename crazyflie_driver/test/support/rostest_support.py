"""Helpers for the rostest nodes of crazyflie_driver: topic counters, waits, the world's control API."""
from __future__ import annotations

import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Set, Tuple

import rosgraph
import rospy
from rosgraph_msgs.msg import Log

from crazyflie_driver.clock import wait_for
from crazyflie_driver.sim.air.medium import RemoteMedium
from crazyflie_driver.sim.world_clock import WorldClock


def wait_until(cond: Callable[[], Any], timeout: float, period: float = 0.02) -> Any:
    """cond()'s first truthy value, or its last value after ``timeout`` s of ROS time: world time under
    /use_sim_time, so a world slowed down by a busy machine is waited for, not judged (``clock.wait_for``)."""
    return wait_for(cond, timeout, ros_time, period, rospy.is_shutdown)


def ros_time() -> float:
    """ROS time [s] once this process is a node, the wall clock before."""
    return rospy.get_time() if rospy.rostime.is_rostime_initialized() else time.monotonic()


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

    def between(self, t0: float, t1: float) -> List[Any]:
        """Messages that arrived in [t0, t1) (monotonic)."""
        with self._lock:
            return [m for t, m in self.messages if t0 <= t < t1]

    def latest(self) -> Optional[Any]:
        with self._lock:
            return self.messages[-1][1] if self.messages else None

    def latest_where(self, accept: Callable[[Any], Any]) -> Optional[Any]:
        """The newest message ``accept`` takes: on a topic with several publishers (/diagnostics has
        the server's and the simulated world's), the newest message is often the other one's."""
        with self._lock:
            newest_first = [m for _, m in reversed(self.messages)]
        return next((m for m in newest_first if accept(m)), None)

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


def rates_per_world_second(recorders: Dict[str, TopicRecorder], medium: RemoteMedium,
                           seconds: float, during: Optional[Callable[[], Any]] = None) -> Dict[str, float]:
    """Messages per second of simulated time, per recorder, over ``seconds`` of world time.

    The firmware's log timers run on world time; on a busy machine the world thread may fall
    behind real time, and then a 10 ms log block yields fewer than 100 packets per wall second
    however well the driver serves it. Counting over a window of world time asks the driver for
    exactly what the firmware produced (and the window holds the same number of periods however
    slow the world is). ``during()``, if given, is called repeatedly until the time is up (the
    load to measure under).
    """
    window = world_window(medium, seconds, during)
    return {name: len(r.between(window.t0, window.t1)) / window.world_s for name, r in recorders.items()}


class Window:
    """A measurement window: wall (monotonic) bounds t0, t1 and the world seconds between them."""

    def __init__(self, t0: float, t1: float, world_s: float) -> None:
        self.t0, self.t1, self.world_s = t0, t1, world_s


def world_window(medium: RemoteMedium, seconds: float, during: Optional[Callable[[], Any]] = None) -> Window:
    """Waits ``seconds`` of world time (calling ``during()`` meanwhile, if given); the window it took."""
    clock = WorldClock(medium.ping)
    w0, t0 = clock.now(), time.monotonic()
    if during is None:
        w1 = clock.sleep(seconds)[1]
    else:
        w1 = clock.wait_until(lambda: during() and False, seconds, start=w0)[1]
    t1 = time.monotonic()
    return Window(t0, t1, max(w1 - w0, 1e-3))


def world(address: str) -> RemoteMedium:
    """The simulated world's control API (the same server the fake dongles talk to)."""
    return RemoteMedium(address)


def wait_for_crazyflie(tf_prefix: str, timeout: float = 60.0) -> None:
    """Until crazyflie_add finished for this Crazyflie (its services exist)."""
    rospy.wait_for_service("/%s/update_params" % tf_prefix, timeout=timeout)


def start_test_node(name: str, crazyflies: Sequence[str] = (), timeout: float = 60.0) -> RemoteMedium:
    """A test's start: its node ``name``, then each of ``crazyflies`` (tf prefixes) served (at most
    ``timeout`` s each); returns the world's control API at the test's ``~sim_address`` parameter."""
    rospy.init_node(name)
    medium = world(rospy.get_param("~sim_address"))
    for tf_prefix in crazyflies:
        wait_for_crazyflie(tf_prefix, timeout)
    return medium


def wait_connected(publishers: Sequence[rospy.Publisher], timeout: float = 10.0) -> bool:
    """Until each publisher has a subscriber connected (a message published before is lost); False
    after ``timeout`` s."""
    return bool(wait_until(lambda: all(p.get_num_connections() > 0 for p in publishers), timeout))


class Repeating:
    """Calls ``fn`` now and then every ``period_s`` s on a thread of its own until :meth:`stop` or
    shutdown: a stream of setpoints or poses that runs beside a test."""

    def __init__(self, fn: Callable[[], Any], period_s: float) -> None:
        self._fn, self._period_s = fn, period_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set() and not rospy.is_shutdown():
            self._fn()
            self._stop.wait(self._period_s)

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        self._thread.join(timeout)


def registered_services() -> Set[str]:
    """Every service name the master knows, from one call. Unlike ``wait_for_service`` with a short
    timeout this does not probe each server's socket, which a busy server may answer late."""
    return {name for name, _providers in rosgraph.Master(rospy.get_name()).getSystemState()[2]}


def service_registered(name: str) -> bool:
    return name in registered_services()


def wait_served(tf_prefixes: Sequence[str], timeout: float,
                stop: Callable[[], Any] = lambda: False) -> Dict[str, float]:
    """Seconds until each Crazyflie was served (its ``update_params`` service registered), for
    those served within ``timeout`` s or before ``stop()`` turns true (e.g. an add failed)."""
    t0, served = time.monotonic(), {}
    wanted = {p: "/%s/update_params" % p.strip("/") for p in tf_prefixes}

    def check() -> bool:
        names = registered_services()
        for prefix, service in wanted.items():
            if prefix not in served and service in names:
                served[prefix] = time.monotonic() - t0
        return len(served) == len(wanted) or bool(stop())
    wait_until(check, timeout, period=0.1)
    return served


def add_crazyflies(requests: Sequence[Any], timeout: float = 30.0) -> Dict[str, float]:
    """Waits for the server's ``/add_crazyflie``, then adds each request (``AddCrazyflieRequest``)
    in turn; seconds each add took, by tf_prefix. The service's error propagates."""
    from crazyflie_driver.srv import AddCrazyflie

    rospy.wait_for_service("/add_crazyflie", timeout)
    add = rospy.ServiceProxy("/add_crazyflie", AddCrazyflie)
    took = {}
    for req in requests:
        t0 = time.monotonic()
        add(req)
        took[req.tf_prefix] = time.monotonic() - t0
    return took
