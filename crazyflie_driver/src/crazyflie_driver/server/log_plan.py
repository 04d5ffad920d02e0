"""Which log blocks to ask a Crazyflie for: the driver's topics, custom topics, and their packing.

The server publishes each topic from one log packet, so a topic's variables must fit one
firmware log block (26 bytes of values). This module holds the fixed sensor topics, checks the
custom ones a user asks for (before any radio traffic), and packs topics into as few blocks as
fit: the fewer blocks, the fewer packets share the radio. The firmware's limits on blocks and
variables are counted over the driver's own topics and the custom ones together, before the first
block is created: an add that asks for more is refused whole, with the numbers and what to change
(a partial set of topics would leave the user's missing topic silent). Pure functions, no link.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import AbstractSet, Dict, List, Sequence, Tuple

from crazyflie_driver.crtp.ctypes import type_size
from crazyflie_driver.crtp.firmware_limits import (
    LOG_BLOCK_MAX_BYTES,
    LOG_MAX_BLOCKS,
    LOG_MAX_OPS,
    LOG_PERIOD_MAX_MS,
    LOG_PERIOD_MIN_MS,
)
from crazyflie_driver.errors import LogConfigError, UnknownName
from crazyflie_driver.protocol.toc import check_toc_name
from crazyflie_driver.server.raw_packets import PACKETS_TOPIC

IMU_TOPIC = "imu"
TEMPERATURE_TOPIC = "temperature"
MAGNETIC_FIELD_TOPIC = "magnetic_field"
PRESSURE_TOPIC = "pressure"
BATTERY_TOPIC = "battery"
RADIO_RSSI_TOPIC = "rssi"
BATTERY_VARIABLE = "pm.vbat"            # battery voltage [V]; the safety monitor's input

# The fixed sensor topics: (topic, period ms, log variables). A topic is delivered whole (all
# its values from one log packet); topics of the same period share blocks as they fit.
FIXED_LOG_TOPICS: Tuple[Tuple[str, int, Tuple[str, ...]], ...] = (
    (IMU_TOPIC, 10, ("acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z")),
    (TEMPERATURE_TOPIC, 100, ("baro.temp",)),
    (MAGNETIC_FIELD_TOPIC, 100, ("mag.x", "mag.y", "mag.z")),
    (PRESSURE_TOPIC, 100, ("baro.pressure",)),
    (BATTERY_TOPIC, 100, (BATTERY_VARIABLE,)),
)
#: crazyflie_add's per-topic switches (the original driver's names) and the fixed topic each turns off.
TOPIC_SWITCHES: Tuple[Tuple[str, str], ...] = (
    ("enable_logging_imu", IMU_TOPIC),
    ("enable_logging_temperature", TEMPERATURE_TOPIC),
    ("enable_logging_magnetic_field", MAGNETIC_FIELD_TOPIC),
    ("enable_logging_pressure", PRESSURE_TOPIC),
    ("enable_logging_battery", BATTERY_TOPIC),
)
#: The original driver's switch of the onboard ``pose`` topic (crazyflie_add default false).
POSE_SWITCH = "enable_logging_pose"
#: The original driver's switch of the ``packets`` topic (downlink packets nothing in the server reads).
PACKETS_SWITCH = "enable_logging_packets"


def fixed_log_topics(disabled: AbstractSet[str]) -> List[Tuple[str, int, Tuple[str, ...]]]:
    """The fixed sensor topics without the ``disabled`` ones: a topic switched off is not asked of the
    firmware at all, so its log packets leave the radio."""
    return [t for t in FIXED_LOG_TOPICS if t[0] not in disabled]


RSSI_LOG_VARIABLE = "radio.rssi"    # current firmware: RSSI is a log variable, not in the acks
# Topics only /diagnostics reads (no ROS topic): (topic, the fixed topic whose period it takes, variables).
# Each fits in that topic's block (IMU 24 + 2 bytes; the 100 ms topics 24 + 1, + 1 for radio.rssi), so
# it costs no packet of its own; left out, silently, where the firmware lacks the variable.
POWER_STATE_TOPIC = "power_state"
SUPERVISOR_TOPIC = "supervisor"
DIAGNOSTIC_LOG_TOPICS: Tuple[Tuple[str, str, Tuple[str, ...]], ...] = (
    (POWER_STATE_TOPIC, BATTERY_TOPIC, ("pm.state",)),
    (SUPERVISOR_TOPIC, IMU_TOPIC, ("supervisor.info",)),    # current firmware only
)
STATUS_TOPIC = "status"            # the Crazyflie's DiagnosticStatus (nodes.crazyflie_server)
# The node's own per-Crazyflie topics besides the log topics: what it subscribes to (nodes.crazyflie_server,
# nodes.onboard_ros) and publishes. A custom log topic of one of these names would be a second type on it.
NODE_TOPICS = frozenset({"cmd_vel", "emergency", "update_params", STATUS_TOPIC, PACKETS_TOPIC, "cmd_position",
                         "cmd_hover", "cmd_full_state", "cmd_velocity_world", "cmd_stop", "external_position",
                         "external_pose"})
RESERVED_TOPIC_NAMES = frozenset(t for t, _, _ in FIXED_LOG_TOPICS) | {
    RADIO_RSSI_TOPIC, POWER_STATE_TOPIC, SUPERVISOR_TOPIC} | NODE_TOPICS


@dataclass(frozen=True)
class LogBlockSpec:
    """A custom log block: published as GenericLogData on ``topic_name`` every ``period_ms``."""

    topic_name: str
    period_ms: int
    variables: Tuple[str, ...]


def validate_log_block_specs(blocks: Sequence[LogBlockSpec]) -> None:
    """Checks that need no Crazyflie: names, periods, duplicates. Raises ValueError naming the fault."""
    seen = set()
    for b in blocks:
        name = b.topic_name
        if not name or not all(c.isalnum() or c in "_/" for c in name) or not (name[0].isalpha()
                                                                                or name[0] == "/"):
            raise ValueError("custom log topic %r is not a valid ROS name (letters, digits, '_', '/', "
                             "starting with a letter)" % (name,))
        if name in RESERVED_TOPIC_NAMES:
            raise ValueError("custom log topic %r clashes with the driver's own topic of that name"
                             % (name,))
        if name in seen:
            raise ValueError("custom log topic %r is given twice" % (name,))
        seen.add(name)
        if not LOG_PERIOD_MIN_MS <= int(b.period_ms) <= LOG_PERIOD_MAX_MS:
            raise ValueError("custom log topic %r: period %r ms is outside %d..%d ms (the value of "
                             "genericLogTopicFrequencies is a period in milliseconds)"
                             % (name, b.period_ms, LOG_PERIOD_MIN_MS, LOG_PERIOD_MAX_MS))
        if not b.variables:
            raise ValueError("custom log topic %r has no variables" % (name,))
        for v in b.variables:
            group, dot, var = v.partition(".")
            if not dot or not group or not var:
                raise ValueError("custom log topic %r: variable %r is not of the form group.name"
                                 % (name, v))
            try:
                check_toc_name(v, "log variable")
            except UnknownName as e:
                raise ValueError("custom log topic %r: %s" % (name, e)) from None


@dataclass
class PlannedBlock:
    """One firmware log block: its period, its variables, and which topic owns which slice."""

    period_ms: int
    variables: List[str] = field(default_factory=list)
    size: int = 0
    topics: List[Tuple[str, int, int]] = field(default_factory=list)   # (topic, start, stop)


def topic_size(topic: str, variables: Sequence[str], types: Dict[str, str]) -> int:
    """Bytes one packet of ``variables`` needs. Raises UnknownName / LogConfigError naming the fault."""
    unknown = [v for v in variables if v not in types]
    if unknown:
        raise UnknownName("log topic %r: unknown log variable(s) %s (not in the Crazyflie's log TOC)"
                          % (topic, ", ".join(unknown)))
    size = sum(type_size(types[v]) for v in variables)
    if size > LOG_BLOCK_MAX_BYTES:
        raise LogConfigError("log topic %r needs %d bytes per packet (%s); a log block holds at most "
                             "%d bytes: split it into several topics"
                             % (topic, size, ", ".join("%s %s" % (v, types[v]) for v in variables),
                                LOG_BLOCK_MAX_BYTES))
    return size


def plan_log_blocks(topics: Sequence[Tuple[str, int, Sequence[str]]], types: Dict[str, str],
                    share: bool = True) -> List[PlannedBlock]:
    """Pack topics into firmware log blocks of at most 26 bytes.

    Each topic stays whole in one block, so one packet carries all of a message's values.
    With ``share`` topics of the same period are packed together (first fit, largest first);
    without it every topic gets its own block.
    """
    sized = [(name, int(period), list(vs), topic_size(name, vs, types)) for name, period, vs in topics]
    blocks: List[PlannedBlock] = []
    order = sorted(sized, key=lambda t: -t[3]) if share else sized
    for name, period, vs, size in order:
        target = None
        if share:
            for b in blocks:
                if b.period_ms == period and b.size + size <= LOG_BLOCK_MAX_BYTES:
                    target = b
                    break
        if target is None:
            target = PlannedBlock(period_ms=period)
            blocks.append(target)
        start = len(target.variables)
        target.variables.extend(vs)
        target.size += size
        target.topics.append((name, start, start + len(vs)))
    return blocks


def log_packet_rate(plan: Sequence[PlannedBlock]) -> float:
    """Log packets per second the planned blocks produce."""
    return sum(1000.0 / b.period_ms for b in plan if b.period_ms > 0)


def check_custom_log_limits(blocks: Sequence[LogBlockSpec], enable_logging: bool,
                            max_blocks: int = LOG_MAX_BLOCKS, max_ops: int = LOG_MAX_OPS) -> None:
    """Custom log blocks alone against the firmware's block and variable limits (each custom topic
    is one block): the check that needs no Crazyflie, so an add that can never fit is refused at
    once. The driver's own topics come on top; :func:`check_log_limits` counts them once the
    Crazyflie's log TOC is known. LogConfigError naming the limit and what to change."""
    own = (" (with enable_logging the driver's own topics need at least %d blocks and %d variables more)"
           % (len({p for _, p, _ in FIXED_LOG_TOPICS}), sum(len(v) for _, _, v in FIXED_LOG_TOPICS))
           if enable_logging else "")
    if len(blocks) > max_blocks:
        raise LogConfigError(
            "%d custom log topics need %d log blocks (one each), the Crazyflie's firmware holds at most %d%s: "
            "remove at least %d custom topics, or put variables of the same period into one topic (up to %d bytes "
            "each)" % (len(blocks), len(blocks), max_blocks, own, len(blocks) - max_blocks, LOG_BLOCK_MAX_BYTES))
    ops = sum(len(b.variables) for b in blocks)
    if ops > max_ops:
        raise LogConfigError(
            "the custom log topics hold %d log variables, the Crazyflie's firmware holds at most %d over all "
            "blocks%s: remove at least %d variables" % (ops, max_ops, own, ops - max_ops))


