"""One Crazyflie's health in a few words and numbers, for its ``status`` topic and ``/diagnostics``.

ROS-free: the node turns a :class:`CrazyflieStatus` into a ``diagnostic_msgs/DiagnosticStatus``;
the levels are the same numbers as that message's (OK 0, WARN 1, ERROR 2, STALE 3).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Tuple

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
    if state == WorkerState.FAILED:
        level, message = ERROR, "worker gave up: %s" % (worker.last_unexpected_error or "connect failed")
    elif worker.emergency_active:
        level, message = ERROR, "emergency: motors stopped until a reboot: to fly again " + power_control.REBOOT_ADVICE
    elif state == WorkerState.RESTARTING:
        level, message = ERROR, "worker restarting after: %s" % worker.last_unexpected_error
    elif state == WorkerState.LOST:
        level, message = ERROR, "link lost: retrying"
    elif state == WorkerState.POWERED_OFF:
        level, message = WARN, "switched off on request (its %s service switches it on)" % (
            power_control.POWER_ON_SERVICE)
    elif state in (WorkerState.CONNECTING, WorkerState.STOPPED):
        level, message = STALE, state
    elif getattr(worker, "watchdog", None) is not None and worker.watchdog.message:
        level = ERROR if worker.watchdog.locked_until_restart else WARN
        message = "motors stopped: " + worker.watchdog.message
    elif worker.log_late:
        level, message = WARN, "running; log data arrives late (%d log packets seen lost so far)" % (
            worker.lost_log_packets())
    elif worker.restarts:
        level, message = WARN, "running; worker restarted %d time(s), last after: %s" % (
            worker.restarts, worker.last_unexpected_error)
    else:
        level, message = OK, "running"
    safety_level, safety_message, safety_values = worker.safety.report()
    if safety_level > level:
        level, message = safety_level, safety_message
    values = (
        ("uri", worker.uri),
        ("state", state),
        ("emergency", str(bool(worker.emergency_active))),
        ("link_quality", "%.3f" % quality if samples else "n/a"),
        ("setpoints_sent", str(worker.setpoints_sent)),
        ("keepalives_sent", str(worker.keepalives_sent)),
        ("restarts", str(worker.restarts)),
        ("last_error", worker.last_unexpected_error),
        ("listener_errors", str(worker.listener_errors)),
        ("log_packets_lost", str(worker.lost_log_packets())),
    ) + safety_values
    for topic, t in sorted(worker.topic_timing.items()):
        values += (("%s age_s" % topic, "%.3f" % t.age), ("%s rate_hz" % topic, "%.1f" % t.rate),
                   ("%s lost" % topic, str(t.lost)))
    reports = [r for r in worker.reports.entries() if r.level != OK]
    if reports:
        level = worst([level] + [r.level for r in reports])
        message = "; ".join([message] + ["%s: %s" % (r.part, r.message) for r in reports])
        values += tuple(("%s: %s" % (r.part, k), v) for r in reports for k, v in r.values)
    return CrazyflieStatus(level, message, values)
