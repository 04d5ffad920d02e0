"""``crazyflie_server``: one process serving every Crazyflie; thin ROS glue over worker and registry.

Global services ``/add_crazyflie`` and ``/remove_crazyflie``; per Crazyflie, under its tf_prefix:
``cmd_vel`` (sub), ``emergency`` and ``update_params`` (services), ``imu``, ``temperature``,
``magnetic_field``, ``pressure``, ``battery``, ``rssi`` and one GenericLogData topic per custom
log block (pubs); its parameters mirrored to ``/<tf_prefix>/<group>/<name>``; ``status``
(``diagnostic_msgs/DiagnosticStatus``, latched, on every change) and one entry per Crazyflie on
``/diagnostics`` every second, with its link, battery, supervisor, commands and reports entries and one
entry per dongle (``server.diagnostics``, docs/diagnostics.md); the radio budget is checked on every
add and logged when a dongle will be short (``server.radio_budget``). A Crazyflie whose worker gave
up is removed (its topics and services go) and stays on ``/diagnostics`` as an error until it is
added again. Also per Crazyflie: crazyflie_ros HEAD's setpoint topics and high-level services
(``nodes/onboard_ros.py``). With ``~swarm_file``, swarm mode: every Crazyflie of the file and the
swarm-wide services (``nodes/swarm_ros.py``).
``magnetic_field`` carries the firmware's ``mag.x/y/z`` values unscaled, as the original did.
"""
from __future__ import annotations

import logging
import math
import os
import threading
from typing import Any, Callable, Dict, List, Optional, Tuple

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Twist
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import Float32
from std_srvs.srv import Empty, EmptyResponse

from crazyflie_driver.clock import WALL, Clock
from crazyflie_driver.crtp.uri import parse_uri, radio_uri_of
from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.msg import GenericLogData, crtpPacket
from crazyflie_driver.nodes.onboard_ros import PosePublisher, RosOnboardCommands
from crazyflie_driver.nodes.ros_clock import ros_clock
from crazyflie_driver.nodes.ros_signals import RosLogHandler, init_node, publish_unless_shutting_down, shutting_down
from crazyflie_driver.nodes.swarm_ros import start_swarm
from crazyflie_driver.protocol.console import rosout_line
from crazyflie_driver.server import memory_config, power_control, radio_budget
from crazyflie_driver.server.add_config import ACCEPTED_SWITCHES, apply_topic_switches, check_config
from crazyflie_driver.server.bring_down import bring_down
from crazyflie_driver.server.diagnostic_thresholds import WORLD_FIGURE_STALE_S
from crazyflie_driver.server.diagnostics import (
    UNKNOWN_BOTTLENECK,
    BottleneckFigures,
    CounterWindow,
    CrazyflieDiagnostics,
    Entry,
    RadioFigures,
    bottleneck_entry,
    radio_entry,
    world_speed_share,
)
from crazyflie_driver.server.log_plan import (
    BATTERY_TOPIC,
    IMU_TOPIC,
    MAGNETIC_FIELD_TOPIC,
    PRESSURE_TOPIC,
    STATUS_TOPIC,
    TEMPERATURE_TOPIC,
    TOPIC_SWITCHES,
    LogBlockSpec,
)
from crazyflie_driver.server.onboard_commands import OnboardCommands
from crazyflie_driver.server.onboard_pose import POSE_TOPIC, is_pose_block
from crazyflie_driver.server.param_names import param_values
from crazyflie_driver.server.raw_packets import PACKETS_TOPIC, SEND_PACKET_SERVICE, packet_fields, raw_packet
from crazyflie_driver.server.refusals import RefusalThrottle
from crazyflie_driver.server.registry import CrazyflieRegistry, DuplicateCrazyflie
from crazyflie_driver.server.safety import SafetyConfig
from crazyflie_driver.server.safety_actions import worker_onboard_commands
from crazyflie_driver.server.status import CrazyflieStatus, worker_status
from crazyflie_driver.server.worker import CrazyflieWorker, WorkerConfig, WorkerListener
from crazyflie_driver.srv import (
    AddCrazyflie,
    AddCrazyflieResponse,
    Arm,
    ArmResponse,
    ReadConfig,
    ReadConfigResponse,
    RemoveCrazyflie,
    RemoveCrazyflieResponse,
    UpdateParams,
    UpdateParamsResponse,
    WriteConfig,
    WriteConfigResponse,
    sendPacket,
    sendPacketResponse,
)

GRAVITY = 9.81
DEG_TO_RAD = math.pi / 180.0
XMLRPC_INT_MAX = 2 ** 31 - 1
DIAGNOSTICS_PERIOD = 1.0        # s between /diagnostics messages
SIM_HARDWARE_ID = "crazyflie_sim"   # the simulated world's /diagnostics entries (nodes/sim_node.py)


