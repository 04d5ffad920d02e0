"""Swarm mode of ``crazyflie_server`` (``~swarm_file``): the ROS face of the swarm.

Adds every Crazyflie of the swarm file at once, writes their firmware parameters, and serves at the
root namespace, as Crazyswarm does: ``/takeoff``, ``/land``, ``/go_to``, ``/start_trajectory``,
``/stop`` (broadcasts with group masks, ``server.swarm.commands``), ``/emergency`` (broadcast and
unicast e-stop to all) and ``/update_params``. Streams motion capture (VRPN, tf or PoseStamped
topics) to the onboard estimators in packed broadcasts (``server.swarm.mocap_stream``), lands a Crazyflie
whose pose goes stale or whose link is lost (``server.swarm.watch``), and reports both in the log
and on ``/diagnostics``.
"""
from __future__ import annotations

import functools
import math
import statistics
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Dict, List, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_srvs.srv import Empty, EmptyResponse

from crazyflie_driver import usb_choice
from crazyflie_driver.clock import WALL, Clock
from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import CommandValueError, CrazyflieError
from crazyflie_driver.nodes import swarm_mocap_sources
from crazyflie_driver.nodes.ros_signals import publish_unless_shutting_down, shutting_down
from crazyflie_driver.radio.crazyradio import list_radios
from crazyflie_driver.server.swarm.mocap_stream import MocapStream
from crazyflie_driver.server import radio_budget
from crazyflie_driver.server.swarm import estimator_placement
from crazyflie_driver.server.onboard_pose import pose_block
from crazyflie_driver.server.swarm.broadcast import SwarmBroadcaster
from crazyflie_driver.server.swarm.commands import SwarmCommands, SwarmMember, update_params
from crazyflie_driver.server.swarm.config import SwarmConfig, SwarmCrazyflie, load_swarm_file
from crazyflie_driver.server.swarm.heartbeat import Heartbeat
from crazyflie_driver.server.swarm.options import SwarmOptions, options_from_params
from crazyflie_driver.server.swarm.watch import SwarmWatch
from crazyflie_driver.server.worker import WorkerConfig, WorkerState
from crazyflie_driver.srv import (GoTo, GoToResponse, Land, LandResponse, StartTrajectory, StartTrajectoryResponse,
                                  Stop, StopResponse, Takeoff, TakeoffResponse, UpdateParams, UpdateParamsResponse)

DIAGNOSTICS_PERIOD_S = 1.0


WATCH_PERIOD_S = 0.02           # how often stale poses and lost links are checked
#: Parameter writes of the first fixes at once (each an acknowledged request on its Crazyflie's radio).
FIRST_FIX_WRITERS = 8
#: Failed initial-position writes of one Crazyflie logged each; after these, every PLACEMENT_LOG_EVERY-th.
PLACEMENT_LOGGED_ATTEMPTS = 3
PLACEMENT_LOG_EVERY = 10
#: s between a swarm Crazyflie's polls when nothing is queued: the radio budget's keep-alive floor.
SWARM_KEEPALIVE_S = 1.0 / radio_budget.KEEPALIVE_FLOOR_HZ


def pose_periods(config: SwarmConfig, options: SwarmOptions) -> Dict[str, int]:
    """Each Crazyflie's onboard pose topic period (ms, 0: none): ``~pose_period_ms``, or where it is
    ``auto`` what its radio's budget allows."""
    if options.pose_period_ms is not None:
        return {cf.tf_prefix: options.pose_period_ms for cf in config.crazyflies}
    return radio_budget.pose_log_periods({cf.tf_prefix: cf.uri for cf in config.crazyflies})


def ros_param_or_none(name: str) -> Any:
    """The ROS parameter ``name``, None when it is not set (one call to the master)."""
    try:
        return rospy.get_param(name)
    except KeyError:
        return None


