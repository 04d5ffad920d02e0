"""The figures behind ``/diagnostics`` for every Crazyflie and dongle, and their OK / WARN / ERROR.

ROS-free. Three kinds of pieces:

* recorders the server feeds as things happen, cheap and thread-safe: :class:`CrazyflieHealth` (the
  latest battery, supervisor and RSSI samples, when the last setpoint and pose went out) and
  :class:`Reports` (named entries any part of the server sets, e.g. a safety reaction, shown on
  ``/diagnostics`` and folded into the Crazyflie's ``status`` topic);
* :class:`CounterWindow`, which turns cumulative counters into differences over the last
  ``FIGURE_WINDOW_S`` s;
* pure functions from figures to an :class:`Entry` (level, message, values), unit-tested, with
  the thresholds of ``server.diagnostic_thresholds`` (docs/diagnostics.md).

The node publishes each entry as a ``diagnostic_msgs/DiagnosticStatus`` named
``crazyflie_server: <tf_prefix> <part>`` (levels are that message's numbers).
"""
from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass
from typing import Callable, Deque, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from crazyflie_driver.clock import WALL
from crazyflie_driver.protocol.supervisor import decode_state
from crazyflie_driver.server import diagnostic_thresholds as T
from crazyflie_driver.server.log_plan import BATTERY_TOPIC, POWER_STATE_TOPIC, RADIO_RSSI_TOPIC, SUPERVISOR_TOPIC

OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}

Values = Tuple[Tuple[str, str], ...]


@dataclass(frozen=True)
class Entry:
    """One line of ``/diagnostics``: ``part`` names it after the Crazyflie (``"link"``, ``"battery"``...)."""

    part: str
    level: int
    message: str
    values: Values = ()


def worst(levels: Iterable[int]) -> int:
    """The most severe level (STALE counts below WARN: it means "no figures yet")."""
    order = {OK: 0, STALE: 1, WARN: 2, ERROR: 3}
    best = OK
    for level in levels:
        if order.get(level, 3) > order[best]:
            best = level
    return best


BELOW, ABOVE = "below", "above"     # the side of its thresholds where a figure is bad (``graded``)


def graded(value: float, warn: float, error: float, reason: Union[str, Tuple[str, str]],
           direction: str = BELOW) -> Tuple[int, str]:
    """``value`` against a warning and an error threshold: (OK, "") when it is past neither, else (WARN
    or ERROR, why). ``direction`` is the side that is bad: BELOW (a ratio or a voltage, worse as it falls)
    or ABOVE (a time, a load). A value exactly at a threshold has not passed it. ``why`` is ``reason %
    {"value": value, "limit": the threshold passed}``; a pair of reasons gives the warning's and the error's.
    """
    if direction not in (BELOW, ABOVE):
        raise ValueError("direction must be BELOW or ABOVE, got %r" % (direction,))
    sign = 1.0 if direction == ABOVE else -1.0
    if sign * value > sign * error:
        level, limit = ERROR, error
    elif sign * value > sign * warn:
        level, limit = WARN, warn
    else:
        return OK, ""
    template = reason if isinstance(reason, str) else reason[level == ERROR]
    return level, template % {"value": value, "limit": limit}


def _values(pairs: Iterable[Tuple[str, object]]) -> Values:
    return tuple((k, v if isinstance(v, str) else str(v)) for k, v in pairs)


# ---------------------------------------------------------------------------------------------------
# recorders


