"""crazyflie_server's swarm-mode parameters, checked, without ROS.

``~swarm_file`` turns swarm mode on; the others tune it (names and defaults in the driver README,
"Swarm mode"). Every fault raises ``SwarmConfigError`` naming the parameter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Tuple

from crazyflie_driver.errors import SwarmConfigError
from crazyflie_driver.radio.broadcast import DEFAULT_REPEAT_INTERVAL_S, DEFAULT_REPEATS
from crazyflie_driver.server.add_config import AddConfigError, log_blocks_from_params
from crazyflie_driver.server.log_plan import LogBlockSpec
from crazyflie_driver.server.swarm.config import LOG_SWITCHES, Switches
from crazyflie_driver.server.swarm.watch import DEFAULT_HOLD_S, DEFAULT_STALE_AFTER_S

MOCAP_SOURCES = ("vrpn", "tf", "topic", "none")
#: Where each source finds Crazyflie ``{name}`` (its tf_prefix): a VRPN tracker, a tf child frame of
#: the world frame (vrpn_client_ros; vicon_bridge: ``vicon/{name}/{name}``), a PoseStamped topic.
DEFAULT_PATTERNS = {"vrpn": "{name}", "tf": "{name}", "topic": "/vrpn_client_node/{name}/pose", "none": "{name}"}


@dataclass(frozen=True)
class SwarmOptions:
    swarm_file: str
    swarm_types_file: str = ""
    mocap: str = "none"
    mocap_pattern: str = "{name}"
    vrpn_server: str = "localhost:3883"
    world_frame: str = "world"
    position_only: bool = False
    stale_after: float = DEFAULT_STALE_AFTER_S
    stale_hold: float = DEFAULT_HOLD_S
    stale_land_duration: float = 2.0
    broadcast_repeats: int = DEFAULT_REPEATS
    broadcast_interval: float = DEFAULT_REPEAT_INTERVAL_S
    enable_logging: bool = False
    pose_period_ms: Optional[int] = None     # None ("auto"): the radio budget chooses (radio_budget.pose_log_period_ms)
    dongle_wait: float = 30.0
    mocap_rate: float = 100.0       # Hz, the motion capture's frame rate: the most the stream sends
    emergency_watchdog: bool = True     # broadcast the emergency-stop watchdog keep-alive (swarm.heartbeat)
    switches: Switches = ()             # HEAD's logging switches given as parameters (the swarm file's win)
    log_blocks: Tuple[LogBlockSpec, ...] = ()   # Crazyswarm's genericLogTopics, for every Crazyflie


#: Crazyswarm's server parameters of its generic log topics (crazyswarm_server.cpp); the per-topic
#: ``genericLogTopic_<name>_Variables`` come beside them.
GENERIC_LOG_TOPICS = "genericLogTopics"
GENERIC_LOG_PERIODS = "genericLogTopicFrequencies"


def generic_log_variables_key(topic: str) -> str:
    return "genericLogTopic_%s_Variables" % topic


def generic_log_blocks(params: Mapping[str, Any], enable_logging: bool) -> Tuple[LogBlockSpec, ...]:
    """Crazyswarm's generic log topics from the server's parameters, the same names and meaning as
    ``crazyflie_add``'s (each "frequency" is a period in ms); as in Crazyswarm's server they exist only
    with ``~enable_logging`` (its shipped launch file lists a topic whose variables are commented out).
    SwarmConfigError naming the parameter and the fix."""
    if not enable_logging or GENERIC_LOG_TOPICS not in params:
        return ()
    try:
        return log_blocks_from_params(params)
    except AddConfigError as e:
        raise SwarmConfigError("swarm mode: %s" % e) from None


def generic_log_note(params: Mapping[str, Any], enable_logging: bool) -> Optional[str]:
    """Why generic log topics given as parameters are not published, or None."""
    if params.get(GENERIC_LOG_TOPICS) and not enable_logging:
        return ("~genericLogTopics %s given but ~enable_logging is false: no generic log topics (as in Crazyswarm's "
                "server, they come with enable_logging; set it true, and enable_logging_imu etc. false for the "
                "sensor topics you do not want)" % (params[GENERIC_LOG_TOPICS],))
    return None


def _bool(name: str, v: Any) -> bool:
    if isinstance(v, bool):
        return v
    if isinstance(v, str) and v.strip().lower() in ("true", "false", "1", "0"):
        return v.strip().lower() in ("true", "1")
    if isinstance(v, int) and v in (0, 1):
        return bool(v)
    raise SwarmConfigError("parameter ~%s must be true or false, got %r" % (name, v))


def _number(name: str, v: Any, minimum: float, strict: bool = False) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        f = float("nan")
    if isinstance(v, bool) or not math.isfinite(f) or f < minimum or (strict and f == minimum):
        raise SwarmConfigError("parameter ~%s must be a number %s %g, got %r" % (name, ">" if strict else ">=",
                                                                                 minimum, v))
    return f


def options_from_params(params: Mapping[str, Any]) -> SwarmOptions:
    """Checked options from the node's private parameters (names without ``~``)."""
    mocap = str(params.get("mocap", "none")).strip().lower()
    if mocap not in MOCAP_SOURCES:
        raise SwarmConfigError("parameter ~mocap must be one of %s, got %r" % (", ".join(MOCAP_SOURCES), mocap))
    pattern = str(params.get("mocap_pattern", "") or DEFAULT_PATTERNS[mocap])
    if "{name}" not in pattern:
        raise SwarmConfigError("parameter ~mocap_pattern must contain {name} (the Crazyflie's tf_prefix), got %r"
                               % pattern)
    repeats = _number("broadcast_repeats", params.get("broadcast_repeats", DEFAULT_REPEATS), 1)
    if repeats != int(repeats):
        raise SwarmConfigError("parameter ~broadcast_repeats must be a whole number, got %r" % (repeats,))
    period = params.get("pose_period_ms", "auto")
    if isinstance(period, str) and period.strip().lower() == "auto":
        period = None
    else:
        period = _number("pose_period_ms", period, 0)
        if period != int(period) or 0 < period < 10 or period > 2550:
            raise SwarmConfigError("parameter ~pose_period_ms must be auto (the radio budget chooses), 0 (no pose "
                                   "topic) or 10..2550 ms in whole milliseconds, got %r" % (period,))
        period = int(period)
    enable_logging = _bool("enable_logging", params.get("enable_logging", False))
    return SwarmOptions(
        swarm_file=str(params.get("swarm_file", "")),
        swarm_types_file=str(params.get("swarm_types_file", "") or ""),
        mocap=mocap,
        mocap_pattern=pattern,
        vrpn_server=str(params.get("vrpn_server", "localhost:3883")),
        world_frame=str(params.get("world_frame", "world")).strip("/"),
        position_only=_bool("position_only", params.get("position_only", False)),
        stale_after=_number("stale_after", params.get("stale_after", DEFAULT_STALE_AFTER_S), 0, strict=True),
        stale_hold=_number("stale_hold", params.get("stale_hold", DEFAULT_HOLD_S), 0),
        stale_land_duration=_number("stale_land_duration", params.get("stale_land_duration", 2.0), 0, strict=True),
        broadcast_repeats=int(repeats),
        broadcast_interval=_number("broadcast_interval", params.get("broadcast_interval",
                                                                   DEFAULT_REPEAT_INTERVAL_S), 0),
        enable_logging=enable_logging,
        pose_period_ms=period,
        dongle_wait=_number("dongle_wait", params.get("dongle_wait", 30.0), 0),
        mocap_rate=_number("mocap_rate", params.get("mocap_rate", 100.0), 0, strict=True),
        emergency_watchdog=_bool("emergency_watchdog", params.get("emergency_watchdog", True)),
        switches=tuple((n, _bool(n, params[n])) for n in LOG_SWITCHES if n in params),
        log_blocks=generic_log_blocks(params, enable_logging),
    )
