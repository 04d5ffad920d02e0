"""The world's motion capture served as a VRPN server on loopback, as a motion-capture PC serves it.

One tracker per vehicle, named after it. Each frame the world's ``MocapModel`` delivers goes out once,
as one report cycle, when the model delivers it: so the stream has the model's rate (in world time),
noise, latency and dropouts (a body the model did not see in a frame is left out of that cycle, as a
real system leaves out a body it lost), and each report is stamped with its capture time on the
host's clock. Any VRPN client (the stack's own, a real vrpn_client_ros, a user's script) reads the
simulation as it would read a real system. Port 3883 (the VRPN default) when it is free, else one
the system picks; ``port`` says which. Facts in docs/simulation.md ("Motion capture over VRPN").
"""
from __future__ import annotations

import socket
import threading
import time
from collections import deque
from typing import Deque, List, Optional, Tuple

from crazyflie_driver.mocap import vrpn_protocol as vp
from crazyflie_driver.mocap.vrpn_server import VrpnTestServer

LOOPBACK = "127.0.0.1"
#: Delivered frames waiting for the sending thread, at most (older ones are dropped when it falls behind).
BACKLOG_CYCLES = 100
#: The smallest step between two report cycles' stamps [us]: VRPN stamps count whole microseconds.
STAMP_STEP_US = 1


def port_is_free(host: str, port: int) -> bool:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        s.bind((host, port))
        return True
    except OSError:
        return False
    finally:
        s.close()


def capture_wall_time(now_wall: float, world_now: float, captured: float, speed: float) -> float:
    """The host-clock time of a capture ``world_now - captured`` world seconds ago (speed 0: now)."""
    if speed <= 0:
        return now_wall
    return now_wall - max(0.0, world_now - captured) / speed


class WorldVrpnServer:
    """Serves a world's ``MocapModel`` frames over VRPN (start/stop; trackers follow the vehicles).

    The world's stepping thread only queues the delivered frames; a thread of its own sends them,
    so a slow client never slows the world.
    """

    def __init__(self, world, mocap, port: Optional[int] = None, host: str = LOOPBACK) -> None:
        self.world = world
        self.mocap = mocap
        if port is None:
            port = vp.DEFAULT_PORT if port_is_free(host, vp.DEFAULT_PORT) else 0
        self._server = VrpnTestServer(trackers=(), host=host, port=int(port), rate=float(mocap.rate), stream=False)
        self._cycles: Deque[Tuple[float, list]] = deque(maxlen=BACKLOG_CYCLES)
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.cycles_sent = 0
        self._last_stamp_us = 0                 # host time of the newest cycle queued [us since the epoch]
        mocap.add_listener(self._on_frames)

    @property
    def port(self) -> int:
        return self._server.port

    @property
    def poses_sent(self) -> int:
        return self._server.poses_sent

    def client_count(self) -> int:
        return self._server.client_count()

    def sync_trackers(self) -> None:
        """One tracker per vehicle of the world (new vehicles get theirs; call after adding some)."""
        for v in self.world.vehicles():
            self._server.add_tracker(v.name)

    def start(self) -> Tuple[str, int]:
        self.sync_trackers()
        address = self._server.start()
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._send_loop, name="world-vrpn-send", daemon=True)
            self._thread.start()
        return address

    def stop(self) -> None:
        self._stop.set()
        self._ready.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        self._server.stop()

    def __enter__(self) -> WorldVrpnServer:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _on_frames(self, frames) -> None:
        """The world's stepping thread: queue the delivery as cycles of one capture each."""
        now_wall, world_now, speed = time.time(), float(self.world.time), float(self.world.speed)
        cycles: dict = {}
        for f in frames:
            cycles.setdefault(f.stamp, []).append((f.name, f.position, f.quaternion))
        with self._lock:
            for captured, poses in sorted(cycles.items()):
                # the world's schedule, when it steps in real time: a burst of frames a world that fell
                # behind steps in one go keeps its frame period, as a motion-capture system's stamps do
                scheduled = self.world.wall_time_of(captured)
                stamp = capture_wall_time(now_wall, world_now, captured, speed) if scheduled is None else scheduled
                # a new schedule (the speed changed, a lag let go) maps a capture made under the old one
                # differently: stamps still never go back, as a motion-capture system's do not
                # (in whole microseconds: a float of a Unix time has a quarter-microsecond grain)
                stamp_us = max(int(round(stamp * 1e6)), self._last_stamp_us + STAMP_STEP_US)
                self._last_stamp_us = stamp_us
                self._cycles.append((stamp_us / 1e6, poses))
        self._ready.set()

    def _send_loop(self) -> None:
        while not self._stop.is_set():
            self._ready.wait(0.5)
            self._ready.clear()
            with self._lock:
                cycles: List[Tuple[float, list]] = list(self._cycles)
                self._cycles.clear()
            for stamp, poses in cycles:
                if self._stop.is_set():
                    return
                self._server.send_poses(poses, stamp)
                self.cycles_sent += 1