def namespace(tf_prefix: str) -> str:
    """``"crazyflie1"`` -> ``"/crazyflie1"``; ``""`` -> ``""`` (global names)."""
    p = tf_prefix.strip("/")
    return "/" + p if p else ""


def param_server_value(value: Any) -> Any:
    """A Crazyflie parameter value the ROS parameter server can hold (XML-RPC ints are 32-bit)."""
    if isinstance(value, int) and not -XMLRPC_INT_MAX - 1 <= value <= XMLRPC_INT_MAX:
        return float(value)
    return value


def ros_param_or_none(name: str) -> Any:
    """The ROS parameter ``name``, None when it is not set (``server.param_names.Lookup``)."""
    try:
        return rospy.get_param(name)
    except KeyError:
        return None


def diagnostic_status(status: CrazyflieStatus, tf_prefix: str, uri: str) -> DiagnosticStatus:
    msg = DiagnosticStatus(name="crazyflie_server: %s" % (tf_prefix or uri), hardware_id=uri)
    msg.level, msg.message = status.level, status.message
    msg.values = [KeyValue(k, v) for k, v in status.values]
    return msg


def entry_status(entry: Entry, label: str, hardware_id: str) -> DiagnosticStatus:
    """``crazyflie_server: <label> <part>``, e.g. ``crazyflie_server: crazyflie1 link``."""
    msg = DiagnosticStatus(name="crazyflie_server: %s" % " ".join(p for p in (label, entry.part) if p),
                           hardware_id=hardware_id)
    msg.level, msg.message = entry.level, entry.message
    msg.values = [KeyValue(k, v) for k, v in entry.values]
    return msg


