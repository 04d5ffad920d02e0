"""The motion-capture system of the simulated world, without ROS (docs/simulation.md, "Motion capture").

``MocapModel`` samples every vehicle's true pose at ``rate`` Hz of world time, adds white position
noise (σ in m) and a small random rotation (σ in rad), drops a body from a frame with probability
``dropout`` (occlusion) and hands the frame out ``latency`` seconds later, stamped with its capture
time. A ROS wrapper publishes the frames as tf / PoseStamped; tests read them directly.
``set_visible(name, False)`` hides a body altogether (an occluded or lost marker set) until shown again.

Per-body faults (``set_body_faults``) override the model's settings for one body at run time: its own
position noise, extra latency, a lower rate, a dropout probability, a frozen pose (the stream goes on
with fresh stamps but the pose stays where it was, as a tracker that lost its markers and repeats the
last solution) and hiding, the last two for a span of world time or for good. A body's extra latency
is delivered with the next capture or delivery tick, so it rounds up to the capture period.

Each body's frames wait in a queue of their own, so one body's latency never holds back another's
frames, and a latency that is lowered or cleared takes effect with the next capture: the frames
still in flight that a newer frame of the same body would overtake are dropped (``frames_superseded``),
so every body's stream stays in capture order.
"""
from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass, replace
from typing import Any, Callable, Deque, Dict, FrozenSet, List, Optional, Tuple

import numpy as np

from crazyflie_driver.sim.room.physics import quat_from_rotvec, quat_multiply


@dataclass
class MocapFrame:
    name: str
    position: np.ndarray        # (3,) m, world frame (z up)
    quaternion: np.ndarray      # (4,) x, y, z, w
    stamp: float                # world time of capture
    delivered: float            # world time it became available (stamp + latency)


@dataclass(frozen=True)
class BodyFaults:
    """What is wrong with one body's tracking; ``None`` keeps the model's own setting."""

    noise: Optional[float] = None          # position noise σ, m (replaces the model's)
    latency: float = 0.0                   # extra delay, s (on top of the model's)
    rate: Optional[float] = None           # Hz, at most the model's rate
    dropout: Optional[float] = None        # probability a frame of this body is lost
    freeze_until: float = -math.inf        # world time the pose stays frozen until (inf: for good)
    hide_until: float = -math.inf          # world time the body stays hidden until (inf: for good)

    def active(self, now: float) -> bool:
        return (self.noise is not None or self.latency > 0 or self.rate is not None or self.dropout is not None
                or self.freeze_until > now or self.hide_until > now)

    def describe(self, now: float) -> str:
        """One line for diagnostics and the fault tool, e.g. ``frozen for 1.8 s more, noise 0.010 m``."""
        parts = []
        for what, until in (("frozen", self.freeze_until), ("hidden", self.hide_until)):
            if until == math.inf:
                parts.append("%s for good" % what)
            elif until > now:
                parts.append("%s for %.1f s more" % (what, until - now))
        if self.noise is not None:
            parts.append("noise %.4f m" % self.noise)
        if self.latency > 0:
            parts.append("latency +%.0f ms" % (self.latency * 1000.0))
        if self.rate is not None:
            parts.append("rate %.1f Hz" % self.rate)
        if self.dropout is not None:
            parts.append("dropout %.0f %%" % (self.dropout * 100.0))
        return ", ".join(parts)


_NO_FAULTS = BodyFaults()


def _finite_non_negative(what: str, value: float, unit: str) -> float:
    if not 0 <= value < math.inf:
        raise ValueError("%s must be a finite number >= 0 %s, got %r" % (what, unit, value))
    return float(value)


def _spans_until(now: float, **spans: Optional[float]) -> Dict[str, float]:
    """``freeze``/``hide`` spans (s from ``now``; inf: for good; 0 ends it) as ``<what>_until`` world
    times (-inf: not in force); spans left None are left out."""
    out = {}
    for what, span in spans.items():
        if span is not None:
            if not span >= 0:
                raise ValueError("mocap %s must last >= 0 s, got %r" % (what, span))
            out[what + "_until"] = now + float(span) if span > 0 else -math.inf
    return out


