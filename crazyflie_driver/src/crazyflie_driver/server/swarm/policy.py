"""Swarm mode's decisions, without ROS: the start sequence, the first fix, the watch's landings, the commands.

``SwarmPolicy`` adds every Crazyflie of the swarm file at once, opens one broadcaster over all their
radios, places each onboard estimator where motion capture first saw it (retrying a write lost on the
radio with the next pose), turns the watch's verdicts (stale pose, lost link) into a unicast land that
is retried until it is taken or is not needed, and refuses every flight command once the swarm is in
emergency. It reaches the server only through ``SwarmServer``, a narrow typed port (add, the workers
served, the radios, the radio budget, the clock), so a unit test drives it with a fake port and a
``ManualClock``; the ROS node (``nodes.swarm_ros``) keeps the services, topics and parameters.
"""
from __future__ import annotations

import functools
import logging
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Protocol, Sequence, Tuple

from crazyflie_driver.clock import Clock
from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import CommandRejected, CommandValueError, CrazyflieError, LogConfigError
from crazyflie_driver.server import radio_budget
from crazyflie_driver.server.log_plan import PACKETS_SWITCH, POSE_SWITCH, TOPIC_SWITCHES, LogBlockSpec
from crazyflie_driver.server.onboard_pose import pose_block
from crazyflie_driver.server.param_names import Lookup
from crazyflie_driver.server.swarm import estimator_placement
from crazyflie_driver.server.swarm.broadcast import SwarmBroadcaster
from crazyflie_driver.server.swarm.commands import SwarmCommands, SwarmMember, update_params
from crazyflie_driver.server.swarm.config import SwarmConfig, SwarmCrazyflie
from crazyflie_driver.server.swarm.heartbeat import Heartbeat
from crazyflie_driver.server.swarm.mocap_stream import MocapStream
from crazyflie_driver.server.swarm.options import SwarmOptions
from crazyflie_driver.server.swarm.unsupervised import (
    LeftOut,
    hearing_broadcasts,
    lock_on_ground,
    locked_text,
    unanswered_text,
    unicast,
)
from crazyflie_driver.server.swarm.watch import SwarmWatch
from crazyflie_driver.server.worker import WorkerConfig, WorkerState

LOG = logging.getLogger("crazyflie_driver.server.swarm")

#: s between two checks of stale poses and lost links.
WATCH_PERIOD_S = 0.02
#: Parameter writes of the first fixes at once (each an acknowledged request on its Crazyflie's radio).
FIRST_FIX_WRITERS = 8
#: Failed initial-position writes of one Crazyflie logged each; after these, every PLACEMENT_LOG_EVERY-th.
PLACEMENT_LOGGED_ATTEMPTS = 3
PLACEMENT_LOG_EVERY = 10
#: s between a swarm Crazyflie's polls when nothing is queued: the radio budget's keep-alive floor.
SWARM_KEEPALIVE_S = 1.0 / radio_budget.KEEPALIVE_FLOOR_HZ
#: ms between battery samples each swarm Crazyflie logs for its safety monitor when the sensor topics are
#: off (~enable_logging false, the default): without them a critical battery went unnoticed in the air
#: (bench/bench_faults_swarm.py). One log packet per 0.5 s, under the monitor's 1 s staleness.
BATTERY_WATCH_MS = 500
#: s between two tries of a watch's unicast land whose link is down.
LAND_RETRY_S = 0.1
#: s between two log lines about a land not delivered yet (one Crazyflie).
LAND_RETRY_LOG_EVERY_S = 2.0
#: Crazyflies connected at once at start.
MAX_PARALLEL_ADDS = 64
#: The swarm service that brings every Crazyflie back after an emergency (Crazyswarm2's ``all/`` prefix).
REBOOT_ALL_SERVICE = "/all/reboot"
#: s (server clock) a rebooted swarm waits for every Crazyflie to answer and be set up again.
REBOOT_BACK_S = 20.0
#: s between two looks at whether the rebooted Crazyflies are back.
REBOOT_POLL_S = 0.1