class Reports:
    """Named entries that other parts of the server set and clear (any thread).

    Use: ``worker.reports.set("battery reaction", WARN, "battery 3.15 V: landing", (("vbat_V", "3.15"),))``;
    ``worker.reports.clear("battery reaction")``. Each shows on ``/diagnostics`` as
    ``crazyflie_server: <tf_prefix> <part>``; the worst of them raises the ``status`` topic's level
    and its message is added there. Setting the same entry again is cheap and publishes nothing new.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._entries: Dict[str, Entry] = {}

    def set(self, part: str, level: int, message: str, values: Iterable[Tuple[str, object]] = ()) -> None:
        if level not in LEVEL_NAMES:
            raise ValueError("level must be OK 0, WARN 1, ERROR 2 or STALE 3, got %r" % (level,))
        entry = Entry(part, level, message, _values(values))
        with self._lock:
            self._entries[part] = entry

    def clear(self, part: str) -> None:
        with self._lock:
            self._entries.pop(part, None)

    def entries(self) -> List[Entry]:
        with self._lock:
            return sorted(self._entries.values(), key=lambda e: e.part)


class CrazyflieHealth:
    """The latest samples of one Crazyflie that the diagnostics show; fed from the worker's thread
    (log packets) and the command paths (setpoints, poses). Times are ``clock()`` seconds."""

    def __init__(self, clock: Callable[[], float] = WALL.now) -> None:
        self.clock = clock
        self.vbat: Optional[float] = None
        self.pm_state: Optional[int] = None
        self.battery_at: Optional[float] = None
        self.supervisor_bits: Optional[int] = None
        self.supervisor_at: Optional[float] = None
        self.rssi_log: Optional[float] = None
        self.setpoint_at: Optional[float] = None
        self.pose_at: Optional[float] = None
        self.poses = 0

    def on_log(self, topic: str, values: Sequence[float], arrived: float) -> None:
        """A log topic's values (only the battery, power state, supervisor and RSSI topics are kept)."""
        if topic == BATTERY_TOPIC:
            self.vbat = float(values[0])
            self.battery_at = arrived
        elif topic == POWER_STATE_TOPIC:
            self.pm_state = int(values[0])
        elif topic == SUPERVISOR_TOPIC:
            self.supervisor_bits = int(values[0])
            self.supervisor_at = arrived
        elif topic == RADIO_RSSI_TOPIC:
            self.rssi_log = float(values[0])

    def setpoint_given(self) -> None:
        """A setpoint was handed to the worker (cmd_vel or a streaming setpoint topic)."""
        self.setpoint_at = self.clock()

    def pose_sent(self) -> None:
        """An external position or pose went out to this Crazyflie."""
        self.pose_at = self.clock()
        self.poses += 1


class CounterWindow:
    """Cumulative counters -> their growth over the last ``window_s`` s (the oldest snapshot kept that
    is at least that old; a shorter span until one is). Feed it every diagnostics period."""

    def __init__(self, window_s: float = T.FIGURE_WINDOW_S) -> None:
        self.window_s = window_s
        self._snaps: Deque[Tuple[float, Dict[str, float]]] = deque()

    def update(self, now: float, counters: Mapping[str, float]) -> Tuple[float, Dict[str, float]]:
        """Adds a snapshot; returns (span s, {name: growth over the span}); span 0 on the first call."""
        snaps = self._snaps
        snaps.append((now, dict(counters)))
        while len(snaps) > 2 and now - snaps[1][0] >= self.window_s:
            snaps.popleft()
        t0, old = snaps[0]
        return now - t0, {k: v - old.get(k, v) for k, v in counters.items()}

    def reset(self) -> None:
        self._snaps.clear()


# ---------------------------------------------------------------------------------------------------
# figures -> entries (pure)


@dataclass(frozen=True)
class LinkFigures:
    """One Crazyflie's link over the last ``span_s`` s (counts are growths over that span)."""

    span_s: float
    round_trips: int
    acked: int
    retries: int
    busy_s: float
    setpoints: int
    log_packets: int
    log_lost: int
    rssi: Optional[float] = None          # -dBm, latest
    state: str = "running"

    @property
    def ack_ratio(self) -> Optional[float]:
        return self.acked / self.round_trips if self.round_trips else None

    @property
    def mean_round_trip_s(self) -> Optional[float]:
        return self.busy_s / self.round_trips if self.round_trips else None

    @property
    def log_receive_ratio(self) -> Optional[float]:
        due = self.log_packets + self.log_lost
        return self.log_packets / due if due else None

    def per_s(self, count: float) -> float:
        return count / self.span_s if self.span_s > 0 else 0.0


