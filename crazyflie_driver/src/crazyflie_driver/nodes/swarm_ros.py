"""Swarm mode of ``crazyflie_server`` (``~swarm_file``): the ROS face of the swarm.

Reads the swarm-mode parameters, then serves at the root namespace, as Crazyswarm does: ``/takeoff``,
``/land``, ``/go_to``, ``/start_trajectory``, ``/stop``, ``/emergency``, ``/update_params``
and Crazyswarm2's ``/all/notify_setpoints_stop`` and ``/all/arm``; feeds
motion capture (VRPN, tf or PoseStamped topics) in, and publishes ``/diagnostics``. Every decision
(the start sequence, the first fix, the watch's landings, what a command may do) is
``server.swarm.policy.SwarmPolicy``'s; this module only adapts it to ROS.
"""
from __future__ import annotations

import math
import statistics
import threading
import time
from typing import Any, Callable, Dict, Iterable, List, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_srvs.srv import Empty, EmptyResponse

from crazyflie_driver import usb_choice
from crazyflie_driver.clock import WALL, Clock
from crazyflie_driver.errors import CrazyflieError, LogConfigError, UnknownName
from crazyflie_driver.nodes import swarm_mocap_sources
from crazyflie_driver.nodes.ros_signals import publish_unless_shutting_down, shutting_down
from crazyflie_driver.radio.crazyradio import list_radios
from crazyflie_driver.server import radio_budget
from crazyflie_driver.server.swarm.commands import SwarmMember
from crazyflie_driver.server.swarm.config import LOG_SWITCHES, load_swarm_file
from crazyflie_driver.server.swarm.options import (
    GENERIC_LOG_PERIODS,
    GENERIC_LOG_TOPICS,
    generic_log_note,
    generic_log_variables_key,
    options_from_params,
)
from crazyflie_driver.server.swarm.policy import REBOOT_ALL_SERVICE, SwarmPolicy, refusal_text
from crazyflie_driver.server.worker import WorkerConfig
from crazyflie_driver.srv import (
    Arm,
    ArmResponse,
    GoTo,
    GoToResponse,
    Land,
    LandResponse,
    NotifySetpointsStop,
    NotifySetpointsStopResponse,
    StartTrajectory,
    StartTrajectoryResponse,
    Stop,
    StopResponse,
    Takeoff,
    TakeoffResponse,
    UpdateParams,
    UpdateParamsResponse,
)

DIAGNOSTICS_PERIOD_S = 1.0


def ros_param_or_none(name: str) -> Any:
    """The ROS parameter ``name``, None when it is not set (one call to the master)."""
    try:
        return rospy.get_param(name)
    except KeyError:
        return None


def count_dongles(wait_s: float) -> int:
    """Crazyradios present (the simulated world's once it answers, waiting up to ``wait_s``).

    Wall seconds: finding USB devices (or the world's fake ones) is a matter of the host, as on hardware."""
    deadline = time.monotonic() + wait_s
    while True:
        error: Optional[Exception] = None
        try:
            n = len(list_radios(usb_choice.get_backend()))
        except (CrazyflieError, OSError, ConnectionError) as e:
            n, error = 0, e
        if n or time.monotonic() >= deadline or shutting_down():
            if error is not None and not n:
                rospy.logwarn("swarm: no Crazyradio found (%s)", error)
            return n
        time.sleep(0.5)


class ServerPort:
    """``SwarmServer`` on a running ``CrazyflieServer`` (its registry, radios, budget and clock)."""

    def __init__(self, server: Any) -> None:
        self._server = server

    @property
    def clock(self) -> Clock:
        return getattr(self._server, "clock", WALL)

    def add(self, config: WorkerConfig) -> SwarmMember:
        try:
            ros = self._server.add(config)
        except rospy.ServiceException as e:
            if isinstance(e.__cause__, (UnknownName, LogConfigError)):     # its log blocks, per its log TOC
                raise LogConfigError(str(e)) from e
            raise CrazyflieError(str(e)) from e
        return SwarmMember(config.tf_prefix, str(ros.config.uri), ros.worker, ros.onboard_commands)

    def served_workers(self) -> Iterable[Any]:
        return self._server.registry.workers()

    def radio_manager(self) -> Any:
        return usb_choice.radio_manager()

    def add_broadcasts(self, dongle: int, stats: Any, burst: Optional[radio_budget.BroadcastDemand]) -> None:
        self._server.add_broadcasts(dongle, stats, burst)

    def shutting_down(self) -> bool:
        return shutting_down()


