"""How fast the simulated world runs: a fixed factor of real time, or ``auto``: slower while the host lags.

In simulation the host's nodes time everything on ROS time, which is the world's time (``/clock``).
A world that runs at a speed the machine cannot serve leaves the host late *in world time*: its
100 Hz loops fire late, its setpoints and external positions reach the Crazyflie late, and the
flight gets worse. ``speed:=auto`` slows the world down while that happens and returns to real
time when the host has caught up, so a busy machine makes a flight slower, not worse.

What "the host lags" means here (docs/simulation.md, "Simulated time and world pacing"): the host's
processes (the world's siblings: the other nodes of its launch) wait in the kernel's run queue
before they get a CPU. Their schedstat (``/proc/<pid>/task/<tid>/schedstat``: time run, time
waited, time slices) gives the mean wait per time slice over the last half second: how late a host
thread starts on what it was woken for. Multiplied by the world's speed it is that lateness in world
time; ``AutoSpeed`` keeps it below ``LAG_BOUND_S``. A process that is silent (a watchdog test, a
killed controller) does not wait for a CPU, so silence cannot look like lag. Where the world itself
cannot keep up with its speed, ``auto`` also takes the speed it achieves.
"""
from __future__ import annotations

import logging
import math
import os
import threading
import time
from dataclasses import dataclass
from typing import Callable, Dict, Iterable, List, Optional, Tuple

_log = logging.getLogger(__name__)

AUTO = "auto"
MIN_SPEED = 0.1
"""Slowest an ``auto`` world runs [world s per wall s]; below this a simulation is no longer usable."""
SAMPLE_PERIOD_S = 0.5
"""Wall seconds [s] between two looks at the host's run-queue waits."""
SIBLINGS_REFRESH_S = 5.0
"""Wall seconds [s] between two scans of /proc for the host's processes (nodes come and go)."""
LAG_BOUND_S = 0.001
"""World seconds [s] a host thread may wait for a CPU per time slice (mean) before ``auto`` slows the
world: a tenth of a 100 Hz control period. Measured on two cores: a node-like thread (3 ms of work
per 10 ms) waits 0.02 ms per slice on an idle machine, 1.5 ms beside two busy loops, 3.3 ms beside
six bursty ones."""
RECOVER_BELOW_S = 0.0004
"""World seconds [s] of mean wait below which ``auto`` speeds the world up again."""
RECOVER_WINDOWS = 2
"""Consecutive calm samples before ``auto`` speeds up (it slows down at once)."""
SPEED_UP_FACTOR = 1.15
"""Per calm sample, ``auto`` speeds the world up by this factor (up to its target)."""
MAX_SLOW_DOWN = 0.5
"""Per laggy sample, ``auto`` at most halves the speed."""
AUTO_MAX_LAG_S = 0.02
"""World seconds [s] an ``auto`` world may trail its schedule and still catch up (stepping ticks back
to back); further behind, it starts a new schedule from where it is. Catching up runs world time
faster than real time, a burst the host cannot follow: its setpoints and external positions miss
the burst's control periods, so under load the flight would get worse instead of slower. Two
control periods: a world thread woken a little late still keeps its schedule."""
BEHIND_TICKS = 50
"""Firmware ticks (50 ms of world time) the world may trail its own schedule before ``auto`` takes
the speed it achieves."""


class PacingError(ValueError):
    """A speed setting that is neither a number >= 0 nor 'auto'; the message says which."""


@dataclass(frozen=True)
class Pacing:
    """A world's pacing: ``auto`` or a fixed speed; ``target`` the speed it runs at when nothing lags
    (the fixed speed itself; 1.0, real time, for ``auto``)."""

    auto: bool
    target: float

    @property
    def mode(self) -> str:
        return AUTO if self.auto else "fixed"

    def describe(self) -> str:
        return "auto (up to %.2fx)" % self.target if self.auto else "fixed %.2fx" % self.target


def parse_pacing(value) -> Pacing:
    """``"auto"`` or a number >= 0 (0: as fast as possible) from a launch argument or a command line."""
    if isinstance(value, str):
        text = value.strip().lower()
        if text == AUTO:
            return Pacing(True, 1.0)
        try:
            value = float(text)
        except ValueError:
            raise PacingError("speed must be 'auto' or a number >= 0 (world seconds per wall second; "
                              "0: as fast as possible), got %r" % (value,)) from None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)) \
            or float(value) < 0:
        raise PacingError("speed must be 'auto' or a number >= 0 (world seconds per wall second; "
                          "0: as fast as possible), got %r" % (value,))
    return Pacing(False, float(value))


class AutoSpeed:
    """The ``auto`` rule, pure: one lag sample in, the world's next speed out.

    ``update(lag_wall_s, achieved)``: ``lag_wall_s`` the host's mean run-queue wait per time slice
    [wall s] over the last sample; ``achieved`` the world's measured real-time factor (None: not
    known, or the world keeps its schedule). The
    lateness in world time is ``lag_wall_s * speed``; above LAG_BOUND_S the speed drops at once to
    where it would be 0.8 of the bound (at most halved per sample, never below MIN_SPEED); below
    RECOVER_BELOW_S for RECOVER_WINDOWS samples in a row it rises by SPEED_UP_FACTOR up to ``target``.
    """

    def __init__(self, target: float = 1.0, start: Optional[float] = None) -> None:
        if not target > 0:
            raise PacingError("auto speed needs a target > 0, got %r" % (target,))
        self.target = float(target)
        self.speed = float(target if start is None else start)
        self.lag_world_s = 0.0
        self._calm = 0

    def update(self, lag_wall_s: float, achieved: Optional[float] = None) -> float:
        speed = self.speed
        lag = max(0.0, float(lag_wall_s)) * speed
        self.lag_world_s = lag
        if lag > LAG_BOUND_S:
            self._calm = 0
            speed *= max(MAX_SLOW_DOWN, 0.8 * LAG_BOUND_S / lag)
        elif lag < RECOVER_BELOW_S:
            self._calm += 1
            if self._calm >= RECOVER_WINDOWS:
                speed *= SPEED_UP_FACTOR
        else:
            self._calm = 0
        if achieved is not None and 0 < achieved < min(speed, self.speed) * 0.95:
            speed = achieved          # the world itself cannot keep up: run at what it achieves
            self._calm = 0
        self.speed = min(self.target, max(MIN_SPEED, speed))
        return self.speed