def ack_ratio_tolerance(ratio: float, samples: int, sigmas: float = 4.0) -> float:
    """How far an ack ratio counted over ``samples`` independent round trips may fall from the true
    one: ``sigmas`` binomial standard deviations (for tests and for reading the figures)."""
    if samples <= 0:
        return 1.0
    p = min(max(ratio, 0.0), 1.0)
    return sigmas * math.sqrt(max(p * (1.0 - p), 1.0 / samples) / samples)


def link_entry(f: LinkFigures) -> Entry:
    """Ack ratio, round-trip time and log receive ratio against their thresholds."""
    level, why = OK, []
    if f.state != "running":
        level = worst([level, ERROR if f.state in ("lost", "failed", "restarting") else STALE])
        why.append("link %s" % f.state)
    for grade, reason in _link_grades(f):
        if grade != OK:
            level = worst([level, grade])
            why.append(reason)
    if f.round_trips == 0 and f.span_s > 0 and f.state == "running":
        level = worst([level, WARN])
        why.append("no round trips")
    summary = _link_summary(f)
    message = "; ".join(why) if why else summary
    if why:
        message += " (%s)" % summary
    return Entry("link", level, message, _link_values(f))


def _link_grades(f: LinkFigures) -> List[Tuple[int, str]]:
    """(level, reason) of each link figure with enough samples to judge: ack ratio and round trip once
    ``MIN_ROUND_TRIPS`` counted, log receive ratio once ``MIN_LOG_PACKETS`` were due."""
    grades = []
    ack, rtt, rx = f.ack_ratio, f.mean_round_trip_s, f.log_receive_ratio
    if f.round_trips >= T.MIN_ROUND_TRIPS:
        if ack is not None:
            grades.append(graded(ack, T.ACK_RATIO_WARN, T.ACK_RATIO_ERROR, "ack ratio %(value).2f < %(limit).2f"))
        if rtt is not None:
            grades.append(graded(rtt * 1e3, T.ROUND_TRIP_WARN_S * 1e3, T.ROUND_TRIP_ERROR_S * 1e3,
                                 "round trip %(value).1f ms > %(limit).0f ms", ABOVE))
    if rx is not None and f.log_packets + f.log_lost >= T.MIN_LOG_PACKETS:
        grades.append(graded(rx, T.LOG_RECEIVE_RATIO_WARN, T.LOG_RECEIVE_RATIO_ERROR,
                             "log packets received %(value).2f < %(limit).2f"))
    return grades


def _link_summary(f: LinkFigures) -> str:
    """The link in one phrase: ack ratio, round trips per second, mean round trip."""
    if f.ack_ratio is None:
        return "no round trips counted yet"
    return "ack %.2f, %.0f round trips/s, %.1f ms" % (f.ack_ratio, f.per_s(f.round_trips),
                                                       (f.mean_round_trip_s or 0.0) * 1e3)


def _link_values(f: LinkFigures) -> Values:
    """The link's figures for ``/diagnostics``, ``n/a`` where there is nothing to divide."""
    ack, rtt, rx = f.ack_ratio, f.mean_round_trip_s, f.log_receive_ratio
    na = "n/a"
    return _values((
        ("ack ratio", "%.3f" % ack if ack is not None else na),
        ("round trips", f.round_trips),
        ("window [s]", "%.2f" % f.span_s),
        ("round trips/s", "%.1f" % f.per_s(f.round_trips)),
        ("retries per acked packet", "%.2f" % (f.retries / f.acked) if f.acked else na),
        ("mean round trip [ms]", "%.2f" % (rtt * 1e3) if rtt is not None else na),
        ("RSSI [-dBm]", "%.0f" % f.rssi if f.rssi is not None else na),
        ("setpoints/s", "%.1f" % f.per_s(f.setpoints)),
        ("log packets/s", "%.1f" % f.per_s(f.log_packets)),
        ("log packets lost", f.log_lost),
        ("log receive ratio", "%.3f" % rx if rx is not None else na),
    ))


