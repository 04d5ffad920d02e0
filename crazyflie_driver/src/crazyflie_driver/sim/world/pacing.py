"""How fast the simulated world runs: a fixed factor of real time, or ``auto``: slower while the host lags.

In simulation the host's nodes time everything on ROS time, which is the world's time (``/clock``).
A world that runs at a speed the machine cannot serve leaves the host late *in world time*: its
100 Hz loops fire late, its setpoints and external positions reach the Crazyflie late, and the
flight gets worse. ``speed:=auto`` slows the world down while that happens and returns to real
time when the host has caught up, so a busy machine makes a flight slower, not worse.

What "the host lags" means here (docs/simulation.md, "World pacing"): a thread at the host nodes'
priority that asks to wake up every ``PROBE_PERIOD_S`` measures how late it wakes
(``LagProbe``, a small process of its own at normal niceness, so neither the world's raised
priority nor its interpreter lock flatters or spoils the figure). That lateness is what every host
loop suffers on top of its own work; multiplied by the world's speed it is the lateness in world
time. ``AutoSpeed`` keeps the 90th percentile of it below ``LAG_BOUND_S``. The figure depends on the
machine's scheduler only, never on what a client sends, so a deliberate silence (a watchdog test,
a killed controller) cannot look like lag. Where the world itself cannot keep up with its speed,
``auto`` also takes the speed it achieves.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
from dataclasses import dataclass
from typing import Callable, List, Optional

AUTO = "auto"
MIN_SPEED = 0.1
"""Slowest an ``auto`` world runs [world s per wall s]; below this a simulation is no longer usable."""
PROBE_PERIOD_S = 0.005
"""Wall seconds [s] the lag probe sleeps between wake-ups (200 wake-ups/s: about 0.5 % of a core)."""
PROBE_WINDOW = 100
"""Wake-ups per lag sample (0.5 s of wall time at PROBE_PERIOD_S)."""
LAG_PERCENTILE = 0.9
"""Which percentile of a window's lateness counts (most host loops, not the single worst one)."""
LAG_BOUND_S = 0.002
"""World seconds [s] a host wake-up may be late (90th percentile) before ``auto`` slows the world:
a fifth of a 100 Hz control period."""
RECOVER_BELOW_S = 0.0008
"""World seconds [s] of lateness below which ``auto`` speeds the world up again."""
RECOVER_WINDOWS = 2
"""Consecutive calm samples before ``auto`` speeds up (it slows down at once)."""
SPEED_UP_FACTOR = 1.15
"""Per calm sample, ``auto`` speeds the world up by this factor (up to its target)."""
MAX_SLOW_DOWN = 0.5
"""Per laggy sample, ``auto`` at most halves the speed."""
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

    ``update(lag_wall_s, achieved)``: ``lag_wall_s`` the probe's percentile lateness [wall s] over
    its last window; ``achieved`` the world's measured real-time factor (None: not known). The
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


def percentile(values: List[float], p: float) -> float:
    """The ``p`` (0..1) percentile of ``values`` (nearest rank); 0.0 for none."""
    if not values:
        return 0.0
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, int(math.ceil(p * len(ordered))) - 1))]


# The probe process: sleeps PERIOD, prints the window's lateness percentile and maximum [s] per line;
# ends when its parent is gone (its stdout breaks or it is re-parented).
_PROBE_SOURCE = r"""
import math, os, sys, time
period, window, p, nice = float(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
try:
    os.setpriority(os.PRIO_PROCESS, 0, nice)
except OSError:
    pass
parent = os.getppid()
while os.getppid() == parent:
    late = []
    for _ in range(window):
        t0 = time.monotonic()
        time.sleep(period)
        late.append(time.monotonic() - t0 - period)
    late.sort()
    k = min(len(late) - 1, max(0, int(math.ceil(p * len(late))) - 1))
    try:
        sys.stdout.write("%.6f %.6f\n" % (max(0.0, late[k]), max(0.0, late[-1])))
        sys.stdout.flush()
    except (BrokenPipeError, OSError):
        break
"""


class LagProbe:
    """A process at the host nodes' niceness (``nice``) that reports how late it wakes up.

    ``on_sample(percentile_s, max_s)`` is called from a reader thread once per window. ``stop``
    ends it. The process is tiny (a sleep loop) and leaves by itself when this one is gone.
    """

    def __init__(self, on_sample: Callable[[float, float], None], nice: int = 0,
                 period_s: float = PROBE_PERIOD_S, window: int = PROBE_WINDOW,
                 percentile_p: float = LAG_PERCENTILE) -> None:
        self._on_sample = on_sample
        self._args = [repr(float(period_s)), str(int(window)), repr(float(percentile_p)), str(int(nice))]
        self._proc: Optional[subprocess.Popen] = None
        self._thread: Optional[threading.Thread] = None

    def start(self) -> "LagProbe":
        self._proc = subprocess.Popen([sys.executable, "-c", _PROBE_SOURCE] + self._args, stdin=subprocess.DEVNULL,
                                      stdout=subprocess.PIPE, close_fds=True, env=dict(os.environ))
        self._thread = threading.Thread(target=self._read, name="lag-probe", daemon=True)
        self._thread.start()
        return self

    def _read(self) -> None:
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        for line in proc.stdout:
            parts = line.split()
            if len(parts) == 2:
                self._on_sample(float(parts[0]), float(parts[1]))

    def stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(1.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(1.0)
        if proc is not None and proc.stdout is not None:
            proc.stdout.close()


class AutoPacer:
    """Runs ``AutoSpeed`` on a ``LagProbe`` and sets the world's speed (``world.set_speed``).

    The world counts as unable to keep its speed when it let go of a lag since the last sample
    (``overruns`` grew) or trails its schedule by more than BEHIND_TICKS; only then is its measured
    real-time factor (over the last second, so partly at the previous speed) passed on as ``achieved``.
    """

    def __init__(self, world, pacing: Pacing, nice: int = 0) -> None:
        self.world = world
        self.pacing = pacing
        self.rule = AutoSpeed(pacing.target, start=pacing.target)
        self.lag_wall_s = 0.0
        self.lag_max_s = 0.0
        self.samples = 0
        self._overruns = int(getattr(world, "overruns", 0))
        self._probe = LagProbe(self._sample, nice=nice)

    def _sample(self, lag_s: float, lag_max_s: float) -> None:
        overruns = int(getattr(self.world, "overruns", 0))
        behind = overruns > self._overruns or int(getattr(self.world, "ticks_behind", 0)) > BEHIND_TICKS
        self._overruns = overruns
        achieved = (self.world.realtime_factor or None) if behind else None
        self.lag_wall_s, self.lag_max_s = lag_s, lag_max_s
        self.samples += 1
        speed = self.rule.update(lag_s, achieved)
        if speed != self.world.speed:
            self.world.set_speed(speed)

    def start(self) -> "AutoPacer":
        self._probe.start()
        return self

    def stop(self) -> None:
        self._probe.stop()


def start_pacing(world, pacing: Pacing, nice: int = 0) -> Optional[AutoPacer]:
    """The pacer of an ``auto`` world (started), None for a fixed one (whose speed the world has)."""
    if not pacing.auto:
        return None
    return AutoPacer(world, pacing, nice).start()