class RosCrazyflie(WorkerListener):
    """The ROS face of one Crazyflie: publishers, the cmd_vel subscriber, its services."""

    def __init__(self, config: WorkerConfig, on_gave_up: Optional[Callable[[], None]] = None,
                 late_cause: Optional[Callable[[], str]] = None) -> None:
        self.config = config
        self._on_gave_up = on_gave_up       # the server removes a Crazyflie whose worker gave up
        self._late_cause = late_cause       # the server's bottleneck judgement, for the late-data message
        self.ns = namespace(config.tf_prefix)
        self.frame_id = (config.tf_prefix.strip("/") + "/base_link") if config.tf_prefix.strip("/") else "base_link"
        self.worker: Optional[CrazyflieWorker] = None
        self._packets_pub: Optional[Any] = None     # the packets topic, once attached (enable_logging_packets)
        self._services: List[Any] = []
        self._subscribers: List[Any] = []
        # Publishers are made once the Crazyflie answered (attach): an absent one costs the server
        # no master registrations. Log packets of the connect sequence before that are dropped.
        self._pubs: Dict[str, rospy.Publisher] = {}
        self._rssi_pub: Optional[rospy.Publisher] = None
        self._custom: Dict[str, rospy.Publisher] = {}
        self._status_pub: Optional[rospy.Publisher] = None
        self._status_lock = threading.Lock()
        self._last_status: Optional[CrazyflieStatus] = None
        self._said_ignored = False
        self._refusals = RefusalThrottle()
        self._onboard: Optional[RosOnboardCommands] = None
        self._pose: Optional[PosePublisher] = None        # HEAD's onboard pose topic, when asked for
        self.frame_id_world = "world"
        self.figures = CrazyflieDiagnostics()

    # -- after the Crazyflie answered --------------------------------------------------------------
    def attach(self, worker: CrazyflieWorker) -> None:
        self.worker = worker
        config = self.config
        name = lambda topic: self.ns + "/" + topic
        pubs: Dict[str, rospy.Publisher] = {}
        if config.enable_logging:
            for topic, kind in ((IMU_TOPIC, Imu), (TEMPERATURE_TOPIC, Temperature),
                                (MAGNETIC_FIELD_TOPIC, MagneticField), (PRESSURE_TOPIC, Float32),
                                (BATTERY_TOPIC, Float32)):
                if topic not in config.disabled_topics:     # a switched-off topic is not advertised
                    pubs[topic] = rospy.Publisher(name(topic), kind, queue_size=10)
        self._custom = {b.topic_name: rospy.Publisher(name(b.topic_name), GenericLogData, queue_size=10)
                        for b in config.log_blocks if not is_pose_block(b)}
        self._pose = next((PosePublisher(name(b.topic_name), self.frame_id_world)
                           for b in config.log_blocks if is_pose_block(b)), None)
        self._rssi_pub = rospy.Publisher(name("rssi"), Float32, queue_size=10)
        self._status_pub = rospy.Publisher(name(STATUS_TOPIC), DiagnosticStatus, queue_size=10, latch=True)
        self._pubs = pubs       # one assignment: the worker thread reads it meanwhile
        self._subscribers.append(rospy.Subscriber(name("cmd_vel"), Twist, self._on_cmd_vel, queue_size=1,
                                                  tcp_nodelay=True))
        self._services.append(rospy.Service(name("emergency"), Empty, self._on_emergency))
        self._services.append(rospy.Service(name(SEND_PACKET_SERVICE), sendPacket, self._on_send_packet))
        self._packets_pub = (rospy.Publisher(name(PACKETS_TOPIC), crtpPacket, queue_size=100)
                             if config.log_packets else None)
        self._services.append(rospy.Service(name("update_params"), UpdateParams, self._on_update_params))
        self._services.append(rospy.Service(name(power_control.ARM_SERVICE), Arm, self._on_arm))
        self._services.append(rospy.Service(name(memory_config.READ_CONFIG_SERVICE), ReadConfig, self._on_read_config))
        self._services.append(rospy.Service(name(memory_config.WRITE_CONFIG_SERVICE), WriteConfig,
                                            self._on_write_config))
        for service, call in ((power_control.RECOVER_SERVICE, worker.recover),
                              (power_control.REBOOT_SERVICE, worker.reboot),
                              (power_control.POWER_OFF_SERVICE, worker.power_off),
                              (power_control.POWER_ON_SERVICE, worker.power_on)):
            self._services.append(rospy.Service(name(service), Empty, self._empty_service(service, call)))
        self._onboard = RosOnboardCommands(self.ns, config.uri, worker_onboard_commands(worker, config.uri))
        self.publish_status()

    @property
    def onboard_commands(self) -> Optional[OnboardCommands]:
        """The HEAD API of this Crazyflie once attached (the swarm's services use it too)."""
        return self._onboard.commands if self._onboard is not None else None

    def status(self) -> CrazyflieStatus:
        return worker_status(self.worker)

    def diagnostic(self) -> DiagnosticStatus:
        return diagnostic_status(self.status(), self.config.tf_prefix, self.config.uri)

    def diagnostics(self) -> List[DiagnosticStatus]:
        """Its status, then one entry per part (link, battery, supervisor, commands, reports)."""
        label = self.config.tf_prefix or self.config.uri
        return [self.diagnostic()] + [entry_status(e, label, self.config.uri)
                                      for e in self.figures.entries(self.worker)]

    def publish_status(self, force: bool = False) -> None:
        """On the latched ``status`` topic when level or message changed (or ``force``)."""
        if self.worker is None:
            return
        status = self.status()
        with self._status_lock:
            pub = self._status_pub
            last, self._last_status = self._last_status, status
            if pub is None or (not force and last is not None and (last.level, last.message) ==
                                                                  (status.level, status.message)):
                return
            publish_unless_shutting_down(pub, diagnostic_status(status, self.config.tf_prefix, self.config.uri))

    def detach(self) -> None:
        if self._onboard is not None:
            self._onboard.close()
            self._onboard = None
        for s in self._subscribers:
            s.unregister()
        for s in self._services:
            s.shutdown("Crazyflie %s removed" % self.config.uri)
        with self._status_lock:
            status_pub, self._status_pub = self._status_pub, None
        pubs = list(self._pubs.values()) + list(self._custom.values()) + [self._rssi_pub, status_pub]
        if self._pose is not None:
            pubs.append(self._pose.pub)
        self._pubs, self._custom, self._rssi_pub, self._pose = {}, {}, None, None
        for p in pubs:
            if p is not None:
                p.unregister()
        self._subscribers, self._services = [], []

    # -- ROS callbacks ------------------------------------------------------------------------------
    def _attached(self) -> CrazyflieWorker:
        """The worker, for the callbacks ``attach`` subscribes after setting it."""
        assert self.worker is not None, "a callback before attach()"
        return self.worker

    def _on_cmd_vel(self, msg: Twist) -> None:
        try:
            setpoint = self._attached().setpoint_for_cmd_vel(msg.linear.x, msg.linear.y, msg.linear.z, msg.angular.z)
        except ValueError as e:
            text = self._refusals.say(self.config.uri, "cmd_vel", str(e))     # once a second per field and rule
            if text is not None:
                rospy.logwarn("%s: cmd_vel refused: %s" % (self.config.uri, text))
            return
        if setpoint.notes:
            text = self._refusals.say(self.config.uri, "cmd_vel held", "; ".join(setpoint.notes))
            if text is not None:
                rospy.logwarn("%s: cmd_vel held to the firmware's limits: %s" % (self.config.uri, text))
        if not self._attached().set_setpoint(setpoint) and not self._said_ignored:
            self._said_ignored = True       # once: the status topic keeps saying it
            rospy.logwarn("%s: cmd_vel ignored after emergency (the Crazyflie stays stopped until a reboot: to fly "
                          "again %s)" % (self.config.uri, power_control.REBOOT_ADVICE))

    def _on_arm(self, req) -> ArmResponse:
        try:
            self._attached().arm(bool(req.arm))
        except CrazyflieError as e:
            raise rospy.ServiceException(str(e)) from e
        return ArmResponse()

    def _on_read_config(self, _req) -> ReadConfigResponse:
        try:
            return ReadConfigResponse(*memory_config.fields_of(self._attached().read_config()))
        except CrazyflieError as e:
            raise rospy.ServiceException("%s: %s" % (memory_config.READ_CONFIG_SERVICE, e)) from e

    def _on_write_config(self, req) -> WriteConfigResponse:
        try:
            block = memory_config.block_of(memory_config.ConfigFields(
                req.channel, req.datarate, req.address, req.pitch_trim, req.roll_trim))
            self._attached().write_config(block)
        except CrazyflieError as e:
            raise rospy.ServiceException("%s: %s" % (memory_config.WRITE_CONFIG_SERVICE, e)) from e
        return WriteConfigResponse(memory_config.uri_after_reboot(self.config.uri, block))

    def _empty_service(self, service: str, call: Callable[[], None]) -> Callable[[Any], EmptyResponse]:
        """A std_srvs/Empty handler: the worker's refusal or failure becomes the service's error."""
        def handle(_req) -> EmptyResponse:
            try:
                call()
            except CrazyflieError as e:
                raise rospy.ServiceException("%s: %s" % (service, e)) from e
            self.publish_status()
            return EmptyResponse()
        return handle

    def _on_emergency(self, _req) -> EmptyResponse:
        self._attached().emergency()
        return EmptyResponse()

    def _on_update_params(self, req) -> UpdateParamsResponse:
        # names checked before the ROS parameter server (XML-RPC) sees them, as the swarm's /update_params does
        values, errors = param_values(req.params, (self.ns,), ros_param_or_none)
        written, write_errors = self._attached().update_params(values)
        errors.extend(write_errors)
        for name in written:
            rospy.loginfo("%s: parameter %s updated", self.config.uri, name)
        if errors:
            for e in errors:
                rospy.logerr("%s: update_params: %s", self.config.uri, e)
            raise rospy.ServiceException("update_params: %d of %d not applied: %s"
                                         % (len(errors), len(req.params), "; ".join(errors)))
        return UpdateParamsResponse()

    # -- worker callbacks (worker thread) -----------------------------------------------------------
    def on_params(self, values: Dict[str, Any]) -> None:
        groups: Dict[str, Dict[str, Any]] = {}
        for full, value in values.items():
            group, _, name = full.partition(".")
            groups.setdefault(group, {})[name] = param_server_value(value)
        for group, entries in groups.items():        # one call per group, not per parameter
            rospy.set_param("%s/%s" % (self.ns, group), entries)

    def on_log_stamped(self, topic: str, onboard_timestamp_ms: int, values: List[float], age_s: float) -> None:
        # stamped when the Crazyflie sampled it: arrival time minus its age (see server.log_timing)
        stamp = rospy.Time.now() - rospy.Duration.from_sec(max(0.0, age_s))
        pub = self._pubs.get(topic)
        custom = self._custom
        if topic == IMU_TOPIC and pub:
            msg = Imu()
            msg.header.stamp, msg.header.frame_id = stamp, self.frame_id
            msg.orientation_covariance[0] = -1.0
            msg.linear_acceleration.x = values[0] * GRAVITY
            msg.linear_acceleration.y = values[1] * GRAVITY
            msg.linear_acceleration.z = values[2] * GRAVITY
            msg.angular_velocity.x = values[3] * DEG_TO_RAD
            msg.angular_velocity.y = values[4] * DEG_TO_RAD
            msg.angular_velocity.z = values[5] * DEG_TO_RAD
            pub.publish(msg)
        elif topic == TEMPERATURE_TOPIC and pub:
            msg = Temperature()
            msg.header.stamp, msg.header.frame_id = stamp, self.frame_id
            msg.temperature = values[0]
            pub.publish(msg)
        elif topic == MAGNETIC_FIELD_TOPIC and pub:
            msg = MagneticField()
            msg.header.stamp, msg.header.frame_id = stamp, self.frame_id
            msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = values[0], values[1], values[2]
            pub.publish(msg)
        elif topic in (PRESSURE_TOPIC, BATTERY_TOPIC) and pub:
            pub.publish(Float32(values[0]))
        elif topic == POSE_TOPIC and self._pose is not None:
            self._pose.publish(stamp, values)
        elif topic in custom:
            msg = GenericLogData()
            msg.header.stamp, msg.header.frame_id = stamp, self.frame_id
            msg.onboard_timestamp = int(onboard_timestamp_ms) & 0xFFFFFFFF
            msg.values = [float(v) for v in values]
            custom[topic].publish(msg)

    def on_rssi(self, rssi: float) -> None:
        pub = self._rssi_pub
        if pub is not None:
            pub.publish(Float32(rssi))

    def on_link_lost(self, reason: str) -> None:
        self.publish_status()       # the worker logged it through the forwarded logger

    def on_link_restored(self) -> None:
        self.publish_status()

    def on_packet(self, packet) -> None:
        pub = self._packets_pub
        if pub is not None:
            size, header, data = packet_fields(packet)
            pub.publish(crtpPacket(size=size, header=header, data=data))

    def _on_send_packet(self, req):
        p = req.packet
        if self.worker is None:
            raise rospy.ServiceException("send_packet: %s is not connected yet" % self.config.uri)
        try:
            self.worker.send_raw(raw_packet(p.header, p.size, bytearray(p.data)))
        except CrazyflieError as e:
            raise rospy.ServiceException(str(e)) from e
        return sendPacketResponse()

    def on_console(self, line: str) -> None:
        rospy.loginfo(rosout_line(self.ns.strip("/") or str(self.config.uri), line))

    def on_log_late(self, message: str, late: bool) -> None:
        self.publish_status()

    def late_cause(self) -> str:
        return self._late_cause() if self._late_cause is not None else super().late_cause()

    def on_emergency(self) -> None:
        self.publish_status()

    def on_safety(self, event: str) -> None:
        self.publish_status()

    def on_worker_error(self, message: str, gave_up: bool) -> None:
        self.publish_status(force=True)
        if gave_up and self._on_gave_up is not None:
            # not in the worker's own thread: removing joins it
            threading.Thread(target=self._on_gave_up, name="remove %s" % self.config.uri, daemon=True).start()