def worker_config(cf: SwarmCrazyflie, options: SwarmOptions, pose_period_ms: int = 0) -> WorkerConfig:
    """No parameter read-back at connect: reading every parameter of 49 Crazyflies one by one takes
    ten times longer than connecting them (warm TOC cache); writes still convert by the TOC's types.
    Polls at the keep-alive floor: nothing streams setpoints, and 17 Crazyflies polling every 10 ms
    would fill their radio."""
    blocks = (pose_block(pose_period_ms),) if pose_period_ms else ()
    return WorkerConfig(uri=cf.uri, tf_prefix=cf.tf_prefix, enable_logging=options.enable_logging,
                        enable_parameters=False, log_blocks=blocks, keepalive_period=SWARM_KEEPALIVE_S)


def count_dongles(wait_s: float) -> int:
    """Crazyradios present (the simulated world's once it answers, waiting up to ``wait_s``).

    Wall seconds: finding USB devices (or the world's fake ones) is a matter of the host, as on hardware."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            n = len(list_radios(usb_choice.get_backend()))
        except (CrazyflieError, OSError, ConnectionError) as e:
            n, error = 0, e
        else:
            error = None
        if n or time.monotonic() >= deadline or shutting_down():
            if error is not None and not n:
                rospy.logwarn("swarm: no Crazyradio found (%s)", error)
            return n
        time.sleep(0.5)


class RosSwarm:
    """Swarm mode inside a running ``CrazyflieServer``, timed on the server's clock."""

    def __init__(self, server, options: SwarmOptions, config: SwarmConfig) -> None:
        self.server = server
        self.clock: Clock = getattr(server, "clock", WALL)
        self.options = options
        self.config = config
        self.members: List[SwarmMember] = []
        self.failed: Dict[str, str] = {}
        self.connect_s = float("nan")
        self.commands: Optional[SwarmCommands] = None
        self.broadcaster: Optional[SwarmBroadcaster] = None
        self.stream: Optional[MocapStream] = None
        self.watch = SwarmWatch([cf.tf_prefix for cf in config.crazyflies], options.stale_after, options.stale_hold)
        self._watch_lock = threading.Lock()
        self._emergency = False
        self._services: List[Any] = []
        self._sources: List[Any] = []
        self._link_ok: Dict[str, bool] = {}
        self._diag_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        self._first_fixes: Optional[ThreadPoolExecutor] = None
        self.placement = estimator_placement.EstimatorPlacement(self.clock)
        self._placement_attempts: Dict[str, int] = {}      # failed initial-position writes, per Crazyflie
        self.heartbeat: Optional[Heartbeat] = None
        self._pose_periods: Dict[str, int] = {}

    # -- start-up ---------------------------------------------------------------------------------
    def start(self) -> None:
        if not rospy.has_param("~budget_setpoint_rate"):
            self.server.budget_setpoint_rate = 0.0     # nothing streams setpoints in swarm mode
        t0 = self.clock.now()
        by_name = {cf.tf_prefix: cf for cf in self.config.crazyflies}
        self._pose_periods = pose_periods(self.config, self.options)
        for period in sorted(set(self._pose_periods.values())):
            rospy.loginfo("swarm: onboard pose topic %s for %d Crazyflies%s", "every %d ms" % period if period
                          else "off", sum(p == period for p in self._pose_periods.values()),
                          " (radio budget)" if self.options.pose_period_ms is None else "")
        with ThreadPoolExecutor(max_workers=max(1, min(64, len(by_name)))) as pool:
            results = list(pool.map(self._add, self.config.crazyflies))
        self.connect_s = self.clock.now() - t0
        for cf, (member, error) in zip(self.config.crazyflies, results):
            if member is not None:
                self.members.append(member)
            else:
                self.failed[cf.tf_prefix] = error
                rospy.logerr("swarm: %s (%s) was not added: %s", cf.tf_prefix, cf.uri, error)
        rospy.loginfo("swarm: %d of %d Crazyflies connected and configured in %.2f s", len(self.members),
                      len(by_name), self.connect_s)
        if not self.members:
            rospy.logerr("swarm: no Crazyflie of %s could be added; no swarm services", self.config.source)
            return
        version = min(m.worker.cf.protocol_version for m in self.members)
        self.broadcaster = SwarmBroadcaster([m.uri for m in self.members], version, usb_choice.radio_manager(),
                                            repeats=self.options.broadcast_repeats,
                                            interval_s=self.options.broadcast_interval, sleep=self.clock.sleep)
        self.broadcaster.open()
        self.commands = SwarmCommands(self.live_members, self.broadcaster,
                                      observe=functools.partial(observe_in_safety, clock=self.clock),
                                      refusal=functools.partial(refusal_in_safety, clock=self.clock),
                                      height=functools.partial(height_in_safety, clock=self.clock))
        if self.options.emergency_watchdog:
            self.heartbeat = Heartbeat(self.broadcaster.watchdog, clock=self.clock).start()
        self._advertise()
        self._start_mocap({m.name: m.uri for m in self.members})
        threading.Thread(target=self._watch_loop, name="swarm watch", daemon=True).start()
        threading.Thread(target=self._diagnostics_loop, name="swarm diagnostics", daemon=True).start()
        rospy.loginfo("swarm ready: %d Crazyflies on %d radio link(s), motion capture: %s", len(self.members),
                      len(self.broadcaster.links), self.options.mocap)

    def _add(self, cf: SwarmCrazyflie):
        """Connect one Crazyflie and configure it: (member, None) or (None, reason)."""
        try:
            ros = self.server.add(worker_config(cf, self.options, self._pose_periods.get(cf.tf_prefix, 0)))
        except (rospy.ServiceException, CrazyflieError, ValueError) as e:
            return None, str(e)
        member = SwarmMember(cf.tf_prefix, str(ros.config.uri), ros.worker, ros.onboard_commands)
        params = dict(cf.params)
        if self.options.mocap == "none":
            # no motion capture to take the first fix from: the file's initial position
            params.update(initial_position_params(cf.initial_position))
        written, errors = ros.worker.update_params(params)
        for e in errors:
            rospy.logerr("swarm: %s: firmware parameter from %s not written: %s", cf.tf_prefix,
                         self.config.source, e)
        try:
            if cf.group_mask:
                member.onboard.set_group_mask(cf.group_mask)
            # the connect's zero setpoints hold the priority: hand it to the high-level commander
            # now, on the ground, where its idle planner just keeps the motors off
            member.onboard.notify_setpoints_stop(0)
        except (CrazyflieError, ValueError) as e:
            rospy.logwarn("swarm: %s: %s", cf.tf_prefix, e)
        return member, None

    def live_members(self) -> List[SwarmMember]:
        """The members whose worker the server still serves (one that gave up is left out)."""
        served = set(id(w) for w in self.server.registry.workers())
        return [m for m in self.members if id(m.worker) in served]

    # -- services ---------------------------------------------------------------------------------
    def _advertise(self) -> None:
        c = self.commands
        services = [
            ("/takeoff", Takeoff, TakeoffResponse, self._takeoff),
            ("/land", Land, LandResponse, lambda r: c.land(r.groupMask, r.height, r.duration.to_sec())),
            ("/go_to", GoTo, GoToResponse, lambda r: c.go_to(r.groupMask, (r.goal.x, r.goal.y, r.goal.z), r.yaw,
                                                            r.duration.to_sec())),
            ("/start_trajectory", StartTrajectory, StartTrajectoryResponse,
             lambda r: c.start_trajectory(r.groupMask, r.trajectoryId, r.timescale, r.reversed)),
            ("/stop", Stop, StopResponse, lambda r: c.stop(r.groupMask)),
            ("/update_params", UpdateParams, UpdateParamsResponse, self._update_params),
        ]
        for name, kind, response, handler in services:
            self._services.append(rospy.Service(name, kind, self._service(name, handler, response)))
        self._services.append(rospy.Service("/emergency", Empty, self._on_emergency))

    def _service(self, name: str, handler: Callable[[Any], Any], response: type) -> Callable[[Any], Any]:
        def callback(req):
            if self._emergency and name != "/update_params":
                raise rospy.ServiceException("%s refused: the swarm is in emergency (restart the Crazyflies and "
                                             "the server to fly again)" % name)
            try:
                handler(req)
            except (ValueError, CrazyflieError) as e:
                rospy.logerr("swarm: %s refused: %s", name, e)
                raise rospy.ServiceException("%s: %s" % (name, e))
            return response()
        return callback

    def _takeoff(self, req) -> None:
        targets = self.commands.targets(req.groupMask)
        if self.stream is not None:     # the server places the estimators: not before they are placed
            missing = self.placement.missing([m.name for m in targets])
            if missing:
                raise CommandValueError(estimator_placement.refusal(missing))
        self.commands.takeoff(req.groupMask, req.height, req.duration.to_sec())
        with self._watch_lock:
            for m in targets:
                self.watch.rearm(m.name)

    def _on_emergency(self, _req) -> EmptyResponse:
        self._emergency = True
        if self.stream is not None:
            self.stream.pause()
        if self.heartbeat is not None:
            self.heartbeat.stop()
        failures = self.commands.emergency()
        rospy.logwarn("swarm: EMERGENCY: e-stop broadcast on every radio and sent to each of %d Crazyflies%s",
                      len(self.members), "; failed: " + "; ".join(failures) if failures else "")
        return EmptyResponse()

    def _update_params(self, req) -> None:
        """Each name from /allcfs/<group>/<name> (for every Crazyflie) or else /<tf_prefix>/<group>/<name>, each
        ROS parameter read once: an /allcfs value by one broadcast on every radio, the others by acknowledged
        unicast, the radios in parallel (``swarm.commands.update_params``); the first-fix writes keep their own
        pool. While first fixes are still to come, it waits for them first (up to the takeoff's
        ``PLACEMENT_WAIT_S``): every Crazyflie answers each write, and a placement's request would wait behind
        those answers in its transmit queue (bench/results/swarm_params.txt: placement 2.6 s -> 5.0 s)."""
        members = self.live_members()
        if self.stream is not None:
            self.placement.missing([m.name for m in members])
        written, errors = update_params(members, req.params, ros_param_or_none, self.broadcaster)
        for name, cfs in written.items():
            rospy.loginfo("swarm: parameter %s updated on %d Crazyflie(s)", name, len(cfs))
        if errors:
            raise ValueError("%d not applied: %s" % (len(errors), "; ".join(errors[:10])))

    # -- motion capture ---------------------------------------------------------------------------
    def mocap_plan(self) -> List[radio_budget.BroadcastDemand]:
        """Each radio's motion-capture bursts at the rate its budget allows beside its Crazyflies' unicast
        needs and the reserve for requests (``radio_budget.mocap_rate_hz``)."""
        demands = [radio_budget.CrazyflieDemand(m.name, parse_uri(m.uri), 0.0, 0.0, m.worker.log_packet_rate)
                   for m in self.members]
        return radio_budget.mocap_plan(demands, self.options.mocap_rate, not self.options.position_only)

    def _start_mocap(self, uris: Dict[str, str]) -> None:
        if self.options.mocap == "none":
            return
        plan = self.mocap_plan()
        for burst in plan:
            rospy.loginfo("swarm: motion capture on radio %d at %.0f Hz (%d packets a burst; radio budget)",
                          burst.dongle, burst.frames_hz, burst.packets)
        for key, link in self.broadcaster.links.items():
            self.server.add_broadcasts(key[0], link.stats, next((b for b in plan if b.dongle == key[0]), None))
        self._first_fixes = ThreadPoolExecutor(max_workers=FIRST_FIX_WRITERS, thread_name_prefix="first fix")
        self.stream = MocapStream(uris, self.broadcaster.send_poses, self.options.position_only,
                                  on_first_fix=self._first_fix, on_pose=self._pose_seen,
                                  radio_of=lambda uri: parse_uri(uri).index,
                                  frame_periods={b.dongle: 1.0 / b.frames_hz for b in plan},
                                  clock=self.clock.now, sleep=self.clock.sleep).start()
        names = {self.options.mocap_pattern.format(name=name): name for name in uris}
        monitors = {m.name: m.worker.safety for m in self.members}
        stream = self.stream

        def pose(name, position, orientation=None, received=None):
            taken = stream.pose(name, position, orientation, received)
            monitor = monitors.get(name)
            if taken and monitor is not None:     # the height a safety landing starts from
                monitor.note_pose(self.clock.now(), position[2])
            return taken
        self._sources.append(swarm_mocap_sources.start(self.options, names, pose, self.clock))

    def _pose_seen(self, name: str, now: float) -> None:
        with self._watch_lock:
            self.watch.pose_seen(name, now)

    def _first_fix(self, name: str, position) -> None:
        """The estimator starts where motion capture first saw the Crazyflie (as Crazyswarm does).

        The parameter writes wait for their answers: they run in a small pool (``FIRST_FIX_WRITERS``),
        so the stream never waits for them and the Crazyflies of a swarm are set up several at a
        time, the radios' unicast reserve shared among them.
        """
        member = next((m for m in self.members if m.name == name), None)
        if member is None or self._first_fixes is None:
            return
        self._first_fixes.submit(self._write_initial_position, member, name, position)

    def _write_initial_position(self, member, name: str, position) -> None:
        if shutting_down():
            return
        values = initial_position_params(position)
        _, errors = member.worker.update_params(values)
        if errors:
            # a write lost on the radio is no reason to leave it unplaced (its takeoff would be refused):
            # the next pose tries again
            attempts = self._placement_attempts[name] = self._placement_attempts.get(name, 0) + 1
            if attempts <= PLACEMENT_LOGGED_ATTEMPTS or attempts % PLACEMENT_LOG_EVERY == 0:
                rospy.logerr("swarm: %s: initial position from its first pose not written (attempt %d): %s; "
                             "trying again with its next pose", name, attempts, "; ".join(errors))
            if self.stream is not None and not shutting_down():
                self.stream.refix(name)
        else:
            self.placement.placed(name)
            rospy.loginfo("swarm: %s first seen at (%.3f, %.3f, %.3f): estimator reset there", name, *position)

    # -- watching -----------------------------------------------------------------------------------
    def _watch_loop(self) -> None:
        while not shutting_down():
            self.clock.sleep(WATCH_PERIOD_S)
            try:
                self._check(self.clock.now())
            except Exception as e:      # never let bookkeeping end the watch
                rospy.logerr_throttle(5.0, "swarm: watch failed: %r" % (e,))

    def _check(self, now: float) -> None:
        members = {m.name: m for m in self.live_members()}
        with self._watch_lock:
            for name, m in members.items():
                ok = m.worker.state != WorkerState.LOST
                if self._link_ok.get(name, True) != ok:
                    self._link_ok[name] = ok
                    if not ok:
                        rospy.logerr("swarm: %s: radio link lost; %s", name, self._link_lost_outcome())
                    else:
                        rospy.logwarn("swarm: %s: radio link back", name)
                self.watch.link(name, ok, now)
            events = self.watch.check(now)
        for ev in events:
            if ev.kind == "stale":
                rospy.logwarn("swarm: %s: no pose for %.2f s (%s); it lands in %.1f s unless the pose comes "
                              "back", ev.name, ev.age, self._stale_cause(ev.name), self.options.stale_hold)
            elif ev.kind == "fresh":
                rospy.loginfo("swarm: %s: pose back", ev.name)
            elif ev.kind == "land" and ev.name in members and not self._emergency:
                rospy.logerr("swarm: %s: landing by itself: %s", ev.name, ev.reason)
                threading.Thread(target=self._land_one, args=(members[ev.name], ev.reason),
                                 name="land %s" % ev.name, daemon=True).start()

    def _stale_cause(self, name: str) -> str:
        if self._emergency:
            return "the emergency stopped the stream"
        refusal = self.stream.last_refusal.get(name) if self.stream is not None else None
        return "its poses are refused: %s" % refusal if refusal else "motion capture lost it"

    def _link_lost_outcome(self) -> str:
        if self.heartbeat is not None and self.heartbeat.running:
            return ("its motors stop 1 s after the last emergency-stop watchdog keep-alive it heard (restart it "
                    "before flying it again); it is told to land if the link comes back first")
        return ("it is told to land once the link comes back (without ~emergency_watchdog nothing onboard stops "
                "it meanwhile: it flies on)")

    def _land_one(self, member: SwarmMember, reason: str) -> None:
        """Unicast land (retried while its link is lost, until it is taken or refused)."""
        while not shutting_down() and not self._emergency and member.worker.state != WorkerState.STOPPED:
            try:
                member.onboard.land(0, 0.0, self.options.stale_land_duration)
                return
            except CrazyflieError as e:
                if "refused" in str(e):         # e.g. on the ground already: nothing to land
                    rospy.loginfo("swarm: %s: land not needed: %s", member.name, e)
                    return
                rospy.logwarn_throttle(2.0, "swarm: %s: land (%s) not delivered yet: %s" % (member.name, reason, e))
            self.clock.sleep(0.1)

    # -- diagnostics --------------------------------------------------------------------------------
    def diagnostics(self, now: float) -> DiagnosticArray:
        arr = DiagnosticArray()
        arr.header.stamp = rospy.Time.now()
        mocap = self.options.mocap != "none"
        with self._watch_lock:
            for m in self.members:
                status = DiagnosticStatus(name="crazyflie_server swarm: %s" % m.name, hardware_id=m.uri)
                state = self.watch.state(m.name, now) if mocap else "no motion capture"
                age = self.watch.age(m.name, now)
                landed = self.watch.landed_for(m.name)
                link_ok = self._link_ok.get(m.name, True)
                status.level = {"ok": DiagnosticStatus.OK, "no motion capture": DiagnosticStatus.OK,
                                "no pose yet": DiagnosticStatus.WARN}.get(state, DiagnosticStatus.ERROR)
                status.message = "pose %s%s" % (state, " (landed: %s)" % landed if landed else "")
                if not link_ok:
                    status.level = DiagnosticStatus.ERROR
                    status.message = "radio link lost: %s; %s" % (self._link_lost_outcome(), status.message)
                status.values = [KeyValue("pose age_s", "%.3f" % age if math.isfinite(age) else "never"),
                                 KeyValue("link", "ok" if link_ok else "lost")]
                if self.stream is not None:     # a pose counts once it went out; refused ones say why
                    status.values += [KeyValue("poses sent", str(self.stream.sent_by_name.get(m.name, 0))),
                                      KeyValue("poses refused", str(self.stream.refused.get(m.name, 0)))]
                    if state != "ok" and self.stream.last_refusal.get(m.name):
                        status.message += "; last pose refused: %s" % self.stream.last_refusal[m.name]
                arr.status.append(status)
            for name, error in self.failed.items():
                arr.status.append(DiagnosticStatus(level=DiagnosticStatus.ERROR, name="crazyflie_server swarm: %s"
                                                   % name, message="not added: %s" % error))
        summary = DiagnosticStatus(name="crazyflie_server swarm", hardware_id=self.config.source)
        summary.level = DiagnosticStatus.ERROR if self._emergency or self.failed else DiagnosticStatus.OK
        summary.message = "emergency" if self._emergency else "%d Crazyflies" % len(self.members)
        values = [("connect_s", "%.2f" % self.connect_s),
                  ("emergency watchdog", "keep-alive every %.2f s, %d sent, %d failed" % (
                      self.heartbeat.period_s, self.heartbeat.sent, self.heartbeat.errors)
                   if self.heartbeat is not None else "off")]
        if self.stream is not None:
            lat = list(self.stream.latencies)
            values += [("mocap frames", str(self.stream.frames)), ("mocap transfers", str(self.stream.transfers))]
            if lat:
                lat.sort()
                values += [("mocap latency median_ms", "%.2f" % (1000 * statistics.median(lat))),
                           ("mocap latency p99_ms", "%.2f" % (1000 * lat[min(len(lat) - 1, int(0.99 * len(lat)))]))]
        if self.broadcaster is not None:
            for key, link in self.broadcaster.links.items():
                values.append(("radio %d channel %d broadcasts" % (key[0], key[1]), str(link.stats.packets)))
        summary.values = [KeyValue(k, v) for k, v in values]
        arr.status.append(summary)
        return arr

    def _diagnostics_loop(self) -> None:
        while not shutting_down():
            self.clock.sleep(DIAGNOSTICS_PERIOD_S)
            try:
                publish_unless_shutting_down(self._diag_pub, self.diagnostics(self.clock.now()))
            except Exception as e:
                rospy.logerr_throttle(10.0, "swarm: diagnostics failed: %r" % (e,))

    def shutdown(self) -> None:
        if self.stream is not None:
            self.stream.stop()
        if self._first_fixes is not None:
            self._first_fixes.shutdown(wait=False)
        if self.heartbeat is not None:
            self.heartbeat.stop()
        for s in self._sources:
            try:
                s.stop()
            except Exception:
                pass
        if self.broadcaster is not None:
            self.broadcaster.close()