def battery_entry(vbat: Optional[float], pm_state: Optional[int], age_s: Optional[float],
                  logging_on: bool = True) -> Entry:
    """Voltage, the firmware's power state and the sample's age."""
    if vbat is None:
        return Entry("battery", STALE if logging_on else OK,
                     "no battery sample yet" if logging_on else "n/a (logging off)", ())
    state_name = pm_state_name(pm_state)
    level, reason = graded(vbat, T.BATTERY_WARN_V, T.BATTERY_CRITICAL_V,
                           ("%(value).2f V < %(limit).1f V (low)", "%(value).2f V < %(limit).1f V (critical)"))
    why = [reason] if reason else []
    if pm_state == T.PM_STATE_SHUTDOWN:
        level = worst([level, ERROR])
        why.append("power state: shutdown")
    elif pm_state == T.PM_STATE_LOW_POWER:
        level = worst([level, WARN])
        why.append("power state: low power")
    if age_s is not None and age_s > T.BATTERY_SAMPLE_STALE_S:
        level = worst([level, WARN])
        why.append("last sample %.1f s old" % age_s)
    message = "; ".join(why) if why else "%.2f V, %s" % (vbat, state_name)
    values = _values((("voltage [V]", "%.3f" % vbat), ("pm.state", state_name),
                      ("sample age [s]", "%.2f" % age_s if age_s is not None else "n/a")))
    return Entry("battery", level, message, values)


def pm_state_name(state: Optional[int]) -> str:
    """``3`` -> ``"3 (low power)"``."""
    if state is None:
        return "n/a"
    return "%d (%s)" % (state, T.PM_STATES.get(state, "unknown"))


def supervisor_entry(bits: Optional[int], age_s: Optional[float], available: bool,
                     why_not: str = "this firmware has no supervisor state") -> Entry:
    """The supervisor's state (current firmware: ``supervisor.info``); "n/a" where there is none."""
    if not available:
        return Entry("supervisor", OK, "n/a (%s)" % why_not, (("state", "n/a"),))
    if bits is None:
        return Entry("supervisor", STALE, "no supervisor sample yet", ())
    flags = decode_state(bits).flags
    on = [name for name, set_ in flags.items() if set_]
    level, why = OK, []
    if flags["locked"]:
        level = ERROR
        why.append("locked: restart the Crazyflie to fly again")
    if flags["crashed"]:
        level = worst([level, ERROR])
        why.append("crashed")
    if flags["tumbled"]:
        level = worst([level, WARN])
        why.append("tumbled")
    if age_s is not None and age_s > T.BATTERY_SAMPLE_STALE_S:
        level = worst([level, WARN])
        why.append("last sample %.1f s old" % age_s)
    message = "; ".join(why) if why else (", ".join(on) or "idle")
    values = _values((("bits", "0x%04X" % bits), ("flags", ", ".join(on) or "none"),
                      ("sample age [s]", "%.2f" % age_s if age_s is not None else "n/a")))
    return Entry("supervisor", level, message, values)


def commands_entry(setpoint_age_s: Optional[float], pose_age_s: Optional[float], poses: int) -> Entry:
    """Ages of the last setpoint handed to the worker and of the last pose sent."""
    level, why = OK, []
    if pose_age_s is not None and pose_age_s > T.POSE_AGE_WARN_S:
        level = WARN
        why.append("no pose sent for %.1f s (after %d)" % (pose_age_s, poses))

    def age(a: Optional[float]) -> str:
        return "%.3f" % a if a is not None else "never"
    message = "; ".join(why) if why else "last setpoint %s s ago, last pose %s s ago" % (
        age(setpoint_age_s), age(pose_age_s))
    return Entry("commands", level, message, _values((
        ("setpoint age [s]", age(setpoint_age_s)), ("pose age [s]", age(pose_age_s)), ("poses sent", poses))))