Schedstat = Dict[int, Tuple[int, int, int]]


def read_schedstat(pids: Iterable[int]) -> Schedstat:
    """pid -> (ns run, ns waited in the run queue, time slices), summed over the process's threads;
    a process that is gone (or has no schedstat) is left out."""
    out: Schedstat = {}
    for pid in pids:
        run = wait = slices = 0
        try:
            for tid in os.listdir("/proc/%d/task" % pid):
                with open("/proc/%d/task/%s/schedstat" % (pid, tid)) as f:
                    fields = f.read().split()
                run, wait, slices = run + int(fields[0]), wait + int(fields[1]), slices + int(fields[2])
        except (OSError, ValueError, IndexError):
            continue
        out[pid] = (run, wait, slices)
    return out


def sibling_pids() -> List[int]:
    """The processes with this one's parent, but not this one: under roslaunch, the launch's other nodes."""
    me, parent = os.getpid(), os.getppid()
    out: List[int] = []
    try:
        names = os.listdir("/proc")
    except OSError:
        return out
    for name in names:
        if not name.isdigit() or int(name) == me:
            continue
        try:
            with open("/proc/%s/stat" % name) as f:
                stat = f.read()
            if int(stat[stat.rindex(")") + 2:].split()[1]) == parent:
                out.append(int(name))
        except (OSError, ValueError, IndexError):
            continue
    return out


class HostDelay:
    """The mean run-queue wait per time slice [s] of the host's processes between two ``sample`` calls.

    ``pids()`` names the host's processes (``sibling_pids``; re-read every ``refresh_s`` of ``now``,
    SIBLINGS_REFRESH_S by default); only processes seen in both samples count, so one that starts or
    ends adds nothing.
    None when there is nothing to judge (no host process, or none ran).
    """

    def __init__(self, pids: Callable[[], List[int]] = sibling_pids,
                 read: Callable[[Iterable[int]], Schedstat] = read_schedstat,
                 now: Callable[[], float] = time.monotonic, refresh_s: float = SIBLINGS_REFRESH_S) -> None:
        self._pids, self._read, self._now = pids, read, now
        self._refresh_s = refresh_s
        self._known: List[int] = []
        self._known_at = -math.inf
        self._last: Schedstat = {}
        self.processes = 0

    def sample(self) -> Optional[float]:
        t = self._now()
        if t - self._known_at >= self._refresh_s:
            self._known, self._known_at = list(self._pids()), t
        stats = self._read(self._known)
        wait = slices = 0
        for pid, (_, w, n) in stats.items():
            before = self._last.get(pid)
            if before is not None and n >= before[2]:
                wait, slices = wait + w - before[1], slices + n - before[2]
        self._last = stats
        self.processes = len(stats)
        return wait * 1e-9 / slices if slices > 0 else None


class AutoPacer:
    """Runs ``AutoSpeed`` on the host's run-queue waits (``HostDelay``) every SAMPLE_PERIOD_S and sets
    the world's speed (``world.set_speed``).

    The world counts as unable to keep its speed when it let go of a lag since the last sample
    (``overruns`` grew) or trails its schedule by more than BEHIND_TICKS; only then is its measured
    real-time factor (over the last second, so partly at the previous speed) passed on as ``achieved``.
    """

    def __init__(self, world, pacing: Pacing, host: Optional[HostDelay] = None) -> None:
        self.world = world
        self.pacing = pacing
        self.rule = AutoSpeed(pacing.target, start=pacing.target)
        self.host = host if host is not None else HostDelay()
        self.lag_wall_s = 0.0
        self.samples = 0
        self._overruns = int(getattr(world, "overruns", 0))
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def step(self) -> None:
        """One look at the host and the world; sets the world's speed when the rule changes it."""
        lag = self.host.sample()
        overruns = int(getattr(self.world, "overruns", 0))
        behind = overruns > self._overruns or int(getattr(self.world, "ticks_behind", 0)) > BEHIND_TICKS
        self._overruns = overruns
        achieved = (self.world.realtime_factor or None) if behind else None
        if lag is None and achieved is None:
            return
        self.lag_wall_s = lag if lag is not None else 0.0
        self.samples += 1
        speed = self.rule.update(self.lag_wall_s, achieved)
        if speed != self.world.speed:
            self.world.set_speed(speed)

    def _run(self) -> None:
        while not self._stop.wait(SAMPLE_PERIOD_S):
            try:
                self.step()
            except Exception:      # pacing must never take the world down
                _log.exception("world pacing failed; the world keeps speed %.2f", self.world.speed)

    def start(self) -> AutoPacer:
        self.host.sample()                       # the first reading: the next one is measured from it
        self._thread = threading.Thread(target=self._run, name="world-pacing", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)


def start_pacing(world, pacing: Pacing) -> Optional[AutoPacer]:
    """The pacer of an ``auto`` world (started; the world then catches up at most AUTO_MAX_LAG_S),
    None for a fixed one (whose speed the world has, catching up its schedule as far as it can)."""
    if not pacing.auto:
        return None
    world.max_lag_s = AUTO_MAX_LAG_S
    return AutoPacer(world, pacing).start()
