"""The motion-capture system of the simulated world, without ROS (docs/simulation.md, "Motion capture").

``MocapModel`` samples every vehicle's true pose at ``rate`` Hz of world time, adds white position
noise (σ in m) and a small random rotation (σ in rad), drops a body from a frame with probability
``dropout`` (occlusion) and hands the frame out ``latency`` seconds later, stamped with its capture
time. A ROS wrapper publishes the frames as tf / PoseStamped; tests read them directly.
``set_visible(name, False)`` hides a body altogether (an occluded or lost marker set) until shown again.
"""
from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass
from typing import Callable, Deque, Dict, List, Optional, Tuple

import numpy as np

from crazyflie_driver.sim.world.physics import quat_from_rotvec, quat_multiply


@dataclass
class MocapFrame:
    name: str
    position: np.ndarray        # (3,) m, world frame (z up)
    quaternion: np.ndarray      # (4,) x, y, z, w
    stamp: float                # world time of capture
    delivered: float            # world time it became available (stamp + latency)


class MocapModel:
    """Samples poses from a world (anything with ``poses()`` and ``add_tick_listener``)."""

    def __init__(self, world, rate: float = 100.0, position_noise: float = 0.0005,
                 orientation_noise: float = math.radians(0.2), latency: float = 0.008, dropout: float = 0.0,
                 seed: Optional[int] = None, history: int = 1000) -> None:
        if not rate > 0:
            raise ValueError("mocap rate must be > 0 Hz, got %r" % (rate,))
        if position_noise < 0 or orientation_noise < 0:
            raise ValueError("mocap noise must be >= 0")
        if latency < 0:
            raise ValueError("mocap latency must be >= 0 s, got %r" % (latency,))
        if not 0.0 <= dropout <= 1.0:
            raise ValueError("mocap dropout must be a probability 0..1, got %r" % (dropout,))
        self.world = world
        self.rate = float(rate)
        self.position_noise = float(position_noise)
        self.orientation_noise = float(orientation_noise)
        self.latency = float(latency)
        self.dropout = float(dropout)
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._pending: Deque[MocapFrame] = deque()
        self._ready: Deque[MocapFrame] = deque(maxlen=history)
        self._latest: Dict[str, MocapFrame] = {}
        self._listeners: List[Callable[[List[MocapFrame]], None]] = []
        self._next_sample = 0.0
        self._attached = False
        self._hidden: set = set()
        self.frames_captured = 0
        self.frames_dropped = 0

    # --- driving -----------------------------------------------------------------------------
    def attach(self) -> "MocapModel":
        """Run from the world's ticks: a capture every 1/rate s of world time, each delivered ``latency`` later."""
        if not self._attached:
            period = 1.0 / self.rate
            self._next_sample = float(self.world.time) + period
            self.world.add_tick_listener(self._on_capture, period)
            if self.latency > 0:
                self.world.add_tick_listener(self._on_delivery, period, first=self._next_sample + self.latency)
            self._attached = True
        return self

    def detach(self) -> None:
        remove = getattr(self.world, "remove_tick_listener", None)
        if self._attached and remove is not None:
            remove(self._on_capture)
            remove(self._on_delivery)
        self._attached = False

    def _on_capture(self, now: float) -> None:
        self.capture(now)
        if self.latency <= 0:
            self.deliver(now)

    def _on_delivery(self, now: float) -> None:
        self.deliver(now)

    def capture(self, now: float) -> List[MocapFrame]:
        """Sample all poses now; the frames become available at now + latency."""
        names, pos, quat = self.world.poses()
        n = len(names)
        if n == 0:
            return []
        rng = self._rng
        if self.position_noise:
            pos = pos + rng.standard_normal((n, 3)) * self.position_noise
        if self.orientation_noise:
            quat = quat_multiply(quat, quat_from_rotvec(rng.standard_normal((n, 3)) * self.orientation_noise))
        seen = rng.random(n) >= self.dropout if self.dropout else np.ones(n, dtype=bool)
        hidden = self._hidden
        frames = [MocapFrame(names[k], pos[k].copy(), quat[k].copy(), now, now + self.latency)
                  for k in range(n) if seen[k] and names[k] not in hidden]
        with self._lock:
            self.frames_captured += len(frames)
            self.frames_dropped += int(n - seen.sum())
            self._pending.extend(frames)
        return frames

    def deliver(self, now: float) -> List[MocapFrame]:
        """Release the frames whose latency has passed; listeners get them as one list."""
        out: List[MocapFrame] = []
        with self._lock:
            while self._pending and self._pending[0].delivered <= now + 1e-9:
                f = self._pending.popleft()
                out.append(f)
                self._ready.append(f)
                self._latest[f.name] = f
            listeners = list(self._listeners)
        if out:
            for fn in listeners:
                fn(out)
        return out

    # --- occlusion ---------------------------------------------------------------------------
    def set_visible(self, name: str, visible: bool) -> None:
        """Stop (False) or resume (True) reporting the body ``name``; KeyError if the world has none."""
        if name not in self.world.poses()[0]:
            raise KeyError("no vehicle called %r for motion capture to see" % (name,))
        hidden = set(self._hidden)
        if visible:
            hidden.discard(name)
        else:
            hidden.add(name)
        self._hidden = frozenset(hidden)     # replaced whole: the stepping thread reads it

    def visible(self, name: str) -> bool:
        return name not in self._hidden

    # --- consuming ---------------------------------------------------------------------------
    def add_listener(self, fn: Callable[[List[MocapFrame]], None]) -> None:
        """fn(frames) from the world's stepping thread whenever frames are delivered."""
        with self._lock:
            self._listeners.append(fn)

    def pop_frames(self) -> List[MocapFrame]:
        """Frames delivered since the last call (oldest first)."""
        with self._lock:
            out = list(self._ready)
            self._ready.clear()
            return out

    def latest(self, name: str) -> Optional[MocapFrame]:
        with self._lock:
            return self._latest.get(name)

    def latest_pose(self, name: str) -> Optional[Tuple[np.ndarray, np.ndarray, float]]:
        f = self.latest(name)
        return None if f is None else (f.position.copy(), f.quaternion.copy(), f.stamp)