def topic_switches_of(tf_prefix: str) -> Dict[str, Any]:
    """The original driver's ``enable_logging_<topic>``/``use_ros_time`` switches that ``crazyflie_add``
    left under the Crazyflie's namespace (the chapter's AddCrazyflie request has no fields for them)."""
    names = [n for n, _ in TOPIC_SWITCHES] + list(ACCEPTED_SWITCHES)
    ns = namespace(tf_prefix)
    return {n: rospy.get_param(ns + "/" + n) for n in names if rospy.has_param(ns + "/" + n)}


def config_from_request(req) -> WorkerConfig:
    return WorkerConfig(
        uri=req.uri, tf_prefix=req.tf_prefix.strip("/"), roll_trim=float(req.roll_trim),
        pitch_trim=float(req.pitch_trim), enable_logging=bool(req.enable_logging),
        enable_parameters=bool(req.enable_parameters),
        log_blocks=tuple(LogBlockSpec(b.topic_name, int(b.frequency), tuple(b.variables))
                         for b in req.log_blocks))


class CrazyflieServer:
    """The services of the server and the ROS objects of each Crazyflie. ``clock``: the one the
    registry's workers run on (``ros_clock()``), which also times the diagnostics and the shutdown."""

    def __init__(self, registry: CrazyflieRegistry, add_timeout: float, clock: Clock = WALL) -> None:
        self.registry = registry
        self.clock = clock
        self.add_timeout = add_timeout
        # An empty tf_prefix makes every name of that Crazyflie global: only when asked for.
        self.allow_empty_tf_prefix = bool(rospy.get_param("~allow_empty_tf_prefix", False))
        self._ros: Dict[str, RosCrazyflie] = {}
        self._gone: Dict[str, DiagnosticStatus] = {}    # removed after their worker gave up, until added again
        self._lock = threading.Lock()
        self._broadcasts: Dict[int, List[Any]] = {}     # dongle -> BroadcastStatistics of its broadcast links
        self._broadcast_plan: List[radio_budget.BroadcastDemand] = []
        self._budget: List[radio_budget.DongleBudget] = []
        self._radio_windows: Dict[int, CounterWindow] = {}
        self.budget_setpoint_rate = float(rospy.get_param("~budget_setpoint_rate", radio_budget.DEFAULT_SETPOINT_HZ))
        self.budget_pose_rate = float(rospy.get_param("~budget_pose_rate", 0.0))
        self._landing_lock = threading.Lock()
        self._landed = False
        self._loop_lag_s: Optional[float] = None        # how late the diagnostics timer woke (host CPU)
        self._world: Optional[Tuple[float, float]] = None   # (simulated world's speed share, when heard)
        self._bottleneck = UNKNOWN_BOTTLENECK
        self._diag_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        if os.environ.get("CRAZYFLIE_BACKEND") == "sim":     # the world's real-time factor, on its /diagnostics
            rospy.Subscriber("/diagnostics", DiagnosticArray, self._on_diagnostics, queue_size=5)
        rospy.Service("/add_crazyflie", AddCrazyflie, self._on_add)
        rospy.Service("/remove_crazyflie", RemoveCrazyflie, self._on_remove)
        threading.Thread(target=self._diagnostics_loop, name="diagnostics", daemon=True).start()

    def add_broadcasts(self, index: int, stats: Any, plan: Optional[radio_budget.BroadcastDemand] = None) -> None:
        """Count a broadcast link's packets (its ``BroadcastStatistics``) on dongle ``index``'s entry, and
        add its planned bursts to the radio budget (swarm mode calls this for each of its links)."""
        with self._lock:
            self._broadcasts.setdefault(index, []).append(stats)
            if plan is not None:
                self._broadcast_plan.append(plan)
        self.check_radio_budget()

    def check_radio_budget(self, warn: bool = True) -> List[radio_budget.DongleBudget]:
        """The radio budget of the Crazyflies served now (their log blocks, ``~budget_setpoint_rate`` and
        ``~budget_pose_rate``) and the broadcasts added; a dongle that will be short is logged as a warning
        (``warn``)."""
        with self._lock:
            served = [(key, ros, ros.worker) for key, ros in self._ros.items()
                      if ros.worker is not None and radio_uri_of(key) is not None]     # usb:// takes no radio
            plan = list(self._broadcast_plan)
        demands = [radio_budget.CrazyflieDemand(ros.config.tf_prefix or key, parse_uri(key), self.budget_setpoint_rate,
                                                self.budget_pose_rate, worker.log_packet_rate)
                   for key, ros, worker in served]
        budget = radio_budget.check_budget(demands, plan)
        self._budget = budget
        for b in budget:
            if b.level and warn:
                rospy.logwarn("radio budget: %s", b.message())
        return budget

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.hardware_id == SIM_HARDWARE_ID:
                share = world_speed_share({kv.key: kv.value for kv in st.values})
                if share is not None:
                    self._world = (share, self.clock.now())

    def late_cause(self) -> str:
        """The bottleneck the last /diagnostics named (said where a Crazyflie's log data arrives late)."""
        return self._bottleneck

    def _replan_quietly(self) -> None:
        """The budget without the Crazyflie that left (its radio entry's planned load follows)."""
        try:
            self.check_radio_budget(warn=False)
        except Exception as e:      # bookkeeping must never fail a removal
            rospy.logerr("radio budget check failed: %r", e)

    def diagnostics(self) -> DiagnosticArray:
        arr = DiagnosticArray()
        arr.header.stamp = rospy.Time.now()
        with self._lock:
            served = list(self._ros.items())
            arr.status.extend(self._gone.values())
            broadcasts = {i: sum(s.packets for s in stats) for i, stats in self._broadcasts.items()}
        by_dongle: Dict[int, List[Any]] = {}
        for key, ros in served:
            try:
                arr.status.extend(ros.diagnostics())
            except Exception as e:      # one Crazyflie's bookkeeping must not hide the others
                arr.status.append(DiagnosticStatus(level=DiagnosticStatus.ERROR, hardware_id=key, message=(
                    "diagnostics failed: %r" % e), name="crazyflie_server: %s" % (ros.config.tf_prefix or key)))
            radio = radio_uri_of(key)
            if radio is not None:                  # a Crazyflie on a USB cable takes no radio's time
                by_dongle.setdefault(radio.index, []).append((key, ros))
        now = self.clock.now()
        loads: List[Tuple[int, float]] = []
        for index in sorted(set(by_dongle) | set(broadcasts)):
            members = by_dongle.get(index, [])
            window = self._radio_windows.setdefault(index, CounterWindow())
            span, grown = window.update(now, {"broadcasts": broadcasts.get(index, 0)})
            links = [ros.figures.link for _, ros in members if ros.figures.link is not None]
            planned = radio_budget.find(self._budget, index)
            names = tuple(sorted(ros.config.tf_prefix or key for key, ros in members))
            figures = RadioFigures(
                index, span, sum(f.per_s(f.round_trips) for f in links), int(grown["broadcasts"]), names,
                radio_budget.capacity_per_s([parse_uri(key) for key, _ in members]),
                planned.load if planned else None, "; ".join(planned.advice) if planned else "")
            arr.status.append(entry_status(radio_entry(figures), "", "radio://%d" % index))
            loads.append((index, figures.load))
        world = self._world
        share = world[0] if world is not None and now - world[1] < WORLD_FIGURE_STALE_S else None
        bottleneck = bottleneck_entry(BottleneckFigures(share, self._loop_lag_s, tuple(loads)))
        self._bottleneck = bottleneck.message
        arr.status.append(entry_status(bottleneck, "", "crazyflie_server"))
        return arr

    def _diagnostics_loop(self) -> None:
        while not shutting_down():
            slept = self.clock.now()
            self.clock.sleep(DIAGNOSTICS_PERIOD)
            # how late this loop woke, on the clock its deadlines are kept on (host CPU starvation)
            self._loop_lag_s = max(0.0, self.clock.now() - slept - DIAGNOSTICS_PERIOD)
            try:
                with self._lock:
                    served = list(self._ros.values())
                for ros in served:
                    ros.publish_status(force=True)      # its figures (ages, rates) change all the time
                publish_unless_shutting_down(self._diag_pub, self.diagnostics())
            except Exception as e:  # never let bookkeeping end the node
                rospy.logerr("crazyflie_server: diagnostics failed: %r", e)

    def _remove_failed(self, key: str) -> None:
        """The worker of ``key`` gave up: take its topics and services away, keep it on /diagnostics."""
        with self._lock:
            ros = self._ros.pop(key, None)
        if ros is None:
            return
        final = ros.diagnostic()
        final.message = "removed: " + final.message
        with self._lock:
            self._gone[key] = final
        try:
            self.registry.remove(key)
        except KeyError:
            pass
        ros.detach()
        self._replan_quietly()
        rospy.logerr("%s removed: its worker failed repeatedly (see the errors above); add it again to fly it", key)

    def _on_add(self, req) -> AddCrazyflieResponse:
        try:
            config = check_config(config_from_request(req), self.allow_empty_tf_prefix)
            config = apply_topic_switches(config, topic_switches_of(config.tf_prefix))
            self.registry.canonical_uri(config.uri)      # a malformed URI is refused here
        except ValueError as e:
            rospy.logerr("add_crazyflie: %s", e)
            raise rospy.ServiceException(str(e)) from e
        self.add(config)
        return AddCrazyflieResponse()

    def add(self, config: WorkerConfig) -> RosCrazyflie:
        """Connect and serve a checked Crazyflie (``/add_crazyflie``, the swarm file); rospy.ServiceException
        with the reason when it cannot be added."""
        key = self.registry.canonical_uri(config.uri)
        if not config.tf_prefix:
            rospy.logwarn("add_crazyflie: %s with an empty tf_prefix: its topics and services are global", key)
        try:        # refused before any publisher is made, so the served one's topics stay untouched
            self.registry.check_free(config)
        except DuplicateCrazyflie as e:
            msg = "could not add %s: %s" % (key, e)
            rospy.logerr(msg)
            raise rospy.ServiceException(msg) from None
        rospy.loginfo("adding %s as %r", key, config.tf_prefix)
        ros = worker = None
        try:
            safety = SafetyConfig.from_params(lambda name, default: rospy.get_param(
                namespace(config.tf_prefix) + "/" + name, rospy.get_param("~" + name, default)))
        except ValueError as e:
            rospy.logerr("add_crazyflie: %s", e)
            raise rospy.ServiceException(str(e)) from e
        try:
            ros = RosCrazyflie(config, on_gave_up=lambda: self._remove_failed(key), late_cause=self.late_cause)
            worker = self.registry.add(config, ros, timeout=self.add_timeout)
            worker.safety.configure(safety)
        except Exception as e:
            if worker is not None:      # added, then its safety configuration failed: never left running
                self.registry.remove(key)
            if ros is not None:
                ros.detach()
            msg = "could not add %s: %s" % (key, e)
            rospy.logerr(msg)
            raise rospy.ServiceException(msg) from e
        try:
            ros.attach(worker)
        except Exception as e:      # a name the master refuses: never a Crazyflie without its emergency service
            ros.detach()
            self.registry.remove(key)
            msg = "could not add %s: its topics or services could not be registered: %s" % (key, e)
            rospy.logerr(msg)
            raise rospy.ServiceException(msg) from e
        with self._lock:
            self._ros[key] = ros
            self._gone.pop(key, None)
        try:
            self.check_radio_budget()
        except Exception as e:      # bookkeeping must never fail an add
            rospy.logerr("radio budget check failed: %r", e)
        rospy.loginfo("%s ready (%s%s)", key, "logging: %s" % ", ".join(worker.log_topics)
                      if worker.log_topics else "no logging",
                      "; no %s on this Crazyflie" % ", ".join(worker.missing_fixed_topics)
                      if worker.missing_fixed_topics else "")
        return ros

    def _on_remove(self, req) -> RemoveCrazyflieResponse:
        try:
            key = self.registry.canonical_uri(req.uri)
            self.bring_down([self.registry.get(key)], "removed by /remove_crazyflie")   # never left flying
            self.registry.remove(key)
        except (ValueError, KeyError) as e:
            msg = "could not remove %s: %s" % (req.uri, str(e).strip("'\""))
            rospy.logerr(msg)
            raise rospy.ServiceException(msg) from e
        with self._lock:
            ros = self._ros.pop(key, None)
        if ros is not None:
            ros.detach()
        rospy.loginfo("%s removed", key)
        self._replan_quietly()
        return RemoveCrazyflieResponse()

    def land_all(self, reason: str = "") -> None:
        """Land or descend every Crazyflie in the air, within ``~safety/shutdown_timeout_s`` (the
        server's shutdown; runs before the links close). Once: a second caller waits for the first."""
        with self._landing_lock:
            if not self._landed:
                self._landed = True
                self._land_all(reason)

    def _land_all(self, reason: str) -> None:
        for worker in self.registry.workers():
            worker.server_exiting()     # a simulated world stopped by the same Ctrl-C may now go first
        self.bring_down(self.registry.workers(), "server shutting down (%s)" % (reason or "shutdown"))

    def bring_down(self, workers: List[CrazyflieWorker], why: str) -> None:
        """Land or descend those of ``workers`` in the air (the shutdown reaction), waiting up to their
        ``~safety/shutdown_timeout_s`` for it to end; their setpoints are refused from now on."""
        budget = max([w.safety.config.shutdown_timeout_s for w in workers] or [0.0])
        bring_down(workers, why, budget, self.clock)

    def shutdown(self) -> None:
        self.land_all("shutdown")
        self.registry.shutdown()


