"""One Crazyflie's health in a few words and numbers, for its ``status`` topic and ``/diagnostics``.

ROS-free: the node turns a :class:`CrazyflieStatus` into a ``diagnostic_msgs/DiagnosticStatus``;
the levels are the same numbers as that message's (OK 0, WARN 1, ERROR 2, STALE 3).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Optional, Tuple

from crazyflie_driver.server import power_control
from crazyflie_driver.server.diagnostics import ERROR, OK, STALE, WARN, worst
from crazyflie_driver.server.worker import WorkerState

__all__ = ["OK", "WARN", "ERROR", "STALE", "CrazyflieStatus", "worker_status"]


@dataclass(frozen=True)
class CrazyflieStatus:
    level: int
    message: str
    values: Tuple[Tuple[str, str], ...]


def worker_status(worker: Any) -> CrazyflieStatus:
    """The status of a :class:`~crazyflie_driver.server.worker.CrazyflieWorker` right now; the worst of
    its ``reports`` (e.g. a safety reaction) raises the level, and their messages are added."""
    state = worker.state
    quality, samples = worker.link_quality()
    level, message = _link_health(worker, state) or _running_health(worker)
    safety_level, safety_message, safety_values = worker.safety.report()
    if safety_level > level:
        level, message = safety_level, safety_message
    values = _worker_values(worker, state, "%.3f" % quality if samples else "n/a") + safety_values \
        + _topic_values(worker.topic_timing)
    reports = [r for r in worker.reports.entries() if r.level != OK]
    if reports:
        level = worst([level] + [r.level for r in reports])
        message = "; ".join([message] + ["%s: %s" % (r.part, r.message) for r in reports])
        values += tuple(("%s: %s" % (r.part, k), v) for r in reports for k, v in r.values)
    return CrazyflieStatus(level, message, values)


def _link_health(worker: Any, state: str) -> Optional[Tuple[int, str]]:
    """(level, message) when the worker does not run a link to its Crazyflie (or an emergency stop
    holds it), else None."""
    if state == WorkerState.FAILED:
        return ERROR, "worker gave up: %s" % (worker.last_unexpected_error or "connect failed")
    if worker.emergency_active:
        return ERROR, "emergency: motors stopped until a reboot: to fly again " + power_control.REBOOT_ADVICE
    if state == WorkerState.RESTARTING:
        return ERROR, "worker restarting after: %s" % worker.last_unexpected_error
    if state == WorkerState.LOST:
        return ERROR, "link lost: retrying"
    if state == WorkerState.POWERED_OFF:
        return WARN, "switched off on request (its %s service switches it on)" % power_control.POWER_ON_SERVICE
    if state in (WorkerState.CONNECTING, WorkerState.STOPPED):
        return STALE, state
    return None


def _running_health(worker: Any) -> Tuple[int, str]:
    """(level, message) of a worker whose link runs: motors stopped by the watchdog, late log data,
    past restarts, else OK."""
    if getattr(worker, "watchdog", None) is not None and worker.watchdog.message:
        return ERROR if worker.watchdog.locked_until_restart else WARN, "motors stopped: " + worker.watchdog.message
    if worker.log_late:
        return WARN, "running; log data arrives late (%d log packets seen lost so far)" % worker.lost_log_packets()
    if worker.restarts:
        return WARN, "running; worker restarted %d time(s), last after: %s" % (
            worker.restarts, worker.last_unexpected_error)
    return OK, "running"


def _worker_values(worker: Any, state: str, link_quality: str) -> Tuple[Tuple[str, str], ...]:
    """The worker's own counters as status values."""
    return (
        ("uri", worker.uri),
        ("state", state),
        ("emergency", str(bool(worker.emergency_active))),
        ("link_quality", link_quality),
        ("setpoints_sent", str(worker.setpoints_sent)),
        ("keepalives_sent", str(worker.keepalives_sent)),
        ("restarts", str(worker.restarts)),
        ("last_error", worker.last_unexpected_error),
        ("listener_errors", str(worker.listener_errors)),
        ("log_packets_lost", str(worker.lost_log_packets())),
    )


def _topic_values(timing: Mapping[str, Any]) -> Tuple[Tuple[str, str], ...]:
    """Age, rate and losses of each input topic, by topic name."""
    values: Tuple[Tuple[str, str], ...] = ()
    for topic, t in sorted(timing.items()):
        values += (("%s age_s" % topic, "%.3f" % t.age), ("%s rate_hz" % topic, "%.1f" % t.rate),
                   ("%s lost" % topic, str(t.lost)))
    return values
