"""Safety reactions of ``crazyflie_server``: pure decisions from figures and time, without ROS or radio.

One :class:`SafetyMonitor` per Crazyflie is told what the server sends and receives (setpoints and
their thrust, poses, high-level commands, battery voltage) and, when polled, says what to do
instead of the user's stream (:class:`Action`); the worker only carries the actions out. The
reactions (docs/safety.md has the figures and why):

* setpoint source silent while flying (``setpoint_silence_s``): with onboard control (a firmware
  with the high-level commander and a position estimate: streaming port-7 setpoints, the
  high-level commander in use, or the Kalman estimator fed by poses) the high-level commander
  lands in place; without it (RPYT only, the chapter's path) the Crazyflie holds level at its
  hover thrust, then descends open loop at a bounded rate (:class:`DescentPlan`) and stops its
  motors once the highest expected flight is on the floor;
* battery below ``battery_warning_v`` for ``battery_persist_s``: warn once; below
  ``battery_critical_v``: the same landing or descent;
* host shutdown: the same landing or descent for every Crazyflie in the air, within a budget.

A landing under way (any of these, the shutdown's or a removal's, or a land command's) is never
cancelled by a command that does not itself land: :meth:`SafetyMonitor.refusal` says why a takeoff,
go_to or start_trajectory must not go out, and one that went out anyway (a broadcast, a race) makes
the reaction land again from where the Crazyflie is. :func:`checked_landing` refuses a land command
that would drop the Crazyflie. An emergency stop (or the supervisor's lock) ends whatever the
monitor believed flew: nothing is left to land.

The emergency-stop watchdog keep-alive (``emergency_watchdog``) is only a switch here; the worker
sends it. Every reaction is logged once with its reason and stays in :meth:`SafetyMonitor.report`.
"""
from __future__ import annotations

import logging
import math
import threading
from collections import deque
from dataclasses import dataclass, fields
from typing import Any, Callable, Deque, Dict, List, NamedTuple, Optional, Tuple

from crazyflie_driver.crtp.firmware_limits import MAX_THRUST
from crazyflie_driver.errors import CommandValueError
from crazyflie_driver.protocol.checks import finite, positive_duration
from crazyflie_driver.protocol.high_level import HIGH_LEVEL_FROM

LOG = logging.getLogger("crazyflie_driver.server.safety")

GRAVITY = 9.81                  # m/s²
#: The firmware treats an RPYT thrust below this as zero: a setpoint below it is "on the ground".
MIN_FLYING_THRUST = 1000
#: Near hover, thrust grows with the command to this power (27 g at 36 344, 32 g at 40 922 on the
#: Crazyflie 2.0's thrust map: ln(32/27) / ln(40922/36344) ≈ 1.4); turns an acceleration into counts.
THRUST_EXPONENT = 1.4
HOVER_WINDOW_S = 1.0            # s of setpoints averaged for the hover thrust
ACCEL_PHASE_MS2 = 1.0           # m/s², downward acceleration that starts a descent
ESTIMATOR_KALMAN = 2            # ``stabilizer.estimator`` value of the Kalman estimator
POSE_FRESH_S = 1.0              # s: a pose sent more recently than this feeds the onboard estimator
MIN_LAND_S = 1.0                # s: shortest onboard landing
#: s after the planned end of a land command (the user's or the swarm's) before it counts as over: the
#: firmware's planner ends such a landing itself (motors off at the plan's end).
LAND_OVER_AFTER_S = 0.5
#: The reaction's own landing flies down with the high-level commander (a go_to to the floor, which the
#: planner holds) and stops the motors only once the Crazyflie rests: when the pose sent to its estimator
#: is this low (m) ...
LANDED_Z_M = 0.02
#: ... or, without a fresh pose, this long (s) after the plan's end (about 4 time constants of the
#: firmware's z position loop, 0.5 s) ...
LAND_SETTLE_S = 2.0
#: ... and at the latest this long (s) after the plan's end (a floor above z = 0, a pose offset).
LAND_GIVE_UP_S = 4.0
OFF_REPEATS = 3                 # zero-thrust setpoints that end a reaction (one may be lost)
#: m a land command's target may lie above the Crazyflie's last known height (pose noise; a drop of a few
#: centimetres at the end). Higher, the firmware climbs there, then stops the motors at the plan's end.
LAND_CLIMB_TOLERANCE_M = 0.05
#: High-level commands that fly: none of them may cancel a landing under way.
FLYING_COMMANDS = frozenset(("takeoff", "go_to", "start_trajectory"))