class SwarmServer(Protocol):
    """What the swarm needs from the server that serves its Crazyflies."""

    @property
    def clock(self) -> Clock:
        """The server's clock (the world's in simulation)."""
        ...

    def add(self, config: WorkerConfig) -> SwarmMember:
        """Connect and serve one Crazyflie; CrazyflieError or ValueError naming why it was not added
        (LogConfigError when its log blocks do not fit its firmware or name a variable it lacks)."""
        ...

    def served_workers(self) -> Iterable[Any]:
        """The workers the server serves now (one that gave up its link is gone)."""
        ...

    def radio_manager(self) -> Any:
        """The process's shared Crazyradios (``radio.shared_radio.RadioManager``)."""
        ...

    def add_broadcasts(self, dongle: int, stats: Any, burst: Optional[radio_budget.BroadcastDemand]) -> None:
        """Count a broadcast link's packets and its planned motion-capture bursts in the radio budget."""
        ...

    def shutting_down(self) -> bool:
        """The process is going away: no new work starts."""
        ...


def pose_periods(config: SwarmConfig, options: SwarmOptions) -> Dict[str, int]:
    """Each Crazyflie's onboard pose topic period (ms, 0: none): ``~pose_period_ms``, or where it is
    ``auto`` what its radio's budget allows."""
    if options.pose_period_ms is not None:
        return {cf.tf_prefix: options.pose_period_ms for cf in config.crazyflies}
    return radio_budget.pose_log_periods({cf.tf_prefix: cf.uri for cf in config.crazyflies})


def worker_config(cf: SwarmCrazyflie, options: SwarmOptions, pose_period_ms: int = 0,
                  custom_topics: bool = True) -> WorkerConfig:
    """The battery logged for the safety monitor even with the sensor topics off. No parameter read-back at
    connect: reading every parameter of 49 Crazyflies one by one takes
    ten times longer than connecting them (warm TOC cache); writes still convert by the TOC's types.
    Polls at the keep-alive floor: nothing streams setpoints, and 17 Crazyflies polling every 10 ms
    would fill their radio. crazyflie_ros HEAD's logging switches: the Crazyflie's (its own, then its
    type's), else the server's parameter, else on, except ``packets`` (off, as the sensor topics are in
    swarm mode: one publisher fewer per Crazyflie); ``enable_logging_pose: false`` drops the pose block.
    ``enable_logging_battery: false`` drops the battery topic, not the safety monitor's battery watch.
    ``custom_topics`` false leaves out the custom log topics (they cannot be served to this Crazyflie)."""
    switches = dict(options.switches)
    switches.update(cf.switches)
    blocks = (pose_block(pose_period_ms),) if pose_period_ms and switches.get(POSE_SWITCH, True) else ()
    return WorkerConfig(uri=cf.uri, tf_prefix=cf.tf_prefix, enable_logging=options.enable_logging,
                        enable_parameters=False,
                        log_blocks=blocks + (custom_log_blocks(cf, options) if custom_topics else ()),
                        keepalive_period=SWARM_KEEPALIVE_S,
                        battery_watch_ms=BATTERY_WATCH_MS,
                        disabled_topics=frozenset(t for n, t in TOPIC_SWITCHES if not switches.get(n, True)),
                        log_packets=switches.get(PACKETS_SWITCH, False))


def custom_log_blocks(cf: SwarmCrazyflie, options: SwarmOptions) -> Tuple[LogBlockSpec, ...]:
    """The Crazyflie's custom log topics: the server's generic ones (Crazyswarm's parameters), each replaced
    by a topic of the same name from the swarm file (Crazyswarm2's firmware_logging), then the file's others."""
    own = {b.topic_name for b in cf.log_blocks}
    return tuple(b for b in options.log_blocks if b.topic_name not in own) + cf.log_blocks


def custom_topics_dropped(cf: SwarmCrazyflie, options: SwarmOptions, why: str) -> str:
    """The error logged for a Crazyflie connected without its custom log topics."""
    names = "".join(" " + b.topic_name for b in custom_log_blocks(cf, options))
    return ("swarm: %s flies WITHOUT its custom log topics%s (from ~genericLogTopics and the swarm file's "
            "firmware_logging): %s; fix them there (each variable in its log TOC, each topic's values in one log "
            "block). Connected anyway: it hears the swarm's broadcasts, so it must be supervised"
            % (cf.tf_prefix, names, why))


def initial_position_params(position: Sequence[float]) -> Dict[str, Any]:
    """Crazyswarm's way to start the Kalman estimator at a known place: initial x/y/z, then reset.
    (A dict keeps this order: the reset must come after the position.)"""
    return {"kalman.initialX": float(position[0]), "kalman.initialY": float(position[1]),
            "kalman.initialZ": float(position[2]), "kalman.resetEstimation": 1}