class MocapModel:
    """Samples poses from a world (anything with ``poses()`` and ``add_tick_listener``)."""

    def __init__(self, world, rate: float = 100.0, position_noise: float = 0.0005,
                 orientation_noise: float = math.radians(0.2), latency: float = 0.008, dropout: float = 0.0,
                 seed: Optional[int] = None, history: int = 1000) -> None:
        if not rate > 0:
            raise ValueError("mocap rate must be > 0 Hz, got %r" % (rate,))
        if not (0 <= position_noise < math.inf and 0 <= orientation_noise < math.inf):
            raise ValueError("mocap noise must be a finite number >= 0, got %r and %r" % (position_noise,
                                                                                       orientation_noise))
        if not 0 <= latency < math.inf:
            raise ValueError("mocap latency must be a finite number >= 0 s, got %r" % (latency,))
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
        self._pending: Dict[str, Deque[MocapFrame]] = {}      # per body, in capture and delivery order
        self._ready: Deque[MocapFrame] = deque(maxlen=history)
        self._latest: Dict[str, MocapFrame] = {}
        self._listeners: List[Callable[[List[MocapFrame]], None]] = []
        self._next_sample = 0.0
        self._attached = False
        self._hidden: FrozenSet[str] = frozenset()
        self._faults: Dict[str, BodyFaults] = {}      # replaced whole: the stepping thread reads it
        self._frozen: Dict[str, Tuple[np.ndarray, np.ndarray]] = {}   # pose a frozen body keeps reporting
        self._next_body_sample: Dict[str, float] = {}                 # bodies with a lower rate
        self.frames_captured = 0
        self.frames_dropped = 0
        self.frames_superseded = 0      # in flight when a lower latency let a newer frame overtake them

    # --- driving -----------------------------------------------------------------------------
    def attach(self) -> MocapModel:
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
        truth = pos
        if self.position_noise:
            pos = pos + rng.standard_normal((n, 3)) * self.position_noise
        if self.orientation_noise:
            quat = quat_multiply(quat, quat_from_rotvec(rng.standard_normal((n, 3)) * self.orientation_noise))
        seen = rng.random(n) >= self.dropout if self.dropout else np.ones(n, dtype=bool)
        hidden = self._hidden
        faults = self._faults
        if faults:
            frames = self._capture_with_faults(now, names, truth, pos, quat, seen, hidden, faults)
        else:
            frames = [MocapFrame(names[k], pos[k].copy(), quat[k].copy(), now, now + self.latency)
                      for k in range(n) if seen[k] and names[k] not in hidden]
        with self._lock:
            self.frames_captured += len(frames)
            self.frames_dropped += int(n - seen.sum())
            for f in frames:
                self._queue(f)
        return frames

    def _queue(self, frame: MocapFrame) -> None:
        """Into its body's queue (lock held); frames it would overtake (its latency fell) are dropped."""
        q = self._pending.get(frame.name)
        if q is None:
            q = self._pending[frame.name] = deque()
        while q and q[-1].delivered > frame.delivered:
            q.pop()
            self.frames_superseded += 1
        q.append(frame)

    def _capture_with_faults(self, now: float, names: List[str], truth: np.ndarray, pos: np.ndarray,
                             quat: np.ndarray, seen: np.ndarray, hidden,
                             faults: Dict[str, BodyFaults]) -> List[MocapFrame]:
        """``capture`` for a frame where some bodies have faults of their own (``set_body_faults``)."""
        rng = self._rng
        frames = []
        for k, name in enumerate(names):
            f = faults.get(name, _NO_FAULTS)
            if f is _NO_FAULTS:
                if seen[k] and name not in hidden:
                    frames.append(MocapFrame(name, pos[k].copy(), quat[k].copy(), now, now + self.latency))
                continue
            if f.rate is not None:
                if now < self._next_body_sample.get(name, -math.inf) - 1e-9:
                    continue
                self._next_body_sample[name] = now + 1.0 / f.rate
            if f.dropout is not None:
                seen[k] = rng.random() >= f.dropout
            if not seen[k] or name in hidden or f.hide_until > now:
                continue
            p, q = pos[k].copy(), quat[k].copy()
            if f.noise is not None:       # this body's noise replaces the model's
                p = truth[k] + rng.standard_normal(3) * f.noise
            if f.freeze_until > now:
                p, q = self._frozen.setdefault(name, (p, q))
                p, q = p.copy(), q.copy()
            else:
                self._frozen.pop(name, None)
            frames.append(MocapFrame(name, p, q, now, now + self.latency + f.latency))
        return frames

    # --- per-body faults ---------------------------------------------------------------------
    def set_body_faults(self, name: str, now: float, noise: Optional[float] = None,
                        latency: Optional[float] = None, rate: Optional[float] = None,
                        dropout: Optional[float] = None, freeze: Optional[float] = None,
                        hide: Optional[float] = None) -> BodyFaults:
        """Add to body ``name``'s faults (arguments left None keep what it has).

        ``freeze`` / ``hide``: seconds of world time from ``now`` (``math.inf``: for good; 0 ends it).
        Raises KeyError for an unknown body, ValueError for a value out of range.
        """
        if name not in self.world.poses()[0]:
            raise KeyError("no vehicle called %r for motion capture to see" % (name,))
        changes: Dict[str, Any] = {}
        if noise is not None:
            changes["noise"] = _finite_non_negative("mocap noise", noise, "m")
        if latency is not None:
            changes["latency"] = _finite_non_negative("mocap latency", latency, "s")
        if rate is not None:
            changes["rate"] = self._body_rate(rate)
        if dropout is not None:
            if not 0.0 <= dropout <= 1.0:
                raise ValueError("mocap dropout must be a probability 0..1, got %r" % (dropout,))
            changes["dropout"] = float(dropout)
        changes.update(_spans_until(now, freeze=freeze, hide=hide))
        f = replace(self._faults.get(name, _NO_FAULTS), **changes)
        self._set_faults(name, f)
        return f

    def _body_rate(self, rate: float) -> Optional[float]:
        """A body's own rate, at most the system's (None: the system's)."""
        if not 0 < rate <= self.rate:
            raise ValueError("a body's mocap rate must be in (0, %g] Hz (the system's rate), got %r"
                             % (self.rate, rate))
        return None if rate == self.rate else float(rate)

    def clear_body_faults(self, name: Optional[str] = None) -> None:
        """Forget the faults of body ``name`` (every body when None); hiding by ``set_visible`` stays."""
        if name is None:
            self._faults = {}
        else:
            self._set_faults(name, _NO_FAULTS)

    def body_faults(self, now: float) -> Dict[str, BodyFaults]:
        """The bodies with a fault in force at world time ``now``."""
        return {n: f for n, f in self._faults.items() if f.active(now)}

    def _set_faults(self, name: str, f: BodyFaults) -> None:
        faults = dict(self._faults)
        if f == _NO_FAULTS:
            faults.pop(name, None)
        else:
            faults[name] = f
        if f.freeze_until == -math.inf:
            self._frozen.pop(name, None)
        if f.rate is None:
            self._next_body_sample.pop(name, None)
        self._faults = faults                 # replaced whole: the stepping thread reads it

    def deliver(self, now: float) -> List[MocapFrame]:
        """Release the frames whose latency has passed; listeners get them as one list."""
        out: List[MocapFrame] = []
        with self._lock:
            due = []
            for q in self._pending.values():        # each body on its own: none waits behind another
                while q and q[0].delivered <= now + 1e-9:
                    due.append(q.popleft())
            if len(due) > 1:
                due.sort(key=lambda f: f.stamp)     # capture order across bodies, as one system delivers
            for f in due:
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