def make_factory(timeout: float, clock: Clock = WALL):
    """Crazyflies sharing one RadioManager (one SharedRadio per dongle), their request timeouts on ``clock``."""
    from crazyflie_driver import usb_choice
    from crazyflie_driver.protocol.crazyflie import Crazyflie

    manager = usb_choice.radio_manager()
    cache_dir = os.environ.get("CRAZYFLIE_TOC_CACHE") or None

    def factory(uri: str):
        return Crazyflie(uri, radio_manager=manager, cache_dir=cache_dir, timeout=timeout, clock=clock)
    return factory


def forward_library_log() -> None:
    """The library's Python log records go to rosout (once per process)."""
    lib_log = logging.getLogger("crazyflie_driver")
    if not any(isinstance(h, RosLogHandler) for h in lib_log.handlers):
        lib_log.addHandler(RosLogHandler())
    lib_log.setLevel(logging.INFO)
    lib_log.propagate = False


def start_server(timeout: float, add_timeout: float) -> CrazyflieServer:
    """The services and the diagnostics of a server in this (already initialised) node, timed on ROS time
    (``ros_clock``: the world's in a simulation under /use_sim_time, else the wall clock)."""
    forward_library_log()
    clock = ros_clock()
    server = CrazyflieServer(CrazyflieRegistry(make_factory(timeout, clock), {"clock": clock}), add_timeout, clock)
    # before rospy's shutdown flag rises: rospy.spin() keeps the process alive while they land
    rospy.core.add_preshutdown_hook(server.land_all)
    rospy.on_shutdown(server.shutdown)
    return server


def main() -> None:
    init_node("crazyflie_server")
    timeout = float(rospy.get_param("~timeout", 1.0))
    add_timeout = float(rospy.get_param("~add_timeout", 30.0))
    try:
        server = start_server(timeout, add_timeout)
        start_swarm(server)      # only with ~swarm_file
    except Exception as e:       # e.g. no usable USB backend, a bad swarm file
        rospy.logfatal("crazyflie_server cannot start: %s", e)
        raise SystemExit(1) from None
    rospy.loginfo("crazyflie_server ready (backend: %s)", os.environ.get("CRAZYFLIE_BACKEND", "usb"))
    rospy.spin()
    server.land_all("shutdown")     # the process ends after this: never while a Crazyflie comes down


if __name__ == "__main__":
    main()