OK, WARN, ERROR = 0, 1, 2       # same numbers as server.status and diagnostic_msgs


@dataclass(frozen=True)
class SafetyConfig:
    """The server parameters of the reactions (``~safety/<name>``); defaults in the driver README."""

    setpoint_silence: bool = True       # react when the setpoint stream stops while flying
    setpoint_silence_s: float = 0.3     # s without a setpoint that counts as silence
    hold_s: float = 0.3                 # s of level hold before the descent; a setpoint meanwhile resumes
    descent_rate: float = 0.3           # m/s: descent speed (open loop) and onboard landing speed
    descent_max_height: float = 2.0     # m: highest flight the open-loop descent must bring down
    battery: bool = True                # warn / land on a low battery
    battery_warning_v: float = 3.45     # V, measured (in flight: under load)
    battery_critical_v: float = 3.30    # V
    battery_persist_s: float = 2.0      # s below a threshold before it counts
    land_on_shutdown: bool = True       # land or descend every Crazyflie in the air on shutdown
    shutdown_timeout_s: float = 10.0    # s the server may spend on that (roslaunch escalates after 15 s)
    emergency_watchdog: bool = False    # send the emergency-stop watchdog keep-alive

    @classmethod
    def off(cls) -> SafetyConfig:
        """No reaction at all (the library's default: a worker without a server does what it is told)."""
        return cls(setpoint_silence=False, battery=False, land_on_shutdown=False)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type in ("bool", bool):
                if not isinstance(value, bool):
                    raise ValueError("safety/%s must be true or false, got %r" % (f.name, value))
            elif isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value <= 0:
                raise ValueError("safety/%s must be a positive number, got %r" % (f.name, value))
        if self.battery_critical_v >= self.battery_warning_v:
            raise ValueError("safety/battery_critical_v (%g V) must be below safety/battery_warning_v (%g V)"
                             % (self.battery_critical_v, self.battery_warning_v))

    @classmethod
    def from_params(cls, get: Callable[[str, Any], Any], prefix: str = "safety/") -> SafetyConfig:
        """Each field from ``get(prefix + name, default)`` (e.g. ``rospy.get_param`` with ``~safety/``)."""
        values = {}
        for f in fields(cls):
            value = get(prefix + f.name, f.default)
            if isinstance(f.default, float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            values[f.name] = value
        return cls(**values)


def checked_landing(height: float, duration_s: float, current_z: Optional[float] = None,
                    who: str = "") -> Tuple[float, float]:
    """(height m, duration s) of a land command that brings the Crazyflie down, else CommandValueError
    naming what was refused. The firmware stops the motors at the end of a landing plan wherever the
    Crazyflie is: a duration of 0 stops them at once, in the air, and a target above ``current_z``
    (its last known height, m; None: unknown, not checked) is a climb and then a fall."""
    where = who + ": " if who else ""
    height = finite("height", height)
    try:
        duration = positive_duration(duration_s)
    except CommandValueError as e:
        raise CommandValueError("%sland refused: %s: the firmware stops the motors at the end of the landing "
                                "plan, so a landing of no time drops the Crazyflie from where it is; give it the "
                                "time to come down (about %.1f s per metre)"
                                % (where, e, 1.0 / SafetyConfig.descent_rate)) from e
    if current_z is not None and height > current_z + LAND_CLIMB_TOLERANCE_M:
        raise CommandValueError("%sland refused: target height %.2f m is above the Crazyflie (%.2f m): it would climb "
                                "there, then stop its motors and fall; land to the floor (height 0) and use go_to to "
                                "go up" % (where, height, current_z))
    return height, duration


def thrust_change_for(accel: float, hover_thrust: float) -> float:
    """Counts to add to ``hover_thrust`` for a vertical acceleration ``accel`` (m/s², small)."""
    return hover_thrust * accel / (THRUST_EXPONENT * GRAVITY)


class DescentPlan:
    """Open-loop descent from a hover thrust, without a height measurement.

    After ``hold_s`` level at the hover thrust, ``ACCEL_PHASE_MS2`` down until the speed is
    ``rate``; then a small deficit (the speed grows to at most twice ``rate`` over the whole
    descent) keeps it sinking, so the floor is reached from ``max_height`` within the plan and the
    Crazyflie rests there (thrust below its weight). Then motors off (:meth:`thrust_at` None).
    """

    def __init__(self, hover_thrust: float, rate: float, max_height: float, hold_s: float) -> None:
        self.hover = float(hover_thrust)
        self.hold_s = float(hold_s)
        self.accel_s = rate / ACCEL_PHASE_MS2
        self.coast_s = max_height / rate
        self.accel_thrust = self.hover - thrust_change_for(ACCEL_PHASE_MS2, self.hover)
        self.coast_thrust = self.hover - thrust_change_for(rate / self.coast_s, self.hover)
        self.duration = self.hold_s + self.accel_s + self.coast_s

    def thrust_at(self, t: float) -> Optional[int]:
        """The thrust ``t`` s after the plan started, or None when the motors go off."""
        if t < self.hold_s:
            u = self.hover
        elif t < self.hold_s + self.accel_s:
            u = self.accel_thrust
        elif t < self.duration:
            u = self.coast_thrust
        else:
            return None
        return int(min(max(u, 0.0), float(MAX_THRUST)))


class BatteryWatch:
    """Battery level from voltage samples: a threshold counts once every sample of the last
    ``persist_s`` is below it (a climb's short sag does not). Levels only go down."""

    def __init__(self, warning_v: float, critical_v: float, persist_s: float) -> None:
        self.warning_v, self.critical_v, self.persist_s = warning_v, critical_v, persist_s
        self.level = OK
        self.volts = float("nan")
        self.sampled_at = -math.inf
        self._samples: Deque[Tuple[float, float]] = deque()

    def update(self, now: float, volts: float) -> Optional[int]:
        """A new sample; returns the new level (WARN or ERROR) when it just dropped, else None."""
        if not math.isfinite(volts) or volts <= 0.0:
            return None
        self.volts, self.sampled_at = float(volts), now
        self._samples.append((now, float(volts)))
        while len(self._samples) > 1 and self._samples[1][0] <= now - self.persist_s:
            self._samples.popleft()
        if now - self._samples[0][0] < self.persist_s:
            return None
        highest = max(v for _, v in self._samples)
        level = ERROR if highest < self.critical_v else WARN if highest < self.warning_v else OK
        if level > self.level:
            self.level = level
            return level
        return None


class Action(NamedTuple):
    """What the worker sends instead of the user's stream this round trip.

    ``kind``: ``"thrust"`` (RPYT level at ``thrust``), ``"land"`` (the high-level commander down by
    ``distance`` m in ``duration`` s, then notify-setpoints-stop), ``"hl_stop"`` (high-level stop: motors
    off), ``"off"`` (motors off by a zero-thrust RPYT).
    """

    kind: str
    thrust: int = 0
    duration: float = 0.0
    distance: float = 0.0


class Reaction:
    """The reaction under way: why, how, since when."""

    NONE = ""
    HOLD = "hold"           # silence: level at hover thrust; a new setpoint resumes the stream
    DESCENT = "descent"     # open-loop descent, then motors off
    LANDING = "landing"     # onboard landing by the high-level commander
    DOWN = "down"           # a reaction ended with the motors off


class SafetyMonitor:
    """The reactions of one Crazyflie; thread safe for notes, polled by the worker's thread.

    ``protocol_version()`` and ``params()`` are narrow callables into the worker (the firmware's
    protocol version and its parameter values as last read or written).
    """

    def __init__(self, config: SafetyConfig, label: str = "",
                 protocol_version: Callable[[], int] = lambda: -1,
                 params: Callable[[], Any] = dict) -> None:
        self.config = config
        self.label = label
        self._protocol_version = protocol_version
        self._params = params
        self._lock = threading.Lock()
        self.battery = BatteryWatch(config.battery_warning_v, config.battery_critical_v, config.battery_persist_s)
        self.reaction = Reaction.NONE
        self.reason = ""                        # why the current (or last) reaction started
        self.events: List[str] = []             # every reaction and warning, once each, in order
        self.ignored_setpoints = 0
        self._thrusts: Deque[Tuple[float, int]] = deque()
        self._last_setpoint_at: Optional[float] = None
        self._stream = ""                       # "rpyt", "generic" (port 7) or "" (none / released)
        self._flying = False
        self._hl_flying = False
        self._hl_used = False
        self._pose_at = -math.inf
        self._pose_z: Optional[float] = None
        self._started_at = 0.0
        self._plan: Optional[DescentPlan] = None
        self._land_until = 0.0
        self._deadline = math.inf               # shutdown: motors off by then
        self._pending_land: Optional[float] = None
        self._land_distance = 0.0
        self._own_landing = False               # the reaction's go_to (it stops the motors) or a land command
        self._battery_critical_pending = False
        self._shutdown = False
        self._said_ignored = False
        self._offs_left = 0                     # zero-thrust setpoints still to send after a reaction
        self._offs_sent = True                  # and the last of them went out (the worker polled again)
        self._motors_off_by = ""                # why the motors are off, when something else stopped them
        self._stopped_for_good = False          # by an emergency stop: nothing of the user's counts any more

    # ------------------------------------------------------------------ notes (any thread)

    def configure(self, config: SafetyConfig) -> None:
        with self._lock:
            self.config = config
            self.battery = BatteryWatch(config.battery_warning_v, config.battery_critical_v,
                                        config.battery_persist_s)

    def note_setpoint(self, now: float, thrust: Optional[int], stop: bool = False) -> bool:
        """A setpoint from the user: RPYT ``thrust``, or a port-7 packet (``thrust`` None; ``stop``
        for the stop type). False when a reaction holds the Crazyflie and the setpoint is dropped; a
        motors-off setpoint (zero thrust, stop) ends a reaction and goes out."""
        with self._lock:
            if not self._admit_setpoint(now, thrust, stop):
                return False
            self._record_setpoint(now, thrust, stop)
            return True

    def _admit_setpoint(self, now: float, thrust: Optional[int], stop: bool) -> bool:
        """Whether the user's setpoint goes out, given the reaction under way (which a new setpoint ends
        in hold, and a motors-off setpoint ends anyway)."""
        if self.reaction == Reaction.HOLD:
            self._resume(now)
        if self.reaction in (Reaction.DESCENT, Reaction.LANDING):
            if not (stop or (thrust is not None and thrust < MIN_FLYING_THRUST)):
                return self._drop_setpoint("%s: setpoints ignored until the safety %s is over (%s)",
                                           self.reaction, self.reason)
            self._down(now, "motors off by the user's setpoint")    # always honoured, as emergency is
            self._offs_left, self._offs_sent = 0, True
        if self._shutdown:
            # the server is going away: nothing may send a Crazyflie up again, e.g. a controller
            # whose integrator wound up while the reaction brought its Crazyflie down
            self.ignored_setpoints += 1
            return False
        if self.reaction == Reaction.DOWN:
            return self._admit_after_reaction(thrust, stop)
        return True

    def _admit_after_reaction(self, thrust: Optional[int], stop: bool) -> bool:
        """After a reaction ended with the motors off: only a motors-off setpoint (then any) goes out, and
        none that flies on a critical battery."""
        if self.battery.level == ERROR and (thrust is None or thrust >= MIN_FLYING_THRUST) and not stop:
            self.ignored_setpoints += 1
            return False        # no new take-off on a critical battery
        if thrust is not None and thrust >= MIN_FLYING_THRUST:
            # as the firmware's thrust lock: a new RPYT flight starts from zero thrust, so a
            # controller wound up while its setpoints were ignored cannot send it up at once
            return self._drop_setpoint("%s: thrust setpoints ignored after the safety reaction until one with zero "
                                       "thrust (a controller that kept running is wound up)")
        self.reaction = Reaction.NONE
        self._offs_left, self._offs_sent = 0, True
        return True

    def _drop_setpoint(self, warning: str, *args: Any) -> bool:
        """Counts a dropped setpoint and logs ``warning`` (the label, then ``args``) once per reaction."""
        self.ignored_setpoints += 1
        if not self._said_ignored:
            self._said_ignored = True
            LOG.warning(warning, self.label, *args)
        return False

    def _record_setpoint(self, now: float, thrust: Optional[int], stop: bool) -> None:
        """The stream, and whether it flies, from a setpoint that goes out."""
        self._last_setpoint_at = now
        if thrust is None:
            self._stream = "generic"
            self._flying = not stop
        else:
            self._stream = "rpyt"
            self._flying = thrust >= MIN_FLYING_THRUST
            if self._flying:
                self._thrusts.append((now, int(thrust)))
            while self._thrusts and self._thrusts[0][0] < now - HOVER_WINDOW_S:
                self._thrusts.popleft()
        if self._flying:
            self._motors_off_by = ""
        # a low-level setpoint takes the priority: the firmware's planner stops and forgets its plan
        # (a land command's landing included)
        self._hl_flying = False
        self._land_until = 0.0

    def note_stream_released(self, now: float) -> None:
        """The low-level stream handed control to the high-level commander (notify-setpoints-stop).

        A Crazyflie flying on that stream stays in the air under the high-level commander: counted as
        high-level flight from here, so a shutdown or removal that looks between this and the high-level
        command that usually follows still lands it (it once saw neither and closed the link at 0.54 m)."""
        with self._lock:
            if self._flying and self._stream != "":
                self._hl_flying = self._hl_used = True
            self._stream = ""
            self._last_setpoint_at = None

    def note_pose(self, now: float, z: Optional[float] = None) -> None:
        """A position or pose sent to the onboard estimator (``z`` in metres when known)."""
        with self._lock:
            self._pose_at = now
            if z is not None and math.isfinite(z):
                self._pose_z = float(z)

    def note_high_level(self, now: float, what: str, duration: float = 0.0) -> None:
        """A high-level command was accepted: takeoff, go_to, start_trajectory, land or stop."""
        with self._lock:
            if self._stopped_for_good:
                return
            self._hl_used = True
            if what == "stop":
                self._hl_flying = False
                return
            self._hl_flying = True
            self._motors_off_by = ""
            if what == "land":
                self._land_until = max(self._land_until, now + duration)
            elif self.reaction == Reaction.LANDING:
                # past refusal() (a broadcast, or sent while the reaction began): the firmware flies that
                # command now, so the landing starts again from here; it is never ended in the air
                _, duration = self._plan_landing(now)
                self._event(LOG.error, "%s: a %s replaced the landing in the firmware: landing again in %.1f s"
                            % (self.reason, what, duration))
            elif self.reaction not in (Reaction.HOLD, Reaction.DESCENT):
                self._land_until = 0.0

    def note_motors_off(self, now: float, why: str, for_good: bool = False) -> None:
        """Something else stopped the motors (an emergency stop, ``for_good``; the supervisor's lock):
        nothing is in the air any more, a reaction under way is over and a shutdown has nothing to land."""
        with self._lock:
            if self.reaction in (Reaction.HOLD, Reaction.DESCENT, Reaction.LANDING):
                self._down(now, why, offs=0)
            self._flying = self._hl_flying = False
            self._stream = ""
            self._last_setpoint_at = None
            self._thrusts.clear()
            self._pending_land = None
            self._land_until = 0.0
            self._battery_critical_pending = False
            self._motors_off_by = why
            self._stopped_for_good = self._stopped_for_good or for_good

    def note_restarted(self) -> None:
        """It rebooted on request: an emergency stop is over, the user's commands count again."""
        with self._lock:
            self._stopped_for_good = False

    def current_height(self, now: float) -> Optional[float]:
        """The height (m) of the last pose sent to the onboard estimator if it is fresh, else None."""
        with self._lock:
            if self._pose_z is not None and now - self._pose_at < POSE_FRESH_S:
                return self._pose_z
            return None

    def refusal(self, now: float, what: str) -> Optional[str]:
        """Why the high-level command ``what`` must not go out now, or None. A command that flies
        (``FLYING_COMMANDS``) never cancels a landing under way, nor starts a flight while the server
        lets the Crazyflie go or on a critical battery; land and stop always may (stop is motors off, as
        emergency)."""
        if what not in FLYING_COMMANDS:
            return None
        with self._lock:
            if self.reaction in (Reaction.HOLD, Reaction.DESCENT, Reaction.LANDING):
                return ("the server is bringing it down (%s); a %s would end that in the air. Land and stop are "
                        "taken meanwhile" % (self.reason, what))
            if self._shutdown:
                return ("the server is shutting down or letting this Crazyflie go: nothing may send it up again "
                        "without supervision")
            if self.config.battery and self.battery.level == ERROR:
                # as for thrust setpoints: no new flight on a battery that made the Crazyflie land
                return ("battery critical (%.2f V): no %s on this battery; charge or change it, then remove "
                        "and add the Crazyflie again" % (self.battery.volts, what))
            if self._hl_flying and now < self._land_until:
                return ("a landing is under way (%.1f s to go) and a %s would cancel it in the air; wait for its "
                        "end, or land again or stop" % (self._land_until - now, what))
            return None

    def note_battery(self, now: float, volts: float) -> None:
        """A ``pm.vbat`` sample (V)."""
        with self._lock:
            if not self.config.battery:
                return
            level = self.battery.update(now, volts)
            if level == WARN:
                self._event(LOG.warning, "battery %.2f V below the warning level %.2f V for %.1f s: land soon"
                            % (volts, self.config.battery_warning_v, self.config.battery_persist_s))
            elif level == ERROR:
                self._event(LOG.error, "battery %.2f V below the critical level %.2f V for %.1f s"
                            % (volts, self.config.battery_critical_v, self.config.battery_persist_s))
                self._battery_critical_pending = True

    # ------------------------------------------------------------------ decisions

    @property
    def flying(self) -> bool:
        """In the air as far as the server knows (last setpoint with thrust, or high-level flight)."""
        with self._lock:
            return self._in_air(0.0)

    def _in_air(self, now: float) -> bool:
        if self.reaction in (Reaction.HOLD, Reaction.DESCENT, Reaction.LANDING):
            return True
        if self._hl_flying and not (self._land_until and now > self._land_until + LAND_OVER_AFTER_S):
            return True
        return self._flying and self._stream != ""

    def onboard_control(self, now: float) -> bool:
        """Whether the Crazyflie can land itself: high-level commander, and a position estimate."""
        if self._protocol_version() < HIGH_LEVEL_FROM:
            return False
        if self._hl_used or self._stream == "generic":
            return True
        try:
            estimator = int(self._params().get("stabilizer.estimator", -1))
        except (TypeError, ValueError):
            estimator = -1
        return estimator == ESTIMATOR_KALMAN and now - self._pose_at < POSE_FRESH_S

    def poll(self, now: float) -> Optional[Action]:
        """What to send this round trip instead of the user's stream (None: the user's stream)."""
        with self._lock:
            cfg = self.config
            if self.reaction == Reaction.NONE:
                if self._battery_critical_pending:
                    self._battery_critical_pending = False
                    if self._in_air(now):
                        self._start(now, "battery critical (%.2f V)" % self.battery.volts, hold=False)
                elif cfg.setpoint_silence and self._stream and self._flying and self._last_setpoint_at is not None \
                        and now - self._last_setpoint_at > cfg.setpoint_silence_s:
                    self._start(now, "no setpoint for %.2f s while flying (limit %.2f s)"
                                % (now - self._last_setpoint_at, cfg.setpoint_silence_s), hold=True)
            return self._act(now)

    def begin_shutdown(self, now: float, budget_s: Optional[float] = None,
                       reason: str = "server shutting down") -> bool:
        """The server is shutting down (or lets this Crazyflie go): land or descend if in the air, and
        send no setpoint of the user's again. True when a reaction runs."""
        with self._lock:
            self._shutdown = True
            budget = self.config.shutdown_timeout_s if budget_s is None else budget_s
            self._deadline = now + max(0.0, budget - 0.5)
            if not self.config.land_on_shutdown:
                return False
            if self.reaction in (Reaction.DESCENT, Reaction.LANDING):
                return True
            if not self._in_air(now):
                if self._motors_off_by:
                    self._event(LOG.info, "%s: nothing to bring down, its motors are off (%s)"
                                % (reason, self._motors_off_by))
                return False
            self.reaction = Reaction.NONE
            self._start(now, reason, hold=False)
            return True

    @property
    def in_control(self) -> bool:
        """A reaction flies the Crazyflie: the user's setpoints are not sent."""
        return self.reaction in (Reaction.HOLD, Reaction.DESCENT, Reaction.LANDING)

    def finished(self, now: float) -> bool:
        """No reaction under way (nothing to wait for before closing the link)."""
        with self._lock:
            return self.reaction in (Reaction.NONE, Reaction.DOWN) and self._pending_land is None \
                and self._offs_sent

    def _resume(self, now: float) -> None:
        self._event(LOG.info, "setpoints back after %.2f s of silence: hold ended, the user flies again"
                    % (now - (self._last_setpoint_at or now)))
        self.reaction = Reaction.NONE
        self._plan = None

    def _start(self, now: float, reason: str, hold: bool) -> None:
        self.reason = reason
        self._started_at = now
        self._said_ignored = False
        if self.onboard_control(now) and self._land_until > now:
            # a landing is already under way (the user's, or the swarm's stale-pose landing): it is
            # not sent twice; the reaction waits for its end
            self.reaction = Reaction.LANDING
            self._pending_land = None
            self._own_landing = False
            self._event(LOG.error, "%s: already landing, %.1f s to go" % (reason, self._land_until - now))
            return
        if self.onboard_control(now):
            height, duration = self._plan_landing(now)
            self._event(LOG.error, "%s: landing by the onboard high-level commander from %s in %.1f s"
                        % (reason, "%.2f m" % height if self._pose_z is not None else "its height", duration))
            return
        hover = self._hover_thrust()
        if hover is None:
            self.reaction = Reaction.DESCENT
            self._plan = None
            self._event(LOG.error, "%s: motors off (no hover thrust known to descend from)" % reason)
            return
        self._plan = DescentPlan(hover, self.config.descent_rate, self.config.descent_max_height,
                                 self.config.hold_s if hold else 0.0)
        self.reaction = Reaction.HOLD if hold else Reaction.DESCENT
        cut = " (cut at the shutdown budget)" if now + self._plan.duration > self._deadline else ""
        self._event(LOG.error, "%s: holding level at thrust %d%s, then descending at %.2f m/s for up to %.1f s "
                    "and motors off%s" % (reason, hover, " for %.1f s" % self._plan.hold_s if hold else "",
                                          self.config.descent_rate, self._plan.duration, cut))

    def _plan_landing(self, now: float) -> Tuple[float, float]:
        """The reaction's own landing from the last known height (else the highest expected flight),
        sent at the next poll: (height m, duration s)."""
        height = self._pose_z if self._pose_z is not None else self.config.descent_max_height
        duration = max(MIN_LAND_S, max(height, 0.0) / self.config.descent_rate)
        duration = min(duration, max(MIN_LAND_S, self._deadline - now - LAND_SETTLE_S))
        self.reaction = Reaction.LANDING
        self._pending_land = duration
        self._land_distance = max(height, 0.0)
        self._own_landing = True
        self._land_until = now + duration
        return height, duration

    def _hover_thrust(self) -> Optional[int]:
        if not self._thrusts:
            return None
        return int(round(sum(t for _, t in self._thrusts) / len(self._thrusts)))

    def _act(self, now: float) -> Optional[Action]:
        step = self._STEPS.get(self.reaction)
        return None if step is None else step(self, now)

    def _landing_step(self, now: float) -> Optional[Action]:
        """Onboard landing: the land command once, then the motors off when it is over."""
        if self._pending_land is not None:
            duration, self._pending_land = self._pending_land, None
            return Action("land", duration=duration, distance=self._land_distance)
        if not self._own_landing:
            if now >= self._land_until + LAND_OVER_AFTER_S:
                self._down(now, "landing over", offs=0)      # the firmware's planner stopped the motors
            return None
        if now >= self._deadline or self._landed(now):
            self._down(now, "landed" if now < self._deadline else "shutdown budget spent")
            return Action("hl_stop")
        return None

    def _down_step(self, now: float) -> Optional[Action]:
        """Reaction over: the zero-thrust setpoints still to send."""
        if self._offs_left > 0:
            self._offs_left -= 1
            return Action("off")
        self._offs_sent = True      # polled again: the last one went out
        return None

    def _descent_step(self, now: float) -> Optional[Action]:
        """Hold, then open-loop descent: the plan's thrust, then the motors off."""
        t = now - self._started_at
        if self._plan is None:
            self._down(now, "no descent possible")
            return self._act(now)
        if self.reaction == Reaction.HOLD and t >= self._plan.hold_s:
            self.reaction = Reaction.DESCENT
        thrust = self._plan.thrust_at(t) if now < self._deadline else None
        if thrust is None:
            self._down(now, "descent over" if now < self._deadline else "shutdown budget spent")
            return self._act(now)
        return Action("thrust", thrust=thrust)

    #: What each reaction sends this round trip (no entry: the user's stream).
    _STEPS: Dict[str, Callable[[SafetyMonitor, float], Optional[Action]]] = {
        Reaction.LANDING: _landing_step,
        Reaction.DOWN: _down_step,
        Reaction.HOLD: _descent_step,
        Reaction.DESCENT: _descent_step,
    }

    def _landed(self, now: float) -> bool:
        """The reaction's own landing is over: its plan ended and the Crazyflie rests on the floor."""
        after = now - self._land_until
        if after < 0.0:
            return False
        if now - self._pose_at < POSE_FRESH_S and self._pose_z is not None:
            return self._pose_z <= LANDED_Z_M or after >= LAND_GIVE_UP_S
        return after >= LAND_SETTLE_S

    def _down(self, now: float, how: str, offs: int = OFF_REPEATS) -> None:
        self.reaction = Reaction.DOWN
        self._said_ignored = False
        self._offs_left, self._offs_sent = offs, offs == 0
        self._flying = self._hl_flying = False
        self._stream = ""
        self._last_setpoint_at = None
        self._thrusts.clear()
        self._event(LOG.warning, "%s after %.1f s: motors off (%s)" % (how, now - self._started_at, self.reason))

    def _event(self, log: Callable[..., None], text: str) -> None:
        self.events.append(text)
        log("%s: %s", self.label, text)

    # ------------------------------------------------------------------ report

    def report(self) -> Tuple[int, str, Tuple[Tuple[str, str], ...]]:
        """(level, message, key-value figures) for the status topic and /diagnostics."""
        with self._lock:
            b = self.battery
            if self.reaction in (Reaction.HOLD, Reaction.DESCENT, Reaction.LANDING):
                level, message = ERROR, "safety %s: %s" % (self.reaction, self.reason)
            elif self.reaction == Reaction.DOWN:
                level, message = WARN, "safety reaction over, motors off: %s" % self.reason
            elif b.level == ERROR:
                level, message = ERROR, "battery critical (%.2f V)" % b.volts
            elif b.level == WARN:
                level, message = WARN, "battery low (%.2f V)" % b.volts
            else:
                level, message = OK, ""
            values = (("safety_reaction", self.reaction or "none"),
                      ("safety_reason", self.reason),
                      ("safety_last_event", self.events[-1] if self.events else ""),
                      ("battery_v", "%.2f" % b.volts if math.isfinite(b.volts) else "n/a"),
                      ("battery_level", {OK: "ok", WARN: "warning", ERROR: "critical"}[b.level]),
                      ("setpoints_ignored_by_safety", str(self.ignored_setpoints)))
            return level, message, values