class RosSwarm:
    """The swarm's services, motion-capture sources and ``/diagnostics`` around a ``SwarmPolicy``."""

    def __init__(self, policy: SwarmPolicy) -> None:
        self.policy = policy
        self.clock = policy.clock
        self.options = policy.options
        self._services: List[Any] = []
        self._sources: List[Any] = []
        self._diag_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)

    def start(self) -> None:
        if not self.policy.start():
            return
        self._advertise()
        if self.policy.start_stream() is not None:
            names = {self.options.mocap_pattern.format(name=name): name for name in self.policy.member_names()}
            self._sources.append(swarm_mocap_sources.start(self.options, names, self.policy.pose, self.clock))
        threading.Thread(target=self.policy.watch_loop, name="swarm watch", daemon=True).start()
        threading.Thread(target=self._diagnostics_loop, name="swarm diagnostics", daemon=True).start()
        links = self.policy.broadcaster.links if self.policy.broadcaster is not None else {}
        rospy.loginfo("swarm ready: %d Crazyflies on %d radio link(s), motion capture: %s", len(self.policy.members),
                      len(links), self.options.mocap)

    # -- services ---------------------------------------------------------------------------------
    def _advertise(self) -> None:
        p = self.policy
        services = [
            ("/takeoff", Takeoff, TakeoffResponse, lambda r: p.takeoff(r.groupMask, r.height, r.duration.to_sec())),
            ("/land", Land, LandResponse, lambda r: p.land(r.groupMask, r.height, r.duration.to_sec())),
            ("/go_to", GoTo, GoToResponse, lambda r: p.go_to(r.groupMask, (r.goal.x, r.goal.y, r.goal.z), r.yaw,
                                                            r.duration.to_sec())),
            ("/start_trajectory", StartTrajectory, StartTrajectoryResponse,
             lambda r: p.start_trajectory(r.groupMask, r.trajectoryId, r.timescale, r.reversed)),
            ("/stop", Stop, StopResponse, lambda r: p.stop(r.groupMask)),
            ("/update_params", UpdateParams, UpdateParamsResponse,
             lambda r: p.update_params(r.params, ros_param_or_none)),
            ("/all/notify_setpoints_stop", NotifySetpointsStop, NotifySetpointsStopResponse,
             lambda r: p.notify_setpoints_stop(r.groupMask, r.remainValidMillisecs)),
            ("/all/arm", Arm, ArmResponse, lambda r: p.arm(r.arm)),
            (REBOOT_ALL_SERVICE, Empty, EmptyResponse, lambda r: p.reboot_all()),
        ]
        for name, kind, response, handler in services:
            self._services.append(rospy.Service(name, kind, self._service(name, handler, response)))
        self._services.append(rospy.Service("/emergency", Empty, self._on_emergency))

    def _service(self, name: str, handler: Callable[[Any], Any], response: type) -> Callable[[Any], Any]:
        def callback(req):
            try:
                handler(req)
            except (ValueError, CrazyflieError) as e:
                text = refusal_text(name, e)
                rospy.logerr("swarm: %s", text)
                raise rospy.ServiceException(text) from e
            return response()
        return callback

    def _on_emergency(self, _req) -> EmptyResponse:
        failures = self.policy.emergency()
        rospy.logwarn("swarm: EMERGENCY: e-stop broadcast on every radio and sent to each of %d Crazyflies%s; %s",
                      len(self.policy.members), "; failed: " + "; ".join(failures) if failures else "",
                      self.policy.emergency_advice())
        return EmptyResponse()

    # -- diagnostics --------------------------------------------------------------------------------
    def diagnostics(self, now: float) -> DiagnosticArray:
        p = self.policy
        arr = DiagnosticArray()
        arr.header.stamp = rospy.Time.now()
        mocap = self.options.mocap != "none"
        with p.lock:
            for m in p.members:
                status = DiagnosticStatus(name="crazyflie_server swarm: %s" % m.name, hardware_id=m.uri)
                state = p.watch.state(m.name, now) if mocap else "no motion capture"
                age = p.watch.age(m.name, now)
                landed = p.watch.landed_for(m.name)
                link_ok = p.link_ok.get(m.name, True)
                status.level = {"ok": DiagnosticStatus.OK, "no motion capture": DiagnosticStatus.OK,
                                "no pose yet": DiagnosticStatus.WARN}.get(state, DiagnosticStatus.ERROR)
                status.message = "pose %s%s" % (state, " (landed: %s)" % landed if landed else "")
                if not link_ok:
                    status.level = DiagnosticStatus.ERROR
                    status.message = "radio link lost: %s; %s" % (p.link_lost_outcome(), status.message)
                status.values = [KeyValue("pose age_s", "%.3f" % age if math.isfinite(age) else "never"),
                                 KeyValue("link", "ok" if link_ok else "lost")]
                if p.stream is not None:     # a pose counts once it went out; refused ones say why
                    status.values += [KeyValue("poses sent", str(p.stream.sent_by_name.get(m.name, 0))),
                                      KeyValue("poses refused", str(p.stream.refused.get(m.name, 0)))]
                    if state != "ok" and p.stream.last_refusal.get(m.name):
                        status.message += "; last pose refused: %s" % p.stream.last_refusal[m.name]
                note_log_topic_fault(status, p.log_topic_faults.get(m.name))
                arr.status.append(status)
            for name, error in p.failed.items():
                arr.status.append(DiagnosticStatus(level=DiagnosticStatus.ERROR, name="crazyflie_server swarm: %s"
                                                   % name, message="not added: %s" % error))
        summary = DiagnosticStatus(name="crazyflie_server swarm", hardware_id=p.config.source)
        summary.level = DiagnosticStatus.ERROR if p.emergency_active or p.failed else DiagnosticStatus.OK
        summary.message = "emergency" if p.emergency_active else "%d Crazyflies" % len(p.members)
        values = [("connect_s", "%.2f" % p.connect_s),
                  ("emergency watchdog", "keep-alive every %.2f s, %d sent, %d failed" % (
                      p.heartbeat.period_s, p.heartbeat.sent, p.heartbeat.errors)
                   if p.heartbeat is not None else "off")]
        if p.stream is not None:
            lat = list(p.stream.latencies)
            values += [("mocap frames", str(p.stream.frames)), ("mocap transfers", str(p.stream.transfers))]
            if lat:
                lat.sort()
                values += [("mocap latency median_ms", "%.2f" % (1000 * statistics.median(lat))),
                           ("mocap latency p99_ms", "%.2f" % (1000 * lat[min(len(lat) - 1, int(0.99 * len(lat)))]))]
        if p.broadcaster is not None:
            for key, link in p.broadcaster.links.items():
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
        self.policy.shutdown()
        for s in self._sources:
            try:
                s.stop()
            except Exception:
                pass


