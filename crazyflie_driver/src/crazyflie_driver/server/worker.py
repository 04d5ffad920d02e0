"""One Crazyflie served by one thread: the work behind ``crazyflie_server``, without ROS.

A :class:`CrazyflieWorker` owns one :class:`~crazyflie_driver.protocol.crazyflie.Crazyflie` (or any
object with the same methods) and is the only thread that streams to it:

* a new setpoint wakes the thread at once and is sent in the next radio round trip; only the
  latest setpoint counts (there is no queue that could add delay);
* when no setpoint comes, null packets keep the link alive (at least every ``keepalive_period``)
  and fetch the log data the Crazyflie has queued, one packet per poll, paced by
  :class:`~crazyflie_driver.server.poll_pacer.PollPacer`;
* link quality (acked / sent over a window, from the link's ``LinkStatistics``) is watched per
  Crazyflie, a listener is told when it drops below ``LINK_QUALITY_WARNING``;
* a Crazyflie that stops answering is reported as lost and retried slowly, without holding the
  dongle for the others; when it answers again its log blocks are set up again;
* :meth:`CrazyflieWorker.emergency` works from any thread, at once, and is idempotent: no
  setpoint is sent after it returns, the e-stop packet goes out, then only zero-thrust
  setpoints, until the worker is removed;
* an unexpected error in the loop never ends the thread silently: it is logged once with its
  traceback, the setpoint stream stops (nothing is replayed, so the firmware's watchdog levels and
  then stops the Crazyflie unless new setpoints come), the listener is told, and the loop restarts;
  after ``MAX_RESTARTS`` errors within ``RESTART_WINDOW`` the worker gives up and closes the link.

The ROS side (``nodes/crazyflie_server.py``) subclasses :class:`WorkerListener` to turn the
callbacks into messages; everything here is testable with a fake Crazyflie object.
"""
from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, FrozenSet, List, Optional, Sequence, Tuple, Union

from crazyflie_driver.clock import WALL, Clock
from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.crtp.firmware_limits import SETPOINT_WATCHDOG_CUT_S
from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import (
    CommandRejected,
    ConnectCancelled,
    CrazyflieError,
    LogConfigError,
    RadioMediumGone,
    RadioNotFound,
    RadioUnplugged,
    UnknownName,
)
from crazyflie_driver.protocol.commander import SUPERVISOR_FROM
from crazyflie_driver.protocol.param import param_value
from crazyflie_driver.protocol.supervisor import decode_state
from crazyflie_driver.protocol.toc import toc_types
from crazyflie_driver.radio.statistics import LINK_QUALITY_MIN_SAMPLES, LINK_QUALITY_RECOVERED, LINK_QUALITY_WARNING
from crazyflie_driver.server import power_control, safety_actions, watchdog_notice
from crazyflie_driver.server.diagnostics import UNKNOWN_BOTTLENECK, CrazyflieHealth, Reports
from crazyflie_driver.server.log_plan import (
    BATTERY_TOPIC,
    BATTERY_VARIABLE,
    DIAGNOSTIC_LOG_TOPICS,
    RADIO_RSSI_TOPIC,
    RSSI_LOG_VARIABLE,
    LogBlockSpec,
    PlannedBlock,
    check_log_limits,
    fixed_log_topics,
    log_packet_rate,
    plan_log_blocks,
)
from crazyflie_driver.server.log_timing import LATE_DATA_WARNING_S, OnboardClock, TopicTiming
from crazyflie_driver.server.poll_pacer import PollPacer
from crazyflie_driver.server.safety import SafetyConfig, SafetyMonitor
from crazyflie_driver.server.setpoint import Setpoint, limits_for_modes, setpoint_from_twist

LOG = logging.getLogger("crazyflie_driver.server")

# What the worker streams: an RPYT setpoint it encodes, or a prepared port-7 packet (onboard modes).
StreamedSetpoint = Union[Setpoint, CRTPPacket]

MAX_RESTARTS = 5            # unexpected loop errors within RESTART_WINDOW before the worker gives up
RESTART_WINDOW = 30.0       # s
RESTART_DELAY = 0.05        # s, pause before the loop restarts after an unexpected error
#: s between closes of the link of a connect sequence being stopped: each close ends the step waiting on the
#: radio at its next round trip (a step that opened the link again meanwhile is closed by the next one)
CANCEL_POLL_S = 0.05


@dataclass(frozen=True)
class WorkerConfig:
    """What ``/add_crazyflie`` asks for."""

    uri: str
    tf_prefix: str = ""
    roll_trim: float = 0.0
    pitch_trim: float = 0.0
    enable_logging: bool = True
    enable_parameters: bool = True
    log_blocks: Tuple[LogBlockSpec, ...] = ()
    # fixed topics switched off by crazyflie_add's enable_logging_<topic> (not logged, not published)
    disabled_topics: FrozenSet[str] = frozenset()
    # s between polls when nothing is queued, with sparse pacing, polls behind the other round trips waiting
    # for the dongle (swarm mode); 0: the server's period, eager pacing
    keepalive_period: float = 0.0
    # ms between battery samples logged for the safety monitor alone when no battery topic is logged
    # (enable_logging off, or the battery topic switched off; swarm mode); 0: none, so no battery
    # reaction without the battery topic
    battery_watch_ms: int = 0
    # the original driver's enable_logging_packets: packets nothing in the server reads go to on_packet
    log_packets: bool = False

    @property
    def logs_anything(self) -> bool:
        """Whether the connection sets up log blocks at all."""
        return bool(self.enable_logging or self.log_blocks or self.battery_watch_ms)


