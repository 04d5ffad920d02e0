"""What the vrpn_client_node does with each report, without ROS: parameters, tracker names,
the optional Y-up conversion, twist from VRPN velocity, staleness bookkeeping.

The node only turns the records made here into messages. Kept apart so the whole path from
bytes to publish-ready values is unit-tested and benchmarked without a ROS master.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple

from crazyflie_driver.clock import WALL
from crazyflie_driver.mocap import vrpn_protocol as vp
from crazyflie_driver.mocap.frames import quaternion_to_rotation_vector, y_up_to_z_up_quaternion, y_up_to_z_up_vector
from crazyflie_driver.mocap.names import clean_tracker_name, frame_name
from crazyflie_driver.mocap.staleness import StalenessMonitor
from crazyflie_driver.mocap.vrpn_client import PoseReport, TwistReport, parse_server

LogFn = Callable[[int, str], None]


class VrpnConfigError(ValueError):
    """A node parameter with a value that cannot work (the message names the parameter)."""


@dataclass
class VrpnNodeConfig:
    """The node's private parameters: vrpn_client_ros's names and defaults, plus y_up and
    stale_timeout."""

    host: str = "localhost"
    port: int = vp.DEFAULT_PORT
    frame_id: str = "world"
    broadcast_tf: bool = False
    refresh_tracker_frequency: float = 0.0
    trackers: List[str] = field(default_factory=list)
    use_server_time: bool = False
    process_sensor_id: bool = False
    y_up: bool = False
    stale_timeout: float = 0.1

    @property
    def auto_discover(self) -> bool:
        """vrpn_client_ros adds the server's senders as trackers only when refreshing is on."""
        return self.refresh_tracker_frequency > 0


def _as_bool(name: str, v: Any) -> bool:
    if isinstance(v, bool):
        return v
    if isinstance(v, (int, float)) and v in (0, 1):
        return bool(v)
    if isinstance(v, str) and v.strip().lower() in ("true", "false", "1", "0", "yes", "no"):
        return v.strip().lower() in ("true", "1", "yes")
    raise VrpnConfigError("parameter ~%s must be true or false, got %r" % (name, v))


def _as_float(name: str, v: Any, minimum: float) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise VrpnConfigError("parameter ~%s must be a number, got %r" % (name, v)) from None
    if not math.isfinite(f) or f < minimum:
        raise VrpnConfigError("parameter ~%s must be >= %g, got %r" % (name, minimum, v))
    return f


def config_from_params(params: Mapping[str, Any]) -> VrpnNodeConfig:
    """Validated configuration from private parameters (names without the '~')."""
    port = params.get("port")
    if port is not None:
        try:
            port = int(port)
        except (TypeError, ValueError):
            raise VrpnConfigError("parameter ~port must be an integer, got %r" % (port,)) from None
    try:
        host, port = parse_server(str(params.get("server", "localhost")), port)
    except ValueError as e:
        raise VrpnConfigError("parameter ~server/~port: %s" % e) from None
    trackers = params.get("trackers", [])
    if isinstance(trackers, str):
        trackers = [t for t in trackers.replace(",", " ").split() if t]
    if not isinstance(trackers, (list, tuple)) or not all(isinstance(t, str) and t for t in trackers):
        raise VrpnConfigError("parameter ~trackers must be a list of tracker names, got %r" % (trackers,))
    frame_id = str(params.get("frame_id", "world")).lstrip("/")
    if not frame_id:
        raise VrpnConfigError("parameter ~frame_id must not be empty")
    stale = _as_float("stale_timeout", params.get("stale_timeout", 0.1), 0.0)
    if stale <= 0:
        raise VrpnConfigError("parameter ~stale_timeout must be > 0 s, got %r" % (stale,))
    return VrpnNodeConfig(
        host=host, port=port, frame_id=frame_id,
        broadcast_tf=_as_bool("broadcast_tf", params.get("broadcast_tf", False)),
        refresh_tracker_frequency=_as_float("refresh_tracker_frequency",
                                            params.get("refresh_tracker_frequency", 0.0), 0.0),
        trackers=list(trackers),
        use_server_time=_as_bool("use_server_time", params.get("use_server_time", False)),
        process_sensor_id=_as_bool("process_sensor_id", params.get("process_sensor_id", False)),
        y_up=_as_bool("y_up", params.get("y_up", False)),
        stale_timeout=stale)


@dataclass(frozen=True)
class PoseOut:
    """A pose ready to publish: ``key`` is the topic path under the node ("cf1", or "cf1/0")."""

    key: str
    child_frame: str
    position: vp.Vec3
    orientation: vp.Quat
    report: PoseReport


@dataclass(frozen=True)
class TwistOut:
    key: str
    linear: vp.Vec3
    angular: vp.Vec3            # rad/s: rotation vector of vel_quat divided by its dt
    report: TwistReport


class VrpnBridge:
    """Turns client reports into publish-ready records; thread safe for one reader thread."""

    def __init__(self, config: VrpnNodeConfig, clock: Callable[[], float] = WALL.now,
                 log: Optional[LogFn] = None) -> None:
        self.config = config
        self.clock = clock
        self._log = log or (lambda level, text: logging.getLogger("crazyflie_driver.mocap.vrpn").log(level, text))
        self.staleness = StalenessMonitor(config.stale_timeout)
        self._names: Dict[str, Optional[str]] = {}
        for t in config.trackers:
            clean = self.ros_name(t)
            if clean is not None:
                self.staleness.watch(clean)

    def ros_name(self, tracker: str) -> Optional[str]:
        """Cleaned name (cached); logs once when a tracker cannot have topics."""
        try:
            return self._names[tracker]
        except KeyError:
            clean = clean_tracker_name(tracker)
            self._names[tracker] = clean
            if clean is None:
                self._log(logging.ERROR, "VRPN tracker name %r is not a valid ROS name even after "
                          "cleaning: no topics for it (rename the rigid body)" % (tracker,))
            elif clean != tracker:
                self._log(logging.INFO, "VRPN tracker %r published as %r" % (tracker, clean))
            return clean

    def _z_up(self, vector: vp.Vec3, quaternion: vp.Quat) -> Tuple[vp.Vec3, vp.Quat]:
        """A vector and a rotation in ROS's frame (z up): converted when the motion capture sends y up."""
        if self.config.y_up:
            return y_up_to_z_up_vector(vector), y_up_to_z_up_quaternion(quaternion)
        return vector, quaternion

    def _key(self, clean: str, sensor: int) -> str:
        return "%s/%d" % (clean, sensor) if self.config.process_sensor_id else clean

    def pose(self, report: PoseReport) -> Optional[PoseOut]:
        clean = self.ros_name(report.tracker)
        if clean is None:
            return None
        pos, quat = self._z_up(report.position, report.orientation)
        key = self._key(clean, report.sensor)
        self.staleness.seen(key, report.receive_time)
        return PoseOut(key, frame_name(key), pos, quat, report)

    def twist(self, report: TwistReport) -> Optional[TwistOut]:
        clean = self.ros_name(report.tracker)
        if clean is None:
            return None
        lin, rot = self._z_up(report.linear, report.rotation)
        if report.dt > 0:
            rv = quaternion_to_rotation_vector(rot)
            ang = (rv[0] / report.dt, rv[1] / report.dt, rv[2] / report.dt)
        else:
            ang = (0.0, 0.0, 0.0)               # no interval: no rate can be given
        return TwistOut(self._key(clean, report.sensor), lin, ang, report)