@dataclass(frozen=True)
class RadioFigures:
    """One dongle over the last ``span_s`` s."""

    index: int
    span_s: float
    round_trips_per_s: float               # its Crazyflies' round trips together
    broadcasts: int                        # broadcast packets over the span
    crazyflies: Tuple[str, ...]
    capacity_per_s: float                  # round trips/s this dongle can carry as it is shared
    planned_load: Optional[float] = None   # the radio budget's share of the capacity, if known
    advice: str = ""


    @property
    def broadcasts_per_s(self) -> float:
        return self.broadcasts / self.span_s if self.span_s > 0 else 0.0

    @property
    def load(self) -> float:
        """Share of the modelled capacity in use (round trips and broadcasts)."""
        return ((self.round_trips_per_s + self.broadcasts_per_s) / self.capacity_per_s
                if self.capacity_per_s > 0 else 0.0)


def radio_entry(f: RadioFigures) -> Entry:
    """Round trips and broadcasts per second against the dongle's modelled capacity."""
    rt_s = f.round_trips_per_s
    bc_s = f.broadcasts_per_s
    load = f.load
    level, why = OK, []
    if f.planned_load is not None:
        level, reason = graded(f.planned_load * 100, T.RADIO_LOAD_WARN * 100, T.RADIO_LOAD_ERROR * 100,
                               "planned load %(value).0f %% of capacity", ABOVE)
        why = [reason] if reason else []
    if load > T.RADIO_LOAD_WARN:
        level = worst([level, WARN])
        why.append("in use %.0f %% of capacity" % (load * 100))
    summary = "%.0f round trips/s + %.0f broadcasts/s of %.0f/s (%.0f %%), %d Crazyflie(s)" % (
        rt_s, bc_s, f.capacity_per_s, load * 100, len(f.crazyflies))
    message = "; ".join(why) + " (%s)" % summary if why else summary
    if why and f.advice:
        message += ": " + f.advice
    values = _values((
        ("round trips/s", "%.1f" % rt_s), ("broadcasts/s", "%.1f" % bc_s),
        ("capacity [round trips/s]", "%.0f" % f.capacity_per_s), ("load", "%.2f" % load),
        ("planned load", "%.2f" % f.planned_load if f.planned_load is not None else "n/a"),
        ("crazyflies", ", ".join(f.crazyflies)), ("window [s]", "%.2f" % f.span_s)))
    return Entry("radio %d" % f.index, level, message, values)


@dataclass(frozen=True)
class BottleneckFigures:
    """What may limit the data flow, as the server sees it (None: not known)."""

    world_speed_share: Optional[float] = None   # simulated world: its real-time factor over its speed
    loop_lag_s: Optional[float] = None          # the server's own periodic timer: how late it woke (host CPU)
    radio_loads: Tuple[Tuple[int, float], ...] = ()     # (dongle, measured share of its modelled capacity)


#: Said where data arrives late, until a bottleneck entry has named what limits it.
UNKNOWN_BOTTLENECK = ("the simulated world, the host's CPU or the radio falls behind (the bottleneck entry of "
                      "/diagnostics names which)")