def observe_in_safety(targets: Sequence[SwarmMember], what: str, duration: float, clock: Clock) -> None:
    """Each addressed Crazyflie's safety monitor learns of a swarm command (it flies, or lands by itself),
    so that a reaction (battery, shutdown) knows it is in the air and never lands it twice."""
    now = clock.now()
    for m in targets:
        m.worker.safety.note_high_level(now, what, duration)


def refusal_in_safety(member: SwarmMember, what: str, clock: Clock) -> Optional[str]:
    """Why a swarm command must not reach this Crazyflie now (a landing under way), from its safety monitor."""
    return member.worker.safety.refusal(clock.now(), what)


def height_in_safety(member: SwarmMember, clock: Clock) -> Optional[float]:
    """The height of the Crazyflie's last fresh pose, as its safety monitor knows it (None: unknown)."""
    return member.worker.safety.current_height(clock.now())


def refusal_text(service: str, error: Exception) -> str:
    """``<service> refused: <why>`` for a swarm service's caller and log, naming the service once (the
    policy's own refusals already start with it)."""
    why = str(error)
    return why if why.startswith(service + " ") else "%s refused: %s" % (service, why)


def _daemon(target: Callable[[], object], name: str) -> None:
    threading.Thread(target=target, name=name, daemon=True).start()