class WorkerListener:
    """Callbacks of a worker; all run in the worker's thread except where noted. Default: nothing."""

    def on_params(self, values: Dict[str, Any]) -> None:
        """All parameter values after connecting, ``{"group.name": value}`` (for mirroring)."""

    def on_log(self, topic: str, onboard_timestamp_ms: int, values: List[float]) -> None:
        """One packet's values for a fixed topic (``imu``, ``battery``...) or a custom topic."""

    def on_log_stamped(self, topic: str, onboard_timestamp_ms: int, values: List[float], age_s: float) -> None:
        """:meth:`on_log` with the packet's age on arrival (s, see ``log_timing``). Default: ``on_log``."""
        self.on_log(topic, onboard_timestamp_ms, values)

    def on_log_late(self, message: str, late: bool) -> None:
        """Log data started (``late``) or stopped arriving later than ``LATE_DATA_WARNING_S``."""

    def late_cause(self) -> str:
        """What limits the data flow as far as is known (``diagnostics.bottleneck_entry``), for the late-data
        message; any thread."""
        return UNKNOWN_BOTTLENECK

    def on_rssi(self, rssi: float) -> None:
        """Radio signal strength, -dBm, from the acks or the ``radio.rssi`` log variable."""

    def on_link_quality(self, quality: float, low: bool) -> None:
        """Called when link quality crosses ``LINK_QUALITY_WARNING`` (and every few s while low)."""

    def on_link_lost(self, reason: str) -> None:
        """The Crazyflie stopped answering (or the dongle went away); the worker keeps retrying."""

    def on_link_restored(self) -> None:
        """The Crazyflie answers again after ``on_link_lost``."""

    def on_console(self, line: str) -> None:
        """One line of the Crazyflie's console (port 0), without its newline; runs in the link's thread."""

    def on_packet(self, packet: CRTPPacket) -> None:
        """A packet nothing in the server reads (``WorkerConfig.log_packets``); runs in the link's thread."""

    def on_emergency(self) -> None:
        """Emergency was triggered (runs in the caller's thread)."""

    def on_worker_error(self, message: str, gave_up: bool) -> None:
        """An unexpected error stopped the loop: it restarts, or (``gave_up``) the link is closed."""

    def on_safety(self, event: str) -> None:
        """A safety reaction started, ended or warned (``server.safety``); already logged."""


class WorkerState:
    CONNECTING = "connecting"
    RUNNING = "running"
    LOST = "lost"
    RESTARTING = "restarting"   # after an unexpected error, before the loop runs again
    FAILED = "failed"
    STOPPED = "stopped"
    POWERED_OFF = "powered off"  # its STM32 domain switched off by request: the nRF acks, nothing more