def note_log_topic_fault(status: DiagnosticStatus, fault: Optional[str]) -> None:
    """A Crazyflie flying without its custom log topics is a warning at least, with the reason."""
    if fault:
        status.level = max(status.level, DiagnosticStatus.WARN)
        status.message += "; no custom log topics: %s" % fault


def generic_log_params() -> Dict[str, Any]:
    """Crazyswarm's generic log topic parameters of this node, as they are set (checked by the options)."""
    out: Dict[str, Any] = {}
    for key in (GENERIC_LOG_TOPICS, GENERIC_LOG_PERIODS):
        if rospy.has_param("~" + key):
            out[key] = rospy.get_param("~" + key)
    topics = out.get(GENERIC_LOG_TOPICS)
    for topic in topics if isinstance(topics, list) else []:
        key = generic_log_variables_key(str(topic))
        if rospy.has_param("~" + key):
            out[key] = rospy.get_param("~" + key)
    return out


def start_swarm(server) -> Optional[RosSwarm]:
    """Swarm mode when ``~swarm_file`` is set: checked options and file (a fault ends the node with its
    message), then everything else in a background thread."""
    params = {k: rospy.get_param("~" + k) for k in ("swarm_file", "swarm_types_file", "mocap", "mocap_pattern",
                                                    "vrpn_server", "world_frame", "position_only", "stale_after",
                                                    "stale_hold", "stale_land_duration", "broadcast_repeats",
                                                    "broadcast_interval", "enable_logging", "pose_period_ms",
                                                    "dongle_wait", "mocap_rate", "emergency_watchdog")
              + LOG_SWITCHES if rospy.has_param("~" + k)}
    if not params.get("swarm_file"):
        return None
    params.update(generic_log_params())
    options = options_from_params(params)
    note = generic_log_note(params, options.enable_logging)
    if note:
        rospy.logwarn("swarm: %s", note)
    load_swarm_file(options.swarm_file, options.swarm_types_file or None)     # file faults first, fast
    dongles = count_dongles(options.dongle_wait)
    config = load_swarm_file(options.swarm_file, options.swarm_types_file or None, dongles=dongles)
    for note in config.notes:
        rospy.logwarn("swarm: %s: %s", options.swarm_file, note)
    if not rospy.has_param("~budget_setpoint_rate"):
        server.budget_setpoint_rate = 0.0     # nothing streams setpoints in swarm mode
    swarm = RosSwarm(SwarmPolicy(ServerPort(server), options, config))
    rospy.on_shutdown(swarm.shutdown)

    def run() -> None:
        try:
            swarm.start()
        except Exception as e:
            rospy.logerr("swarm: start failed: %s", e)
    threading.Thread(target=run, name="swarm start", daemon=True).start()
    return swarm