class SwarmPolicy:
    """Swarm mode inside a running server, timed on the server's clock. ``spawn(target, name)`` runs
    a background task (a daemon thread; a test may run it inline)."""

    def __init__(self, server: SwarmServer, options: SwarmOptions, config: SwarmConfig,
                 spawn: Callable[[Callable[[], object], str], None] = _daemon) -> None:
        self.server = server
        self.clock: Clock = server.clock
        self.options = options
        self.config = config
        self._spawn = spawn
        self.members: List[SwarmMember] = []
        self.failed: Dict[str, str] = {}
        self.connect_s = float("nan")
        self.commands: Optional[SwarmCommands] = None
        self.broadcaster: Optional[SwarmBroadcaster] = None
        self.stream: Optional[MocapStream] = None
        self.heartbeat: Optional[Heartbeat] = None
        self.watch = SwarmWatch([cf.tf_prefix for cf in config.crazyflies], options.stale_after, options.stale_hold)
        self.lock = threading.Lock()            # the watch and the link states (the diagnostics read them too)
        self.link_ok: Dict[str, bool] = {}
        self.emergency_active = False
        self.recovering = False                  # reboot_all is waiting for the Crazyflies to come back
        self.placement = estimator_placement.EstimatorPlacement(self.clock)
        self.pose_periods: Dict[str, int] = {}
        self.locked: Dict[str, str] = {}        # name -> URI: left out, motors locked on the ground
        self.log_topic_faults: Dict[str, str] = {}           # name -> why it flies without its custom log topics
        self._placement_attempts: Dict[str, int] = {}      # failed initial-position writes, per Crazyflie
        self._first_fixes: Optional[ThreadPoolExecutor] = None
        self._land_logged_at: Dict[str, float] = {}
        self._safety_of: Dict[str, Any] = {}                 # name -> safety monitor, for the pose hot path

    # -- start-up ---------------------------------------------------------------------------------
    def start(self) -> bool:
        """Connect and configure every Crazyflie of the file at once, then open the broadcaster and the
        swarm commands (and the emergency-stop watchdog's keep-alive). False when none could be added."""
        t0 = self.clock.now()
        self.pose_periods = pose_periods(self.config, self.options)
        for period in sorted(set(self.pose_periods.values())):
            LOG.info("swarm: onboard pose topic %s for %d Crazyflies%s", "every %d ms" % period if period else "off",
                     sum(p == period for p in self.pose_periods.values()),
                     " (radio budget)" if self.options.pose_period_ms is None else "")
        crazyflies = list(self.config.crazyflies)
        with ThreadPoolExecutor(max_workers=max(1, min(MAX_PARALLEL_ADDS, len(crazyflies)))) as pool:
            results = list(pool.map(self.add, crazyflies))
        self.connect_s = self.clock.now() - t0
        for cf, (member, error) in zip(crazyflies, results):
            if member is not None:
                self.members.append(member)
            else:
                self.failed[cf.tf_prefix] = error or "not added"
                LOG.error("swarm: %s (%s) was not added: %s", cf.tf_prefix, cf.uri, error)
        LOG.info("swarm: %d of %d Crazyflies connected and configured in %.2f s", len(self.members),
                 len(crazyflies), self.connect_s)
        if not self.members:
            LOG.error("swarm: no Crazyflie of %s could be added; no swarm services", self.config.source)
            return False
        self.lock_left_out()
        version = min(m.worker.cf.protocol_version for m in self.members)
        self.broadcaster = SwarmBroadcaster([m.uri for m in self.members], version, self.server.radio_manager(),
                                            repeats=self.options.broadcast_repeats,
                                            interval_s=self.options.broadcast_interval, sleep=self.clock.sleep)
        self.broadcaster.open()
        self.commands = SwarmCommands(self.live_members, self.broadcaster,
                                      observe=functools.partial(observe_in_safety, clock=self.clock),
                                      refusal=functools.partial(refusal_in_safety, clock=self.clock),
                                      height=functools.partial(height_in_safety, clock=self.clock))
        if self.options.emergency_watchdog:
            self.heartbeat = Heartbeat(self.broadcaster.watchdog, clock=self.clock).start()
        return True

    def add(self, cf: SwarmCrazyflie) -> Tuple[Optional[SwarmMember], Optional[str]]:
        """Connect one Crazyflie and configure it: (member, None) or (None, reason)."""
        try:
            member = self._connect(cf)
        except (CrazyflieError, ValueError) as e:
            return None, str(e)
        params = dict(cf.params)
        if self.options.mocap == "none":
            # no motion capture to take the first fix from: the file's initial position
            params.update(initial_position_params(cf.initial_position))
        _, errors = member.worker.update_params(params)
        for error in errors:
            LOG.error("swarm: %s: firmware parameter from %s not written: %s", cf.tf_prefix, self.config.source,
                      error)
        try:
            if cf.group_mask:
                member.onboard.set_group_mask(cf.group_mask)
            # the connect's zero setpoints hold the priority: hand it to the high-level commander
            # now, on the ground, where its idle planner just keeps the motors off
            member.onboard.notify_setpoints_stop(0)
        except (CrazyflieError, ValueError) as e:
            LOG.warning("swarm: %s: %s", cf.tf_prefix, e)
        return member, None

    def _connect(self, cf: SwarmCrazyflie) -> SwarmMember:
        """Add one Crazyflie to the server. One whose custom log topics cannot be served (a fault in the file,
        or its firmware refuses them) is connected without them, with an error: left unconnected it would
        still hear the broadcast takeoff and fly unsupervised."""
        period = self.pose_periods.get(cf.tf_prefix, 0)
        if cf.log_error:
            self.log_topic_faults[cf.tf_prefix] = cf.log_error
            LOG.error(custom_topics_dropped(cf, self.options, cf.log_error))
            return self.server.add(worker_config(cf, self.options, period, custom_topics=False))
        try:
            return self.server.add(worker_config(cf, self.options, period))
        except LogConfigError as e:
            if not custom_log_blocks(cf, self.options):
                raise
            self.log_topic_faults[cf.tf_prefix] = str(e)
            LOG.error(custom_topics_dropped(cf, self.options, str(e)))
        return self.server.add(worker_config(cf, self.options, period, custom_topics=False))

    def lock_left_out(self) -> None:
        """Before the first broadcast: lock the motors of each Crazyflie of the file that was not added but
        listens on a channel the swarm broadcasts on (``unsupervised``); name the ones that do not answer."""
        left_out = [LeftOut(cf.tf_prefix, cf.uri, self.failed[cf.tf_prefix]) for cf in self.config.crazyflies
                    if cf.tf_prefix in self.failed]
        for cf in hearing_broadcasts(left_out, [m.uri for m in self.members]):
            try:
                with unicast(cf.uri, self.server.radio_manager()) as send:
                    acked = lock_on_ground(send)
            except CrazyflieError as e:
                LOG.error(unanswered_text(cf, str(e)))
                continue
            if acked:
                self.locked[cf.name] = cf.uri
                LOG.error(locked_text(cf))
            else:
                LOG.error(unanswered_text(cf, "not acknowledged"))

    def live_members(self) -> List[SwarmMember]:
        """The members whose worker the server still serves (one that gave up is left out)."""
        served = set(id(w) for w in self.server.served_workers())
        return [m for m in self.members if id(m.worker) in served]

    # -- commands ---------------------------------------------------------------------------------
    def _flight_commands(self, what: str) -> SwarmCommands:
        """The swarm commands, once started and while not in emergency (CommandRejected otherwise)."""
        if self.emergency_active:
            raise CommandRejected("%s refused: the swarm is in emergency (%s)" % (what, self.emergency_advice()))
        if self.commands is None:
            raise CommandRejected("%s refused: the swarm has not started (no Crazyflie added yet)" % what)
        return self.commands

    def takeoff(self, group_mask: int, height: float, duration_s: float) -> int:
        """Takeoff of the addressed Crazyflies; with motion capture, not before each estimator is placed.
        A Crazyflie the watch landed is watched again once it takes off."""
        commands = self._flight_commands("/takeoff")
        targets = commands.targets(group_mask)
        if self.options.mocap != "none":    # the server places the estimators: not before they are placed
            # (decided by the options, not by the stream: a takeoff can come between start and start_stream)
            missing = self.placement.missing([m.name for m in targets])
            if missing:
                raise CommandValueError(estimator_placement.refusal(missing))
        sent = commands.takeoff(group_mask, height, duration_s)
        with self.lock:
            for m in targets:
                self.watch.rearm(m.name)
        return sent

    def land(self, group_mask: int, height: float, duration_s: float) -> int:
        return self._flight_commands("/land").land(group_mask, height, duration_s)

    def go_to(self, group_mask: int, offset: Sequence[float], yaw: float, duration_s: float) -> int:
        return self._flight_commands("/go_to").go_to(group_mask, offset, yaw, duration_s)

    def start_trajectory(self, group_mask: int, trajectory_id: int, timescale: float, reversed_: bool) -> int:
        return self._flight_commands("/start_trajectory").start_trajectory(group_mask, trajectory_id, timescale,
                                                                           reversed_)

    def stop(self, group_mask: int) -> int:
        return self._flight_commands("/stop").stop(group_mask)

    def notify_setpoints_stop(self, group_mask: int, remain_valid_ms: int) -> int:
        """Crazyswarm2's ``all/notify_setpoints_stop``: the high-level commander takes over again on every
        Crazyflie of ``group_mask`` (0: all). Acknowledged unicast to each, not one broadcast: the packet
        has no group mask, and each Crazyflie's own low-level stream must stop with it (the per-Crazyflie
        ``notify_setpoints_stop`` does both). CrazyflieError naming those it failed for; the count sent."""
        targets = self._flight_commands("/all/notify_setpoints_stop").targets(group_mask)
        failed = []
        for m in targets:
            try:
                m.onboard.notify_setpoints_stop(remain_valid_ms)
            except CrazyflieError as e:
                failed.append("%s: %s" % (m.name, e))
        if failed:
            raise CrazyflieError("notify-setpoints-stop failed for %d Crazyflie(s): %s; the others took it"
                                 % (len(failed), "; ".join(failed[:5])))
        return len(targets)

    def arm(self, arm: bool) -> None:
        """Crazyswarm2's ``all/arm``: arm (or disarm) every Crazyflie by one broadcast per radio."""
        if self.broadcaster is None:
            raise CommandRejected("/all/arm refused: the swarm has not started (no Crazyflie added yet)")
        self.broadcaster.arm(arm)

    def emergency(self) -> List[str]:
        """Motors off for every Crazyflie, for good: the pose stream and the watchdog keep-alive stop (the
        watchdog then stops any Crazyflie the e-stop missed). Returns what failed (never raises)."""
        self.emergency_active = True
        if self.stream is not None:
            self.stream.pause()
        if self.heartbeat is not None:
            self.heartbeat.stop()
        return self.commands.emergency() if self.commands is not None else []

    def emergency_advice(self) -> str:
        """What brings the swarm back after an emergency, for refusals and the log."""
        if self.recovering:
            return "its Crazyflies are rebooting; flight commands are taken again once all are back"
        return ("the motors stay off until a reboot: %s reboots every Crazyflie, and the swarm flies again once "
                "all are back" % REBOOT_ALL_SERVICE)

    def reboot_all(self) -> List[str]:
        """``/all/reboot``: reboot every Crazyflie of the swarm, refused whole (nothing sent) while any of
        them flies. Once each answers again and is set up again (its log blocks and parameters by its
        worker; its group mask, the high-level commander's priority and a first fix from its next pose
        here), an emergency is over: the pose stream and the watchdog keep-alive go on. Runs the wait in
        the background; returns the names rebooted."""
        if self.commands is None:
            raise CommandRejected("%s refused: the swarm has not started (no Crazyflie added yet)"
                                  % REBOOT_ALL_SERVICE)
        if self.recovering:
            raise CommandRejected("%s refused: a reboot of the swarm is under way" % REBOOT_ALL_SERVICE)
        members = self.live_members()
        refusals = ["%s: %s" % (m.name, why) for m in members for why in [m.worker.reboot_refusal()] if why]
        if refusals:
            raise CommandRejected("%s refused, nothing sent: %s" % (REBOOT_ALL_SERVICE, "; ".join(refusals)))
        self.recovering = True
        self.placement = estimator_placement.EstimatorPlacement(self.clock)    # a rebooted estimator is unplaced
        rebooted: List[SwarmMember] = []
        for m in members:
            try:
                m.worker.reboot()
                rebooted.append(m)
            except CrazyflieError as e:
                LOG.error("swarm: %s: not rebooted: %s", m.name, e)
        LOG.warning("swarm: %d of %d Crazyflies rebooting; flight commands wait until all are back",
                    len(rebooted), len(members))
        self._spawn(functools.partial(self.come_back, rebooted, len(rebooted) == len(members)), "swarm reboot")
        return [m.name for m in rebooted]

    def come_back(self, rebooted: Sequence[SwarmMember], all_rebooted: bool) -> bool:
        """After ``reboot_all``: wait (REBOOT_BACK_S at most) for each rebooted Crazyflie's worker to run
        again, set up what the swarm set up, and leave emergency when every Crazyflie came back. Whether
        the swarm flies again."""
        deadline = self.clock.now() + REBOOT_BACK_S
        waiting = list(rebooted)
        while waiting and self.clock.now() < deadline and not self.server.shutting_down():
            waiting = [m for m in waiting if m.worker.state != WorkerState.RUNNING]
            if waiting:
                self.clock.sleep(REBOOT_POLL_S)
        back = [m for m in rebooted if m not in waiting]
        groups = {cf.tf_prefix: cf.group_mask for cf in self.config.crazyflies}
        for m in back:
            try:
                if groups.get(m.name):
                    m.onboard.set_group_mask(groups[m.name])
                m.onboard.notify_setpoints_stop(0)
            except (CrazyflieError, ValueError) as e:
                LOG.warning("swarm: %s: after the reboot: %s", m.name, e)
            if self.stream is not None:
                self.stream.refix(m.name)
        self.recovering = False
        if waiting or not all_rebooted:
            LOG.error("swarm: still in emergency: %s did not come back within %.0f s; call %s again",
                      ", ".join(m.name for m in waiting) or "not every Crazyflie rebooted", REBOOT_BACK_S,
                      REBOOT_ALL_SERVICE)
            return False
        self.emergency_active = False
        if self.stream is not None:
            self.stream.pause(False)
        if self.options.emergency_watchdog and self.broadcaster is not None:
            self.heartbeat = Heartbeat(self.broadcaster.watchdog, clock=self.clock).start()
        LOG.warning("swarm: all %d Crazyflies back after the reboot: flight commands are taken again", len(back))
        return True

    def update_params(self, names: Sequence[str], lookup: Lookup) -> Dict[str, List[str]]:
        """``/update_params`` of the swarm (``commands.update_params``): {parameter: [Crazyflies written]};
        ValueError naming what was not applied. While first fixes are still to come it waits for them
        first (up to the takeoff's ``PLACEMENT_WAIT_S``): every Crazyflie answers each write, and a
        placement's request would wait behind those answers in its transmit queue."""
        members = self.live_members()
        if self.stream is not None:
            self.placement.missing([m.name for m in members])
        written, errors = update_params(members, names, lookup, self.broadcaster)
        for name, cfs in written.items():
            LOG.info("swarm: parameter %s updated on %d Crazyflie(s)", name, len(cfs))
        if errors:
            raise ValueError("%d not applied: %s" % (len(errors), "; ".join(errors[:10])))
        return written

    # -- motion capture ---------------------------------------------------------------------------
    def mocap_plan(self) -> List[radio_budget.BroadcastDemand]:
        """Each radio's motion-capture bursts at the rate its budget allows beside its Crazyflies' unicast
        needs and the reserve for requests (``radio_budget.mocap_rate_hz``); a Crazyradio 2.0 with inline
        mode is planned without control transfers."""
        demands = [radio_budget.CrazyflieDemand(m.name, parse_uri(m.uri), 0.0, 0.0, m.worker.log_packet_rate)
                   for m in self.members]
        links = self.broadcaster.links if self.broadcaster is not None else {}
        inline = {key[0] for key, link in links.items() if link.sends_inline}
        return radio_budget.mocap_plan(demands, self.options.mocap_rate, not self.options.position_only, inline)

    def start_stream(self) -> Optional[MocapStream]:
        """The pose stream to the members' estimators, planned on the radio budget (None without motion
        capture). Poses come in through ``pose``."""
        if self.options.mocap == "none" or self.broadcaster is None:
            return None
        plan = self.mocap_plan()
        for burst in plan:
            LOG.info("swarm: motion capture on radio %d at %.0f Hz (%d packets a burst; radio budget)",
                     burst.dongle, burst.frames_hz, burst.packets)
        for key, link in self.broadcaster.links.items():
            self.server.add_broadcasts(key[0], link.stats, next((b for b in plan if b.dongle == key[0]), None))
        self._safety_of = {m.name: m.worker.safety for m in self.members}
        self._first_fixes = ThreadPoolExecutor(max_workers=FIRST_FIX_WRITERS, thread_name_prefix="first fix")
        self.stream = MocapStream({m.name: m.uri for m in self.members}, self.broadcaster.send_poses,
                                  self.options.position_only, on_first_fix=self.first_fix, on_pose=self.pose_seen,
                                  radio_of=lambda uri: parse_uri(uri).index,
                                  frame_periods={b.dongle: 1.0 / b.frames_hz for b in plan},
                                  clock=self.clock.now, sleep=self.clock.sleep).start()
        return self.stream

    def pose(self, name: str, position: Sequence[float], orientation: Optional[Sequence[float]] = None,
             received: Optional[float] = None) -> bool:
        """A pose from motion capture (any source); whether the stream took it. A taken pose is also the
        height a safety landing of that Crazyflie starts from."""
        stream = self.stream
        if stream is None:
            return False
        taken = stream.pose(name, position, orientation, received)
        monitor = self._safety_of.get(name)
        if taken and monitor is not None:
            monitor.note_pose(self.clock.now(), position[2])
        return taken

    def pose_seen(self, name: str, now: float) -> None:
        with self.lock:
            self.watch.pose_seen(name, now)

    def first_fix(self, name: str, position: Sequence[float]) -> None:
        """The estimator starts where motion capture first saw the Crazyflie (as Crazyswarm does).

        The parameter writes wait for their answers: they run in a small pool (``FIRST_FIX_WRITERS``),
        so the stream never waits for them and the Crazyflies of a swarm are set up several at a
        time, the radios' unicast reserve shared among them.
        """
        member = next((m for m in self.members if m.name == name), None)
        if member is None or self._first_fixes is None:
            return
        self._first_fixes.submit(self.write_initial_position, member, position)

    def write_initial_position(self, member: SwarmMember, position: Sequence[float]) -> bool:
        """One first-fix write; a write lost on the radio asks the stream for the next pose's fix (its
        takeoff would be refused while it is unplaced). Whether it was placed."""
        if self.server.shutting_down():
            return False
        name = member.name
        _, errors = member.worker.update_params(initial_position_params(position))
        if errors:
            attempts = self._placement_attempts[name] = self._placement_attempts.get(name, 0) + 1
            if attempts <= PLACEMENT_LOGGED_ATTEMPTS or attempts % PLACEMENT_LOG_EVERY == 0:
                LOG.error("swarm: %s: initial position from its first pose not written (attempt %d): %s; "
                          "trying again with its next pose", name, attempts, "; ".join(errors))
            if self.stream is not None and not self.server.shutting_down():
                self.stream.refix(name)
            return False
        self.placement.placed(name)
        LOG.info("swarm: %s first seen at (%.3f, %.3f, %.3f): estimator reset there", name, *position)
        return True

    # -- watching -----------------------------------------------------------------------------------
    def watch_loop(self) -> None:
        """Check every ``WATCH_PERIOD_S`` until the process shuts down; a failed check never ends it."""
        while not self.server.shutting_down():
            self.clock.sleep(WATCH_PERIOD_S)
            try:
                self.check(self.clock.now())
            except Exception as e:      # never let bookkeeping end the watch
                LOG.error("swarm: watch failed: %r", e)

    def check(self, now: float) -> List[str]:
        """Note each live member's link, then act on the watch's events; the names told to land now."""
        members = {m.name: m for m in self.live_members()}
        with self.lock:
            for name, m in members.items():
                ok = m.worker.state != WorkerState.LOST
                if self.link_ok.get(name, True) != ok:
                    self.link_ok[name] = ok
                    if not ok:
                        LOG.error("swarm: %s: radio link lost; %s", name, self.link_lost_outcome())
                    else:
                        LOG.warning("swarm: %s: radio link back", name)
                self.watch.link(name, ok, now)
            events = self.watch.check(now)
        landing: List[str] = []
        for ev in events:
            if ev.kind == "stale":
                LOG.warning("swarm: %s: no pose for %.2f s (%s); it lands in %.1f s unless the pose comes back",
                            ev.name, ev.age, self.stale_cause(ev.name), self.options.stale_hold)
            elif ev.kind == "fresh":
                LOG.info("swarm: %s: pose back", ev.name)
            elif ev.kind == "land" and ev.name in members and not self.emergency_active:
                LOG.error("swarm: %s: landing by itself: %s", ev.name, ev.reason)
                self._spawn(functools.partial(self.land_one, members[ev.name], ev.reason), "land %s" % ev.name)
                landing.append(ev.name)
        return landing

    def stale_cause(self, name: str) -> str:
        if self.emergency_active:
            return "the emergency stopped the stream"
        refusal = self.stream.last_refusal.get(name) if self.stream is not None else None
        return "its poses are refused: %s" % refusal if refusal else "motion capture lost it"

    def link_lost_outcome(self) -> str:
        """What happens to a Crazyflie whose link is lost (for the log and /diagnostics)."""
        if self.heartbeat is not None and self.heartbeat.running:
            return ("its motors stop 1 s after the last emergency-stop watchdog keep-alive it heard (restart it "
                    "before flying it again); it is told to land if the link comes back first")
        return ("it is told to land once the link comes back (without ~emergency_watchdog nothing onboard stops "
                "it meanwhile: it flies on)")

    def land_one(self, member: SwarmMember, reason: str) -> bool:
        """Unicast land, retried every ``LAND_RETRY_S`` while it does not reach the Crazyflie, until it is
        taken (True) or not needed or not sendable (False): a refusal (``CommandRejected``: on the ground,
        in emergency) means there is nothing to land; a land its checks refuse is never retried."""
        while not self.server.shutting_down() and not self.emergency_active \
                and member.worker.state != WorkerState.STOPPED:
            try:
                member.onboard.land(0, 0.0, self.options.stale_land_duration)
                return True
            except CommandRejected as e:
                LOG.info("swarm: %s: land not needed: %s", member.name, e)
                return False
            except CommandValueError as e:
                LOG.error("swarm: %s: land (%s) cannot be sent: %s", member.name, reason, e)
                return False
            except CrazyflieError as e:
                now = self.clock.now()
                if now - self._land_logged_at.get(member.name, -float("inf")) >= LAND_RETRY_LOG_EVERY_S:
                    self._land_logged_at[member.name] = now
                    LOG.warning("swarm: %s: land (%s) not delivered yet: %s", member.name, reason, e)
            self.clock.sleep(LAND_RETRY_S)
        return False

    def member_names(self) -> Mapping[str, str]:
        """{name: URI} of every member."""
        return {m.name: m.uri for m in self.members}

    def shutdown(self) -> None:
        """Stop the stream, the first fixes, the keep-alive and the broadcaster (never raises)."""
        if self.stream is not None:
            self.stream.stop()
        if self._first_fixes is not None:
            self._first_fixes.shutdown(wait=False)
        if self.heartbeat is not None:
            self.heartbeat.stop()
        if self.broadcaster is not None:
            self.broadcaster.close()
