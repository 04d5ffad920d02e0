"""Motion capture to the onboard estimators of a swarm, in packed broadcasts, without ROS.

Poses come in one by one from whatever source (VRPN, tf, topics), in any thread. Each radio has its
own sender thread (the radios then work in parallel): the first pose of a motion-capture frame wakes
it, it waits ``gather_s`` for the rest of that frame and then sends every pose of its Crazyflies that
arrived since its last burst, two poses per packet (or four positions), in one turn of its dongle. So
the stream runs at the motion-capture rate with one radio turn per frame and radio. A pose whose
orientation is missing or not a unit quaternion goes out as a position only.

A pose the packed format cannot carry (NaN, infinity, a coordinate beyond +-32.767 m: a tracker's
outlier or ghost) is refused on its own: the other Crazyflies of its radio get their poses as usual,
the refused one keeps its last good pose pending, and the log names the Crazyflie and the value (the
first refusal at once, then at most one line per ``REFUSAL_LOG_PERIOD_S`` with the count). Dropping
beats clamping: a clamped pose is a wrong position the estimator would trust. ``on_pose`` reports
a pose only once its burst went out, so a Crazyflie whose poses are all refused (or whose radio
fails) goes stale for the swarm watch and ``/diagnostics`` instead of looking fresh.

The first pose of each Crazyflie is also reported once (``on_first_fix``; again after ``refix``, when
writing it failed), for the estimator's initial position (``kalman.initialX/Y/Z`` +
``kalman.resetEstimation``, as Crazyswarm does); that runs in its own thread so slow parameter
writes never hold the stream.
"""
from __future__ import annotations

import logging
import math
import queue
import threading
import time
from typing import Callable, Dict, Hashable, List, Mapping, Optional, Sequence, Tuple

from crazyflie_driver.errors import CommandValueError
from crazyflie_driver.protocol.localization import packed_position

LOG = logging.getLogger("crazyflie_driver.server.mocap")

Position = Tuple[float, float, float]
Quaternion = Tuple[float, float, float, float]
#: How long the sender waits for the rest of a frame after its first pose (s).
DEFAULT_GATHER_S = 0.002
LATENCY_SAMPLES = 2000          # kept for the median / p99 (the newest ones)
#: A Crazyflie's refused poses are logged at most once in this many seconds (s; its first one at once).
REFUSAL_LOG_PERIOD_S = 5.0
#: Faster than a Crazyflie flies (m/s): a pose that implies more, from that Crazyflie's last accepted
#: one, is a ghost (noise, a swapped or reflected marker set) and is refused, not sent.
MAX_POSE_SPEED_M_S = 5.0
#: What a true pose may move on top of that (m): motion-capture noise and one frame's latency.
POSE_JUMP_MARGIN_M = 0.2


def usable_quaternion(q: Optional[Sequence[float]]) -> Optional[Quaternion]:
    """``q`` normalised, or None when it is missing, not finite or far from unit length."""
    if q is None or len(q) != 4 or not all(math.isfinite(c) for c in q):
        return None
    n = math.sqrt(sum(c * c for c in q))
    if not 0.5 < n < 1.5:
        return None
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