def bottleneck_entry(f: BottleneckFigures) -> Entry:
    """The bottleneck it sees, in this order: a simulated world behind real time (everything that follows its
    clock is late by that factor, whatever the radios carry), the host's CPU (the server's timers wake late),
    a radio near its capacity; OK when none is. Each with the figures of the others and what to do."""
    busiest = max(f.radio_loads, key=lambda r: r[1]) if f.radio_loads else None
    radios = ("radio load %s" % ", ".join("%d: %.0f %%" % (i, 100 * load) for i, load in f.radio_loads)
              if f.radio_loads else "no radio figures yet")
    lag = "server timer lag %.0f ms" % (1000 * f.loop_lag_s) if f.loop_lag_s is not None else "no timer lag yet"
    world = ("world at %.2f of its speed" % f.world_speed_share if f.world_speed_share is not None
             else "no simulated world figures")
    figures = "; ".join((world, lag, radios))
    if f.world_speed_share is not None and f.world_speed_share < T.WORLD_BEHIND_FACTOR:
        level, message = WARN, ("the simulated world: it runs at %.2f of its speed, so the Crazyflies' data and "
                                "the motion capture come that much slower, whatever the radios carry (give it "
                                "a core: fewer processes on this host, or a lower world speed)" % f.world_speed_share)
    elif f.loop_lag_s is not None and f.loop_lag_s > T.LOOP_LAG_WARN_S:
        level, message = WARN, ("the host's CPU: crazyflie_server's timers wake %.0f ms late, so it polls and "
                                "publishes late (fewer processes on this host)" % (1000 * f.loop_lag_s))
    elif busiest is not None and busiest[1] > T.RADIO_LOAD_WARN:
        level, message = WARN, ("radio %d: in use %.0f %% of its capacity (fewer Crazyflies on it, longer log "
                                "periods or enable_logging false)" % (busiest[0], 100 * busiest[1]))
    else:
        return Entry("bottleneck", OK, "none seen (%s)" % figures, _bottleneck_values(f))
    return Entry("bottleneck", level, "%s (%s)" % (message, figures), _bottleneck_values(f))


def _bottleneck_values(f: BottleneckFigures) -> Values:
    na = "n/a"
    return _values([("world speed share", "%.3f" % f.world_speed_share if f.world_speed_share is not None else na),
                    ("server timer lag [s]", "%.3f" % f.loop_lag_s if f.loop_lag_s is not None else na)]
                   + [("radio %d load" % i, "%.2f" % load) for i, load in f.radio_loads])


def world_speed_share(values: Mapping[str, str]) -> Optional[float]:
    """The simulated world's real-time factor over its speed, from its /diagnostics values ("real-time factor",
    "speed"); None when they are missing or the world runs as fast as it can (speed 0)."""
    try:
        factor, speed = float(values["real-time factor"]), float(values["speed"])
    except (KeyError, ValueError):
        return None
    return factor / speed if speed > 0 and math.isfinite(factor) else None


# ---------------------------------------------------------------------------------------------------
# one served Crazyflie -> its entries (reads a worker; the node calls it every period)


class CrazyflieDiagnostics:
    """The entries of one served Crazyflie, from its worker: link, battery, supervisor, commands, and
    whatever its ``reports`` hold. Keeps the counter window between calls."""

    def __init__(self, window_s: float = T.FIGURE_WINDOW_S) -> None:
        self.window = CounterWindow(window_s)
        self.link: Optional[LinkFigures] = None     # the latest figures (the radio entries sum them)

    def entries(self, worker) -> List[Entry]:
        health: CrazyflieHealth = worker.health
        now = health.clock()
        stats = worker.cf.link.stats
        span, d = self.window.update(now, {
            "sent": stats.sent, "acked": stats.acked, "retries": stats.retries_total, "busy": stats.busy_s,
            "setpoints": worker.setpoints_sent, "log": worker.log_packets_received,
            "lost": worker.lost_log_packets()})
        rssi = stats.rssi if stats.rssi is not None else health.rssi_log
        self.link = LinkFigures(span, int(d["sent"]), int(d["acked"]), int(d["retries"]), d["busy"],
                                int(d["setpoints"]), int(d["log"]), max(0, int(d["lost"])), rssi, worker.state)
        age = (lambda t: None if t is None else max(0.0, now - t))
        logging_on = bool(worker.config.enable_logging)
        return [link_entry(self.link),
                battery_entry(health.vbat, health.pm_state, age(health.battery_at), logging_on),
                supervisor_entry(health.supervisor_bits, age(health.supervisor_at),
                                 SUPERVISOR_TOPIC in worker.log_topics,
                                 "this firmware has no supervisor state" if logging_on else "logging off"),
                commands_entry(age(health.setpoint_at), age(health.pose_at), health.poses)] + worker.reports.entries()