def observe_in_safety(targets, what: str, duration: float, clock: Clock = WALL) -> None:
    """Each addressed Crazyflie's safety monitor learns of a swarm command (it flies, or lands by itself),
    so that a reaction (battery, shutdown) knows it is in the air and never lands it twice."""
    now = clock.now()
    for m in targets:
        m.worker.safety.note_high_level(now, what, duration)


def refusal_in_safety(member: SwarmMember, what: str, clock: Clock = WALL) -> Optional[str]:
    """Why a swarm command must not reach this Crazyflie now (a landing under way), from its safety monitor."""
    return member.worker.safety.refusal(clock.now(), what)


def height_in_safety(member: SwarmMember, clock: Clock = WALL) -> Optional[float]:
    """The height of the Crazyflie's last fresh pose, as its safety monitor knows it (None: unknown)."""
    return member.worker.safety.current_height(clock.now())


def initial_position_params(position) -> Dict[str, Any]:
    """Crazyswarm's way to start the Kalman estimator at a known place: initial x/y/z, then reset.
    (A dict keeps this order: the reset must come after the position.)"""
    return {"kalman.initialX": float(position[0]), "kalman.initialY": float(position[1]),
            "kalman.initialZ": float(position[2]), "kalman.resetEstimation": 1}


def start_swarm(server) -> Optional[RosSwarm]:
    """Swarm mode when ``~swarm_file`` is set: checked options and file (a fault ends the node with its
    message), then everything else in a background thread."""
    params = {k: rospy.get_param("~" + k) for k in ("swarm_file", "swarm_types_file", "mocap", "mocap_pattern",
                                                    "vrpn_server", "world_frame", "position_only", "stale_after",
                                                    "stale_hold", "stale_land_duration", "broadcast_repeats",
                                                    "broadcast_interval", "enable_logging", "pose_period_ms",
                                                    "dongle_wait", "mocap_rate", "emergency_watchdog")
              if rospy.has_param("~" + k)}
    if not params.get("swarm_file"):
        return None
    options = options_from_params(params)
    load_swarm_file(options.swarm_file, options.swarm_types_file or None)     # file faults first, fast
    dongles = count_dongles(options.dongle_wait)
    config = load_swarm_file(options.swarm_file, options.swarm_types_file or None, dongles=dongles)
    swarm = RosSwarm(server, options, config)
    rospy.on_shutdown(swarm.shutdown)

    def run() -> None:
        try:
            swarm.start()
        except Exception as e:
            rospy.logerr("swarm: start failed: %s", e)
    threading.Thread(target=run, name="swarm start", daemon=True).start()
    return swarm