class CrazyflieWorker:
    """One Crazyflie, one thread: connect sequence, then setpoints / keep-alives until stopped."""

    def __init__(self, config: WorkerConfig, crazyflie: Any, listener: Optional[WorkerListener] = None,
                 keepalive_period: float = 0.010, link_lost_timeout: float = 1.0,
                 lost_retry_period: float = 0.25, quality_warning_interval: float = 5.0,
                 rssi_period: float = 0.1, device_retry_window: float = 10.0,
                 clock: Clock = WALL, safety: Optional[SafetyConfig] = None) -> None:
        self.config = config
        self.cf = crazyflie
        self.listener = listener or WorkerListener()
        console = getattr(crazyflie, "console", None)
        if console is not None:     # the listener is asked each time: a server may attach its own later
            console.on_line(lambda line: self.listener.on_console(line))
        link = getattr(crazyflie, "link", None)
        if config.log_packets and link is not None and hasattr(link, "on_unclaimed"):
            link.on_unclaimed(lambda packet: self.listener.on_packet(packet))
        self.keepalive_period = config.keepalive_period or keepalive_period
        self.link_lost_timeout = link_lost_timeout
        self.lost_retry_period = lost_retry_period
        self.quality_warning_interval = quality_warning_interval
        self.rssi_period = rssi_period
        self.device_retry_window = device_retry_window
        self.clock = clock                       # every time and wait of the worker (world time in a simulation)
        self._clock = clock.now

        self.state = WorkerState.CONNECTING
        self.error: Optional[BaseException] = None
        self.setpoints_sent = 0
        self.keepalives_sent = 0
        self.log_topics: List[str] = []          # topics whose blocks were started
        self.missing_fixed_topics: List[str] = []
        self.param_types: Dict[str, str] = {}
        self.restarts = 0                        # loop restarts after unexpected errors
        self.last_unexpected_error = ""          # "Type: message" of the latest one
        self.listener_errors = 0                 # log packets a listener failed to handle
        self.param_values: Dict[str, Any] = {}   # as read after connecting and written since
        self.topic_timing: Dict[str, TopicTiming] = {}   # per log topic: age, rate, lost packets
        self.log_late = False                    # log data currently arrives late
        self.health = CrazyflieHealth(clock.now)     # latest battery/supervisor samples, last setpoint and pose
        self.reports = Reports()                 # entries other parts add to /diagnostics and the status

        self._cond = threading.Condition()
        self._pending: Optional[StreamedSetpoint] = None
        self._send_lock = threading.Lock()       # a setpoint check-and-send vs. emergency
        self._emergency = False
        self._server_exiting = False     # set by server_exiting(): a world that stops now is expected
        self._stopping = False
        self._ready = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._last_ack = 0.0
        self._quality_low = False
        self._quality_warned_at = -1e9
        self._rssi_from_log = False
        self._rssi_sent_at = -1e9
        self._blocks: List[Any] = []
        self._downlink_packets = 0
        self._pacer = PollPacer(self.keepalive_period, now=clock.now(),
                                margin=PollPacer.SPARSE_MARGIN if config.keepalive_period else PollPacer.MARGIN)
        self._log_plan: List[PlannedBlock] = []
        self._error_times: List[float] = []
        self._onboard_clock = OnboardClock()
        self._late_warned_at = -1e9
        self._lost_at_late_warning = 0
        self._errors_seen: Dict[Tuple[str, str], int] = {}   # (type, where) -> count, for "traceback once"
        self._lost_at = 0.0
        # what the firmware's setpoint watchdog makes of the stream sent (said once per cut)
        self.watchdog = watchdog_notice.WatchdogNotice(self._protocol_version)
        self.safety = SafetyMonitor(safety or SafetyConfig.off(), config.uri,
                                    lambda: getattr(self.cf, "protocol_version", -1), lambda: self.param_values)
        self._safety_events = 0
        self._watchdog_due = 0.0
        self.user_params: Dict[str, Any] = {}    # written through update_params: set again after a reboot
        self._rebooted = False                   # a reboot was asked for: set up again once it answers

    # ------------------------------------------------------------------ lifecycle

    @property
    def uri(self) -> str:
        return self.config.uri

    @property
    def emergency_active(self) -> bool:
        return self._emergency

    def start(self) -> None:
        """Start the thread; the connect sequence runs in it. See :meth:`wait_ready`."""
        if self._thread is not None:
            raise RuntimeError("worker for %s already started" % self.uri)
        self._thread = threading.Thread(target=self._run, name="crazyflie %s" % self.uri, daemon=True)
        self._thread.start()

    def wait_ready(self, timeout: float) -> None:
        """Block until the connect sequence finished (``timeout`` s of the worker's clock). Raises its
        error, or TimeoutError."""
        if not self.clock.wait(self._ready, timeout):
            raise TimeoutError("Crazyflie %s did not finish connecting within %.1f s (is it switched on, "
                               "on this channel and address, and in range?)" % (self.uri, timeout))
        if self.error is not None:
            raise self.error

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the thread and close the link. Safe to call twice and from any thread.

        A connect sequence under way is cut short: the link is closed under it, so the step waiting on
        the radio fails at its next round trip and nothing more is sent (an add that timed out leaves no
        worker talking to the Crazyflie). Waits up to ``timeout`` s for the thread to end."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            deadline = time.monotonic() + timeout      # wall clock: joining a host thread
            while True:
                if self.state == WorkerState.CONNECTING:
                    self._close_link()
                t.join(max(0.0, min(CANCEL_POLL_S, deadline - time.monotonic())))
                if not t.is_alive() or time.monotonic() >= deadline:
                    break
            if t.is_alive():
                # it closes the link itself when its current radio exchange ends
                if timeout > 0:
                    LOG.warning("%s: worker thread still busy after %.1f s; leaving it to finish", self.uri, timeout)
                return
        self._close()

    def _close_link(self) -> None:
        try:
            self.cf.close()
        except Exception as e:          # closing a dead link must not raise into the caller
            LOG.debug("%s: close: %s", self.uri, e)

    def _close(self) -> None:
        self._close_link()
        if self.state != WorkerState.FAILED:
            self.state = WorkerState.STOPPED

    # ------------------------------------------------------------------ commands (any thread)

    def set_setpoint(self, setpoint: StreamedSetpoint) -> bool:
        """Latest setpoint wins; wakes the worker at once. False (ignored) after emergency."""
        if self._emergency:
            return False
        self.health.setpoint_given()
        if not self.safety.note_setpoint(self._clock(), *safety_actions.setpoint_thrust(setpoint)):
            return True     # a safety reaction flies it (said once by the monitor)
        with self._cond:
            self._pending = setpoint
            self._cond.notify_all()
        return True

    def set_packet_setpoint(self, packet: Optional[CRTPPacket]) -> bool:
        """A prepared setpoint packet (port 7) streamed like an RPYT one; None drops a pending one."""
        if packet is None:
            with self._cond:
                self._pending = None
            self.watchdog.handed_over()
            self.safety.note_stream_released(self._clock())
            return True
        return self.set_setpoint(packet)

    def cmd_vel(self, linear_x: float, linear_y: float, linear_z: float, angular_z: float) -> bool:
        """A cmd_vel message mapped with this Crazyflie's trims (see :meth:`setpoint_for_cmd_vel`)."""
        return self.set_setpoint(self.setpoint_for_cmd_vel(linear_x, linear_y, linear_z, angular_z))

    def setpoint_for_cmd_vel(self, linear_x: float, linear_y: float, linear_z: float, angular_z: float) -> Setpoint:
        """The setpoint a cmd_vel asks for, held to this Crazyflie's limits (its flight modes).

        ValueError naming the field when one is NaN or infinite (the last good setpoint stays);
        fields held to their limit are named in the setpoint's ``notes``."""
        return setpoint_from_twist(linear_x, linear_y, linear_z, angular_z, self.config.roll_trim,
                                   self.config.pitch_trim, limits_for_modes(self.param_values))

    def emergency(self) -> None:
        """Stop flying now: no setpoint after this returns; e-stop packet; then zero thrust only."""
        with self._send_lock:
            first = not self._emergency
            self._emergency = True
            with self._cond:
                self._pending = None
                self._cond.notify_all()
            try:
                self.cf.emergency_stop()
            except Exception as e:      # the worker keeps sending zero-thrust setpoints anyway
                LOG.error("%s: emergency stop packet failed: %s (zero-thrust setpoints follow)", self.uri, e)
        if first:
            self.safety.note_motors_off(self._clock(), "emergency stop", for_good=True)
            LOG.warning("%s: EMERGENCY: motors stopped until a reboot; to fly again %s", self.uri,
                        power_control.REBOOT_ADVICE)
            try:
                self.listener.on_emergency()
            except Exception:
                LOG.exception("%s: emergency listener failed", self.uri)

    def update_params(self, values: Dict[str, Any]) -> Tuple[List[str], List[str]]:
        """Write parameters (``{"group.name": value}``). Runs in the caller's thread.

        Returns (written names, error messages); unknown names and bad values are errors, the
        others are still written.
        """
        written, errors = [], []
        for name, value in values.items():
            ctype = self.param_types.get(name)
            if ctype is None and self.param_types:
                errors.append("%s: no such parameter on %s" % (name, self.uri))
                continue
            try:
                v = param_value(name, ctype, value) if ctype else value
                self.cf.params.set(name, v)
                self.param_values[name] = v
                self.user_params[name] = v
                written.append(name)
            except UnknownName:
                errors.append("%s: no such parameter on %s" % (name, self.uri))
            except (ValueError, CrazyflieError) as e:
                errors.append("%s: %s" % (name, e))
        return written, errors

    # ------------------------------------------------------------------ supervisor and power (any thread)

    def _offline(self) -> str:
        """'' while the link runs, else why nothing can be asked of the Crazyflie."""
        if self.state == WorkerState.POWERED_OFF:
            return "its STM32 is switched off (call its %s service)" % power_control.POWER_ON_SERVICE
        if self.state != WorkerState.RUNNING:
            return "its link is %s" % self.state
        return ""

    def arm(self, do_arm: bool = True) -> None:
        """Arm (or disarm) through its supervisor (platform port before protocol 12). CommandRejected
        when refused here or by the Crazyflie; NotSupported on firmware that arms itself."""
        refusal = power_control.arm_refusal(do_arm, self._emergency, self._offline())
        if refusal is not None:
            raise CommandRejected("%s: %s" % (self.uri, refusal))
        if not self.cf.supervisor.arm(do_arm):
            raise CommandRejected("%s: the Crazyflie refused to %s (its supervisor is locked or crashed: see its "
                                  "status)" % (self.uri, "arm" if do_arm else "disarm"))

    def read_config(self) -> cb.ConfigBlock:
        """The EEPROM configuration block; CommandRejected while the link does not run."""
        offline = self._offline()
        if offline:
            raise CommandRejected("%s: cannot read its configuration: %s" % (self.uri, offline))
        return self.cf.memory.read_config()

    def write_config(self, block: cb.ConfigBlock) -> None:
        """Write the EEPROM configuration block (taken by the firmware at its next boot)."""
        cb.check(block)
        offline = self._offline()
        if offline:
            raise CommandRejected("%s: cannot write its configuration: %s" % (self.uri, offline))
        self.cf.memory.write_config(block)

    def recover(self) -> None:
        """Leave the crashed state (after a tumble); CommandRejected when refused or still upside down."""
        refusal = power_control.recover_refusal(self._emergency, self._offline())
        if refusal is not None:
            raise CommandRejected("%s: %s" % (self.uri, refusal))
        if not self.cf.supervisor.recover():
            raise CommandRejected("%s: not recovered: the Crazyflie is still tumbled (put it upright) or not "
                                  "crashed" % self.uri)

    def _airborne(self) -> Tuple[Optional[float], bool]:
        now = self._clock()
        bits, at = self.health.supervisor_bits, self.health.supervisor_at
        sup_flying = bits is not None and at is not None and now - at < 1.0 and bool(decode_state(bits).flags["flying"])
        return self.watchdog.flying_for(now), sup_flying

    def send_raw(self, packet: CRTPPacket) -> None:
        """A packet built by ``raw_packets.raw_packet`` (the original's send_packet), sent once as it is;
        CommandRejected after an emergency (nothing goes to a stopped Crazyflie but a reboot) and while the
        link does not run, as the configuration services say it."""
        if self._emergency:
            raise CommandRejected("%s: send_packet refused: emergency is active; %s"
                                  % (self.uri, power_control.REBOOT_ADVICE))
        offline = self._offline()
        if offline:
            raise CommandRejected("%s: send_packet refused: %s" % (self.uri, offline))
        with self._send_lock:
            self.cf.link.send(packet)

    def reboot_refusal(self) -> Optional[str]:
        """Why a reboot is refused now (it flies), or None."""
        flying_for, sup_flying = self._airborne()
        return power_control.power_change_refusal("reboot", flying_for, sup_flying, self._emergency)

    def reboot(self) -> None:
        """Restart it into its firmware; the worker then waits for it and sets up again what the server
        set up (log blocks, the parameters written through ``update_params``), and an emergency is over."""
        refusal = self.reboot_refusal()
        if refusal is not None:
            raise CommandRejected("%s: %s" % (self.uri, refusal))
        with self._send_lock:
            self.cf.reboot()
            self._went_down("rebooted on request")
            self._emergency = False
        self.watchdog.restarted(False)
        self.safety.note_restarted()

    def power_off(self) -> None:
        """Switch its STM32 domain off (the nRF stays on the radio, so ``power_on`` can reach it)."""
        flying_for, sup_flying = self._airborne()
        refusal = power_control.power_change_refusal("power-off", flying_for, sup_flying, self._emergency)
        if refusal is not None:
            raise CommandRejected("%s: %s" % (self.uri, refusal))
        with self._send_lock:
            self.cf.power_off_stm()
            self._went_down("switched off on request", WorkerState.POWERED_OFF)

    def power_on(self) -> None:
        """Switch its STM32 domain on: it boots, and is set up again as after a reboot. On one that was not
        switched off this changes nothing (the radio chip ignores it; an emergency stays)."""
        with self._send_lock:
            self.cf.power_on_stm()
            if self.state != WorkerState.POWERED_OFF:
                return
            self.state = WorkerState.LOST
            self._emergency = False
        self.watchdog.restarted(False)
        self.safety.note_restarted()

    def _went_down(self, reason: str, state: str = WorkerState.LOST) -> None:
        with self._cond:
            self._pending = None
            self._rebooted = True
            self.state = state
            self._lost_at = self._clock()
            self._cond.notify_all()
        LOG.warning("%s: %s; it is set up again when it answers", self.uri, reason)

    # ------------------------------------------------------------------ thread

    def _run(self) -> None:
        try:
            self._connect_sequence()
        except BaseException as e:
            if self._stopping:      # whatever the closed link made the step raise: it was stopped
                e = ConnectCancelled("%s: connect stopped before it finished (%s)" % (self.uri, e))
            self.error = e if isinstance(e, Exception) else RuntimeError(str(e))
            self.state = WorkerState.FAILED
            self._close()           # before the caller hears of it: a retry finds the link down
            self._ready.set()
            return
        self.state = WorkerState.RUNNING
        self._last_ack = self._clock()
        self._ready.set()
        try:
            while not self._stopping:
                try:
                    self._loop()
                    return
                except Exception as e:      # never let the thread die silently
                    if not self._recover_from(e):
                        return
        finally:
            if self._stopping:
                self._close()

    def _recover_from(self, error: Exception) -> bool:
        """After an unexpected error in the loop: log (traceback once per kind), stop the setpoint
        stream, tell the listener; True to run the loop again, False when the worker gave up."""
        now = self._clock()
        self._error_times = [t for t in self._error_times if now - t < RESTART_WINDOW] + [now]
        tb = error.__traceback__
        while tb is not None and tb.tb_next is not None:
            tb = tb.tb_next
        where = "%s:%d" % (tb.tb_frame.f_code.co_filename, tb.tb_lineno) if tb is not None else "?"
        kind = (type(error).__name__, where)
        seen = self._errors_seen.get(kind, 0)
        self._errors_seen[kind] = seen + 1
        self.last_unexpected_error = "%s: %s" % (type(error).__name__, error)
        with self._cond:
            self._pending = None        # never replay the setpoint that was in flight
        gave_up = len(self._error_times) > MAX_RESTARTS
        if gave_up:
            action = ("%d unexpected errors within %.0f s: giving up on this Crazyflie (link closed, nothing "
                      "is sent: its watchdog stops the motors within 2 s); remove and add it again"
                      % (len(self._error_times), RESTART_WINDOW))
        else:
            action = ("setpoints stopped (its watchdog levels it after 0.5 s and stops the motors after 2 s "
                      "unless new setpoints come); worker restarted")
        text = "%s: worker loop failed: %s; %s" % (self.uri, self.last_unexpected_error, action)
        if seen == 0:
            LOG.error(text, exc_info=error)
        else:
            LOG.error("%s (same error as before, %d times)", text, seen + 1)
        self.state = WorkerState.FAILED if gave_up else WorkerState.RESTARTING
        try:
            self.listener.on_worker_error(text, gave_up)
        except Exception:
            LOG.exception("%s: worker error listener failed", self.uri)
        if gave_up:
            self._close()
            return False
        self.restarts += 1
        with self._cond:
            if not self._stopping:      # a pause of at most RESTART_DELAY of the clock (a setpoint ends it)
                self._cond.wait(self.clock.wall_bound(RESTART_DELAY))
        if self.state == WorkerState.RESTARTING:
            self.state = WorkerState.RUNNING
        return True

    def _connect_sequence(self) -> None:
        """Connect, TOCs, parameters, log blocks, thrust unlock; stopped between steps by ``stop`` (which
        also closes the link under the step under way)."""
        cfg, cf = self.config, self.cf
        self._connect_link()
        self._check_cancelled()
        if cfg.logs_anything:
            cf.log.reset()
        if cfg.enable_parameters:
            self._check_cancelled()
            cf.params.fetch_toc()
            self.param_types = toc_types(cf.params.toc)
            self._check_cancelled()
            values = cf.params.read_all()
            self.param_values = dict(values)
            self._check_cancelled()
            self.listener.on_params(dict(values))
        if cfg.logs_anything:
            self._check_cancelled()
            cf.log.fetch_toc()
            self._log_plan = self._plan_logging(toc_types(cf.log.toc))
            self._check_cancelled()
            self._start_log_blocks()
        self._check_cancelled()
        self._release_thrust_lock()
        self._check_cancelled()

    def _check_cancelled(self) -> None:
        if self._stopping:
            raise ConnectCancelled("%s: connect stopped before it finished" % self.uri)

    def _connect_link(self) -> None:
        """``cf.connect()``; a radio that is not there yet (dongle, or the simulated world still
        starting) is retried for ``device_retry_window`` s. A silent Crazyflie fails at once."""
        deadline = self._clock() + self.device_retry_window
        while True:
            try:
                self.cf.connect()
                return
            except (RadioNotFound, ConnectionError) as e:
                if self._stopping or self._clock() >= deadline:
                    raise
                LOG.info("%s: radio not available yet (%s); retrying", self.uri, e)
                with self._cond:
                    self._cond.wait(self.clock.wall_bound(0.5))

    def _plan_logging(self, types: Dict[str, str]) -> List[PlannedBlock]:
        """Fixed topics (skipping those this Crazyflie lacks) + custom ones; errors for custom ones."""
        cfg = self.config
        topics: List[Tuple[str, int, Sequence[str]]] = []
        plan: List[PlannedBlock] = []
        self.missing_fixed_topics = []
        if cfg.enable_logging:
            fixed = fixed_log_topics(cfg.disabled_topics)
            rssi = self.cf.link.stats.rssi
            if rssi is None and RSSI_LOG_VARIABLE in types:
                fixed.append((RADIO_RSSI_TOPIC, 100, (RSSI_LOG_VARIABLE,)))
                self._rssi_from_log = True
            for name, period, variables in fixed:
                missing = [v for v in variables if v not in types]
                if missing:
                    self.missing_fixed_topics.append(name)
                    LOG.warning("%s: no %s topic: this Crazyflie has no log variable(s) %s",
                                self.uri, name, ", ".join(missing))
                    continue
                topics.append((name, period, variables))
            for name, host, variables in DIAGNOSTIC_LOG_TOPICS:     # for /diagnostics, in the hosts' blocks
                host_periods = [p for t, p, _ in topics if t == host]
                if host_periods and all(v in types for v in variables):
                    topics.append((name, host_periods[0], variables))
            plan.extend(plan_log_blocks(topics, types, share=True))
        # the safety monitor's battery, when no battery topic brings it (sensor topics off, or the
        # battery topic switched off): the switch turns a topic off, not the supervision
        if (cfg.battery_watch_ms and not any(t == BATTERY_TOPIC for t, _, _ in topics)
                and BATTERY_VARIABLE in types):
            plan.extend(plan_log_blocks([(BATTERY_TOPIC, cfg.battery_watch_ms, (BATTERY_VARIABLE,))], types,
                                        share=True))
        custom = [(b.topic_name, b.period_ms, b.variables) for b in cfg.log_blocks]
        plan.extend(plan_log_blocks(custom, types, share=False))
        log = self.cf.log       # the firmware's limits over all blocks, before the first is created
        check_log_limits(plan, {b.topic_name for b in cfg.log_blocks}, log.max_blocks, log.max_ops)
        return plan

    def _start_log_blocks(self) -> None:
        self._blocks = []
        self.log_topics = []
        self._onboard_clock.reset()
        self.topic_timing = {t: TopicTiming(p.period_ms) for p in self._log_plan for t, _, _ in p.topics}
        for planned in self._log_plan:
            callback = self._make_log_callback(planned)
            try:
                block = self.cf.log.create_block(list(planned.variables), planned.period_ms, callback)
            except LogConfigError as e:
                raise LogConfigError("%s: log block for %s: %s" % (
                    self.uri, ", ".join(t for t, _, _ in planned.topics), e)) from e
            self._blocks.append(block)
            self.log_topics.extend(t for t, _, _ in planned.topics)
        self._pacer.reset(log_packet_rate(self._log_plan), self._clock())

    def _make_log_callback(self, planned: PlannedBlock) -> Callable[[int, List[float]], None]:
        slices = list(planned.topics)
        listener = self.listener

        def on_packet(onboard_timestamp_ms: int, values: List[float]) -> None:
            self._downlink_packets += 1
            onboard_s = self._onboard_clock.onboard_seconds(onboard_timestamp_ms)
            arrived = self._clock()
            age = self._onboard_clock.age(onboard_s, arrived)
            for topic, start, stop in slices:
                part = list(values[start:stop])
                if len(part) != stop - start:
                    continue        # a truncated packet: never publish a partial message
                timing = self.topic_timing.get(topic)
                if timing is not None:
                    timing.record(onboard_s, age, arrived)
                self.health.on_log(topic, part, arrived)
                if topic == BATTERY_TOPIC:
                    self.safety.note_battery(arrived, float(part[0]))
                try:
                    if topic == RADIO_RSSI_TOPIC:
                        listener.on_rssi(float(part[0]))
                    else:
                        listener.on_log_stamped(topic, onboard_timestamp_ms, part, age)
                except Exception:   # one bad message must not stop the setpoint stream
                    self.listener_errors += 1
                    if self.listener_errors == 1:
                        LOG.exception("%s: publishing %s failed (counted in the status from now on)",
                                      self.uri, topic)
            self._check_late(age)
        return on_packet

    @property
    def log_packet_rate(self) -> float:
        """Log packets per second the started blocks produce."""
        return log_packet_rate(self._log_plan)

    @property
    def log_packets_received(self) -> int:
        """Log packets received since the worker started (all blocks)."""
        return self._downlink_packets

    def lost_log_packets(self) -> int:
        """Log packets the onboard timestamps say never arrived (one count per block)."""
        seen, lost = set(), 0
        for planned in self._log_plan:
            topic = planned.topics[0][0]
            if topic in self.topic_timing and topic not in seen:
                seen.add(topic)
                lost += self.topic_timing[topic].lost
        return lost

    def _check_late(self, age: float) -> None:
        """Say once when log data starts arriving late (again every 10 s while it stays late, with
        the packets lost meanwhile), and once when it is on time again."""
        now = self._clock()
        if self.state == WorkerState.LOST:
            return          # packets the Crazyflie queued while the link was down
        if age > LATE_DATA_WARNING_S:
            if self.log_late and now - self._late_warned_at < 10.0:
                return
            lost = self.lost_log_packets()
            new_lost = lost - self._lost_at_late_warning
            self._lost_at_late_warning = lost
            self.log_late, self._late_warned_at = True, now
            try:
                cause = self.listener.late_cause()
            except Exception:
                cause = UNKNOWN_BOTTLENECK
            text = "%s: log data arrives %.1f s late%s; bottleneck: %s" % (
                self.uri, age, "; %d log packets lost: the Crazyflie's transmit queue overflows" % new_lost
                if new_lost else "", cause)
            LOG.warning(text)
            self._tell_late(text, True)
        elif self.log_late and age < LATE_DATA_WARNING_S / 2:
            self.log_late = False
            text = "%s: log data on time again (%.2f s old on arrival)" % (self.uri, age)
            LOG.info(text)
            self._tell_late(text, False)

    def _tell_late(self, text: str, late: bool) -> None:
        try:
            self.listener.on_log_late(text, late)
        except Exception:
            LOG.exception("%s: late-data listener failed", self.uri)

    def _release_thrust_lock(self) -> None:
        """Zero setpoints until one is acked (the firmware unlocks thrust on a zero-thrust packet)."""
        for _ in range(10):
            if self._stopping:
                return
            if self.cf.send_setpoint(0.0, 0.0, 0.0, 0):
                return
        LOG.warning("%s: no ack for 10 zero setpoints after connecting (poor link?)", self.uri)

    def _loop(self) -> None:
        next_due = self._clock()
        while True:
            with self._cond:
                if not self._await_turn(next_due):
                    return
                setpoint = self._pending
                self._pending = None
            next_due = self._one_round(setpoint)

    def _await_turn(self, next_due: float) -> bool:
        """Waits (holding ``_cond``) until a setpoint is pending on a live link or ``next_due`` has come;
        False when the worker stops."""
        while not self._stopping:
            now = self._clock()
            lost = self.state in (WorkerState.LOST, WorkerState.POWERED_OFF)
            if self._pending is not None and not lost:
                break
            wait = next_due - now
            if wait <= 0:
                break
            self._cond.wait(self.clock.wall_bound(wait))
        return not self._stopping

    def _one_round(self, setpoint: Optional[StreamedSetpoint]) -> float:
        """One round trip (the setpoint, a safety reaction's, or a keep-alive) and what follows it;
        returns when the next one is due."""
        setpoint = self._safety_step(setpoint)
        downlink_before = self._downlink_packets
        fetched_before = self._fetched_packets()
        acked = self._round_trip(setpoint)
        now = self._clock()
        next_due = self._next_due(now, downlink_before, fetched_before)
        if acked is not None:
            self._after_round_trip(acked, now)
            if acked and self._downlink_packets == downlink_before:
                self._onboard_clock.drained()
        self._watchdog_duties(now)
        return next_due

    def _next_due(self, now: float, downlink_before: int, fetched_before: int) -> float:
        """When the next round trip is due: the lost-link retry period, else the pacer's choice from the
        log data and other answers this round trip brought down."""
        if self.state in (WorkerState.LOST, WorkerState.POWERED_OFF):
            return now + self.lost_retry_period
        logged = self._downlink_packets - downlink_before
        return now + self._pacer.after_round_trip(
            logged, now, max(0, self._fetched_packets() - fetched_before - logged))

    def _watchdog_duties(self, now: float) -> None:
        """The emergency-stop watchdog: say once that it cut the motors, send its keep-alive when due."""
        silent = self.watchdog.due(now)
        if not self._emergency and silent is not None:
            self._say_watchdog_cut(now, silent)
        if self.safety.config.emergency_watchdog and now >= self._watchdog_due:
            self._watchdog_due = now + safety_actions.WATCHDOG_KEEPALIVE_PERIOD_S
            safety_actions.send_watchdog_keepalive(self.cf)

    def _fetched_packets(self) -> int:
        """Packets the Crazyflie's queue gave up so far: log data and every other answer (parameter,
        memory and high-level replies, console text) that shares the queue with it."""
        return getattr(self.cf.link, "downlink_packets", self._downlink_packets)

    def _safety_step(self, setpoint: Optional[StreamedSetpoint]) -> Optional[StreamedSetpoint]:
        """The setpoint to send this round trip: the user's, or a safety reaction's (see server.safety)."""
        if self._emergency:
            return setpoint
        action = self.safety.poll(self._clock())
        if self.safety.in_control or action is not None:
            setpoint = safety_actions.carry_out(action, self.cf) if action is not None else None
            if action is not None and action.kind == "land":
                self.watchdog.handed_over()     # the high-level commander flies it now
        if len(self.safety.events) != self._safety_events:
            self._safety_events = len(self.safety.events)
            try:
                self.listener.on_safety(self.safety.events[-1])
            except Exception:
                LOG.exception("%s: safety listener failed", self.uri)
        return setpoint

    def begin_safe_shutdown(self, budget_s: Optional[float] = None, reason: str = "server shutting down") -> bool:
        """Land or descend before the link closes (server shutdown, removal); True when a reaction runs.
        Any thread; :meth:`safe_to_close` says when it is over."""
        started = self.safety.begin_shutdown(self._clock(), budget_s, reason)
        with self._cond:
            self._cond.notify_all()
        return started

    def server_exiting(self) -> None:
        """The whole server is shutting down. A simulated world stopped by the same Ctrl-C may go first:
        from now on that is expected (said at info level, and nothing is left to bring down), while a
        world that stops while the server runs stays a lost link (an error)."""
        self._server_exiting = True

    def _medium_gone_at_exit(self, error: RadioMediumGone) -> None:
        if self.state != WorkerState.RUNNING:
            return
        self.state = WorkerState.LOST
        self._lost_at = self._clock()
        with self._cond:
            self._pending = None
        LOG.info("%s: link closed: %s (it shuts down with the server)", self.uri, error)

    def safe_to_close(self) -> bool:
        return self._emergency or self.state != WorkerState.RUNNING or self.safety.finished(self._clock())

    def _round_trip(self, setpoint: Optional[StreamedSetpoint]) -> Optional[bool]:
        """One packet to the Crazyflie. Returns acked, or None when the dongle failed."""
        try:
            with self._send_lock:
                if self._emergency:
                    return bool(self.cf.send_setpoint(0.0, 0.0, 0.0, 0))
                if isinstance(setpoint, CRTPPacket):
                    acked = bool(self.cf.link.send(setpoint))
                    self.setpoints_sent += 1
                    self.watchdog.sent(setpoint, self._clock())     # on the air (a dead dongle raised)
                    return acked
                if setpoint is not None:
                    acked = bool(self.cf.send_setpoint(setpoint.roll, setpoint.pitch,
                                                       setpoint.yawrate, setpoint.thrust))
                    self.setpoints_sent += 1
                    self.watchdog.sent(setpoint, self._clock())
                    return acked
                acked = bool(self.cf.send_keepalive(background=True) if self.config.keepalive_period
                             else self.cf.send_keepalive())
                self.keepalives_sent += 1
                return acked
        except RadioUnplugged as e:
            self._mark_lost("%s: plug it back in (it is picked up again, nothing to restart)" % e)
            return None
        except RadioMediumGone as e:
            if self._server_exiting:
                self._medium_gone_at_exit(e)
            else:
                self._check_lost(self._clock(), str(e))
            return None
        except CrazyflieError as e:
            self._check_lost(self._clock(), str(e))
            return None

    def _after_round_trip(self, acked: bool, now: float) -> None:
        if acked:
            self._last_ack = now
            if self.state == WorkerState.LOST:
                self._restore()
        else:
            self._check_lost(now, "no ack for %.1f s" % (now - self._last_ack))
        self._check_quality(now)
        if acked and not self._rssi_from_log and now - self._rssi_sent_at >= self.rssi_period:
            rssi = self.cf.link.stats.rssi
            if rssi is not None:
                self._rssi_sent_at = now
                self.listener.on_rssi(float(rssi))

    def _check_lost(self, now: float, reason: str) -> None:
        if self.state == WorkerState.RUNNING and now - self._last_ack >= self.link_lost_timeout:
            self._mark_lost(reason)

    def _mark_lost(self, reason: str) -> None:
        if self.state == WorkerState.LOST:
            return
        self.state = WorkerState.LOST
        self._lost_at = self._clock()
        with self._cond:
            self._pending = None      # never replay an old setpoint after the link comes back
        flying = self.watchdog.flying_for(self._lost_at)
        if flying is not None:
            reason += "; " + watchdog_notice.flying_when_lost_message(flying)
        LOG.error("%s: link lost: %s; retrying every %.2f s", self.uri, reason, self.lost_retry_period)
        self.listener.on_link_lost(reason)

    def _protocol_version(self) -> int:
        return getattr(self.cf, "protocol_version", -1)      # -1 until connected

    def _say_watchdog_cut(self, now: float, silent: float) -> None:
        """The setpoints stopped ``silent`` s ago while asking for thrust: the firmware has stopped the
        motors. Where it has a supervisor (and the link is up) it is asked whether it is locked."""
        link_down = self.state == WorkerState.LOST
        locked = None
        if not link_down and self._protocol_version() >= SUPERVISOR_FROM:
            try:
                flags = self.cf.supervisor.state().flags
            except CrazyflieError as e:
                LOG.debug("%s: supervisor state unknown: %s", self.uri, e)
            else:
                if flags["flying"] and not flags["locked"]:
                    if silent < SETPOINT_WATCHDOG_CUT_S + 1.0:
                        self.watchdog.not_yet(now)     # its clock runs a little behind ours
                    else:
                        self.watchdog.handed_over()    # something else holds it in the air: no cut
                    return
                locked = flags["locked"]
        text = watchdog_notice.cut_message(silent, locked, self._protocol_version(), link_down)
        self.watchdog.said(text, locked)
        LOG.warning("%s: %s", self.uri, text)
        if locked:
            self.safety.note_motors_off(now, "locked by its supervisor after the setpoint watchdog's cut")

    def _restore(self) -> None:
        if self._rebooted:
            # It booted afresh: no log blocks, parameters at their defaults, thrust locked. Until its firmware
            # answers (the nRF acks first) this fails and is tried again at the next ack.
            try:
                self._set_up_again()
            except CrazyflieError as e:
                LOG.info("%s: not up yet after the reboot (%s); trying again", self.uri, e)
                return
            self._rebooted = False
            LOG.warning("%s: back after the reboot (%.1f s): %d log block(s) and %d parameter(s) set again",
                        self.uri, self._clock() - self._lost_at, len(self._blocks), len(self.user_params))
            self.state = WorkerState.RUNNING
            self.listener.on_link_restored()
            return
        LOG.warning("%s: link restored after %.1f s", self.uri, self._clock() - self._lost_at)
        if self._clock() - self._lost_at >= SETPOINT_WATCHDOG_CUT_S:
            self.safety.note_stream_released(self._clock())     # the firmware's watchdog ended that stream
        if self.watchdog.locked_until_restart and self._protocol_version() >= SUPERVISOR_FROM:
            try:     # restarted meanwhile?
                self.watchdog.restarted(self.cf.supervisor.state().flags["locked"])
            except CrazyflieError as e:
                LOG.debug("%s: supervisor state unknown: %s", self.uri, e)
        if self._log_plan:
            # The firmware deletes all log blocks after 1 s without radio traffic: set them up again.
            try:
                self.cf.log.reset()
                self._start_log_blocks()
            except Exception as e:
                LOG.error("%s: could not restart logging after the link came back: %s", self.uri, e)
        self._apply_user_params()
        self.state = WorkerState.RUNNING     # only now: log data queued during the outage is not "late"
        self.listener.on_link_restored()

    def _set_up_again(self) -> None:
        """After a reboot: the firmware answers, then log blocks, the user's parameters, thrust unlock."""
        self.cf.platform.detect_protocol_version()
        self.safety.note_stream_released(self._clock())
        if self._log_plan:
            self.cf.log.reset()
            self._start_log_blocks()
        for name, value in self.user_params.items():
            self.cf.params.set(name, value)
            self.param_values[name] = value
        self._release_thrust_lock()

    def _apply_user_params(self) -> None:
        """The parameters written through the server, set again (a Crazyflie restarted by hand meanwhile
        lost them; on one that kept them this writes the same values)."""
        for name, value in self.user_params.items():
            try:
                self.cf.params.set(name, value)
            except CrazyflieError as e:
                LOG.error("%s: could not set %s again after the link came back: %s", self.uri, name, e)

    def link_quality(self) -> Tuple[float, int]:
        """(acked / sent, samples) over the recent window, per radio packet, from the link's
        statistics (safelink re-sends hide losses from ``send``'s result)."""
        stats = self.cf.link.stats
        return stats.ack_ratio, stats.samples

    def _check_quality(self, now: float) -> None:
        q, samples = self.link_quality()
        if samples < LINK_QUALITY_MIN_SAMPLES:
            return
        if q < LINK_QUALITY_WARNING:
            if not self._quality_low or now - self._quality_warned_at >= self.quality_warning_interval:
                self._quality_low = True
                self._quality_warned_at = now
                LOG.warning("%s: link quality %.2f (below %.2f)", self.uri, q, LINK_QUALITY_WARNING)
                self.listener.on_link_quality(q, True)
        elif self._quality_low and q >= LINK_QUALITY_RECOVERED:
            self._quality_low = False
            LOG.info("%s: link quality back to %.2f", self.uri, q)
            self.listener.on_link_quality(q, False)