def _describe(blocks: Sequence[PlannedBlock]) -> str:
    return "; ".join(", ".join(t for t, _, _ in b.topics) for b in blocks)


def check_log_limits(plan: Sequence[PlannedBlock], custom_topics: AbstractSet[str],
                     max_blocks: int = LOG_MAX_BLOCKS, max_ops: int = LOG_MAX_OPS) -> None:
    """A whole plan (the driver's own topics and the custom ones) against the firmware's limits on
    log blocks and log variables (the TOC info reports them), before any block is created.

    LogConfigError naming the limit, what the driver's topics and the custom topics use and what
    to change; nothing is sent when it raises."""
    custom = [b for b in plan if any(t in custom_topics for t, _, _ in b.topics)]
    own = [b for b in plan if b not in custom]
    own_ops = sum(len(b.variables) for b in own)
    custom_ops = sum(len(b.variables) for b in custom)
    own_text = ("the driver's own topics use %d (%s)" % (len(own), _describe(own)) if own
                else "the driver's own topics use none")
    fix_own = (", or set enable_logging false to free the driver's %d blocks and %d variables"
               % (len(own), own_ops) if own else "")
    if len(plan) > max_blocks:
        raise LogConfigError(
            "%d log blocks needed, the Crazyflie's firmware holds at most %d: %s, the %d custom topics one each: "
            "remove at least %d custom topics%s" % (len(plan), max_blocks, own_text, len(custom),
                                                    len(plan) - max_blocks, fix_own))
    if own_ops + custom_ops > max_ops:
        raise LogConfigError(
            "%d log variables needed, the Crazyflie's firmware holds at most %d over all blocks: the driver's own "
            "topics use %d, the custom topics %d: remove at least %d custom variables%s"
            % (own_ops + custom_ops, max_ops, own_ops, custom_ops, own_ops + custom_ops - max_ops, fix_own))