class MocapStream:
    """``send(poses, position_only)`` sends one frame (``poses``: by URI, (x, y, z, qx, qy, qz, qw) or
    (x, y, z)); ``uris``: the URI of each Crazyflie name the poses come under; ``radio_of(uri)``: the
    key of the radio that reaches it (one sender thread each; default: one for all); ``frame_periods``:
    the shortest time between two bursts of a radio (s, by radio key; default none: every frame);
    ``clock`` and ``sleep`` time the poses and pace the bursts; ``on_pose(name, received)`` is called
    for each pose once its burst went out (``received``: when the pose came in)."""

    def __init__(self, uris: Mapping[str, str], send: Callable[[Dict[str, tuple], bool], int],
                 position_only: bool = False, on_first_fix: Optional[Callable[[str, Position], None]] = None,
                 on_pose: Optional[Callable[[str, float], None]] = None, gather_s: float = DEFAULT_GATHER_S,
                 clock: Callable[[], float] = time.monotonic,
                 radio_of: Optional[Callable[[str], Hashable]] = None,
                 frame_periods: Optional[Mapping[Hashable, float]] = None,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.uris = dict(uris)
        self._radio = {name: (radio_of(uri) if radio_of is not None else 0) for name, uri in self.uris.items()}
        self._send = send
        self.position_only = position_only
        self._on_first_fix = on_first_fix
        self._on_pose = on_pose
        self.gather_s = gather_s
        self.frame_periods: Dict[Hashable, float] = dict(frame_periods or {})
        self._clock = clock
        self._sleep = sleep
        self._cond = threading.Condition()
        self._pending: Dict[Hashable, Dict[str, Tuple[float, Position, Optional[Quaternion]]]] = {
            radio: {} for radio in self._radio.values()}
        self._stats_lock = threading.Lock()
        self._fixed: set = set()
        self._last_good: Dict[str, Tuple[float, Position]] = {}     # name -> (time s, position m) accepted
        self._fixes: queue.Queue[Optional[Tuple[str, Position]]] = queue.Queue()
        self._stopping = False
        self._paused = False
        self._threads: List[threading.Thread] = []
        self.frames = 0
        self.transfers = 0
        self.poses_sent = 0
        self.send_errors = 0
        self.latencies: List[float] = []        # s from a pose's arrival to its burst leaving
        self.sent_by_name: Dict[str, int] = {name: 0 for name in self.uris}      # poses that went out
        self.refused: Dict[str, int] = {name: 0 for name in self.uris}           # poses refused
        self.last_refusal: Dict[str, str] = {}                                  # why, the newest one
        self._refusal_logged: Dict[str, Tuple[float, int]] = {}                 # when, count then

    # -- input (any thread) ---------------------------------------------------------------------
    def pose(self, name: str, position: Sequence[float], orientation: Optional[Sequence[float]] = None,
             received: Optional[float] = None) -> bool:
        """A new pose of ``name`` (m, world frame); False when the name is not in the swarm or the
        packed format cannot carry the position (refused and logged; the last good pose stays pending)."""
        if name not in self.uris:
            return False
        try:
            p = packed_position(position)
        except CommandValueError as e:
            self._refuse(name, str(e))
            return False
        now = self._clock() if received is None else received
        jump = self._implausible_jump(name, now, position)
        if jump:
            self._refuse(name, jump)
            return False
        with self._cond:
            self._last_good[name] = (now, (float(position[0]), float(position[1]), float(position[2])))
            self._pending[self._radio[name]][name] = (now, p, usable_quaternion(orientation))
            self._cond.notify_all()
            first = name not in self._fixed
            self._fixed.add(name)
        if first:
            self._fixes.put((name, p))
        return True

    def _implausible_jump(self, name: str, now: float, position: Sequence[float]) -> str:
        """Why ``position`` cannot be ``name``'s (a jump faster than MAX_POSE_SPEED_M_S from its last
        accepted pose), or "". The allowance grows with the time since, so a body hidden and carried
        elsewhere is taken again once the time could explain the move."""
        with self._cond:
            last = self._last_good.get(name)
        if last is None:
            return ""
        t0, p0 = last
        moved = math.sqrt(sum((float(a) - b) ** 2 for a, b in zip(position, p0)))
        allowed = POSE_JUMP_MARGIN_M + MAX_POSE_SPEED_M_S * max(0.0, now - t0)
        if moved <= allowed:
            return ""
        return ("pose jumped %.2f m in %.3f s from its last accepted one (more than %.1f m/s): a ghost or a "
                "swapped marker set; check the motion-capture body" % (moved, max(0.0, now - t0), MAX_POSE_SPEED_M_S))

    def refix(self, name: str) -> None:
        """Report ``name``'s next pose as a first fix again (its initial position was not written)."""
        with self._cond:
            self._fixed.discard(name)

    def pause(self, paused: bool = True) -> None:
        """Stop (or resume) sending, e.g. after an emergency; poses are still taken in."""
        self._paused = paused

    # -- threads ---------------------------------------------------------------------------------
    def pending(self) -> Dict[str, Tuple[float, Position, Optional[Quaternion]]]:
        """The poses not sent yet, of every radio (tests send them with ``send_frame``)."""
        with self._cond:
            return {name: item for frame in self._pending.values() for name, item in frame.items()}

    def take_pending(self) -> Dict[str, Tuple[float, Position, Optional[Quaternion]]]:
        """``pending()``, taken: the next frame starts empty (tests drive bursts with this and ``send_frame``)."""
        with self._cond:
            frame = {name: item for frame in self._pending.values() for name, item in frame.items()}
            for radio in self._pending:
                self._pending[radio] = {}
            return frame

    def start(self) -> MocapStream:
        targets = [(lambda radio=radio: self._run(radio), "mocap stream %s" % (radio,)) for radio in self._pending]
        for target, name in targets + [(self._run_fixes, "mocap first fixes")]:
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def stop(self, timeout: float = 2.0) -> None:
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        self._fixes.put(None)
        for t in self._threads:
            t.join(timeout)

    def _run(self, radio: Hashable) -> None:
        last_burst = -1e9
        while True:
            with self._cond:
                while not self._pending[radio] and not self._stopping:
                    self._cond.wait()
                if self._stopping:
                    return
            wait = max(self.gather_s, last_burst + self.frame_periods.get(radio, 0.0) - self._clock())
            if wait > 0:
                self._sleep(wait)
            last_burst = self._clock()
            with self._cond:
                frame, self._pending[radio] = self._pending[radio], {}
            if not self._paused:
                self.send_frame(frame)

    def send_frame(self, frame: Mapping[str, Tuple[float, Position, Optional[Quaternion]]]) -> int:
        """Send one frame now (the sender thread calls this; tests may too). Returns USB transfers.
        A pose the packed format cannot carry is left out (and logged), never the whole frame."""
        frame = self._packable(frame)
        if not frame:
            return 0
        taken = self._broadcast(frame)
        if taken is None:
            return 0
        self._count(frame, taken)
        if self._on_pose is not None:
            for name, (received, _, _) in frame.items():
                self._on_pose(name, received)
        return taken

    def _packable(self, frame: Mapping[str, Tuple[float, Position, Optional[Quaternion]]]
                  ) -> Dict[str, Tuple[float, Position, Optional[Quaternion]]]:
        """The frame's poses the packed format can carry; the others are refused (counted, logged)."""
        good = {}
        for name, item in frame.items():
            try:
                packed_position(item[1])
            except CommandValueError as e:
                self._refuse(name, str(e))
                continue
            good[name] = item
        return good

    def _broadcast(self, frame: Mapping[str, Tuple[float, Position, Optional[Quaternion]]]) -> Optional[int]:
        """The frame's full poses and positions on the air; the USB transfers, None when a dongle failed
        (logged; the next frame tries again)."""
        poses: Dict[str, tuple] = {}
        positions: Dict[str, tuple] = {}
        for name, (_, p, q) in frame.items():
            if self.position_only or q is None:
                positions[self.uris[name]] = p
            else:
                poses[self.uris[name]] = p + q
        taken = 0
        try:
            if poses:
                taken += self._send(poses, False)
            if positions:
                taken += self._send(positions, True)
        except Exception as e:      # a dongle gone: the next frame tries again
            self.send_errors += 1
            if self.send_errors == 1 or self.send_errors % 1000 == 0:
                LOG.error("motion capture broadcast failed (%d times so far): %s", self.send_errors, e)
            return None
        return taken

    def _count(self, frame: Mapping[str, Tuple[float, Position, Optional[Quaternion]]], taken: int) -> None:
        """The statistics of a frame sent: frames, transfers, poses per Crazyflie, latencies."""
        sent_at = self._clock()
        with self._stats_lock:
            self.frames += 1
            self.transfers += taken
            self.poses_sent += len(frame)
            for name in frame:
                self.sent_by_name[name] += 1
            self.latencies.extend(sent_at - t for t, _, _ in frame.values())
            if len(self.latencies) > LATENCY_SAMPLES:
                del self.latencies[:-LATENCY_SAMPLES]

    def _refuse(self, name: str, why: str) -> None:
        """Count and log a pose of ``name`` the packed format cannot carry (throttled per Crazyflie)."""
        now = self._clock()
        with self._stats_lock:
            self.refused[name] = count = self.refused.get(name, 0) + 1
            self.last_refusal[name] = why
            logged_at, logged_count = self._refusal_logged.get(name, (-math.inf, 0))
            due = now - logged_at >= REFUSAL_LOG_PERIOD_S
            if due:
                self._refusal_logged[name] = (now, count)
        if due:
            LOG.error("motion capture: %s: pose refused, not sent (%s); %d refused in all%s; its radio's other "
                      "Crazyflies get theirs", name, why, count,
                      "" if logged_count == 0 else ", %d since the last report" % (count - logged_count))

    def _run_fixes(self) -> None:
        while True:
            item = self._fixes.get()
            if item is None:
                return
            if self._on_first_fix is not None:
                try:
                    self._on_first_fix(*item)
                except Exception as e:
                    LOG.error("%s: initial position from the first pose failed: %s", item[0], e)
