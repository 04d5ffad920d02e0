"""A worker's status line from its state alone: which condition wins, at which level, with which words
(a stand-in worker: the status reads only attributes and a few calls)."""
from __future__ import annotations

from types import SimpleNamespace
from typing import Any, List

import pytest

from crazyflie_driver.server.diagnostics import Entry
from crazyflie_driver.server.status import ERROR, OK, STALE, WARN, worker_status
from crazyflie_driver.server.worker import WorkerState


class _Reports:
    def __init__(self, entries: List[Entry]) -> None:
        self._entries = entries

    def entries(self) -> List[Entry]:
        return self._entries


class _Safety:
    def __init__(self, level: int = OK, message: str = "") -> None:
        self.level, self.message = level, message

    def report(self) -> Any:
        return self.level, self.message, (("safety_reaction", "none"),)


def worker(**changes: Any) -> Any:
    fields = dict(state=WorkerState.RUNNING, emergency_active=False, last_unexpected_error="", watchdog=None,
                  log_late=False, restarts=0, uri="radio://0/80/2M/E7E7E7E701", setpoints_sent=7,
                  keepalives_sent=3, listener_errors=0, topic_timing={}, safety=_Safety(),
                  reports=_Reports([]))
    fields.update(changes)
    w = SimpleNamespace(**fields)
    w.link_quality = lambda: (0.95, 10)
    w.lost_log_packets = lambda: 4
    return w


@pytest.mark.parametrize("changes, level, words", [
    (dict(state=WorkerState.FAILED), ERROR, "worker gave up: connect failed"),
    (dict(state=WorkerState.FAILED, last_unexpected_error="boom"), ERROR, "worker gave up: boom"),
    (dict(state=WorkerState.RESTARTING, last_unexpected_error="boom"), ERROR, "restarting after: boom"),
    (dict(state=WorkerState.LOST), ERROR, "link lost: retrying"),
    (dict(state=WorkerState.CONNECTING), STALE, "connecting"),
    (dict(state=WorkerState.STOPPED), STALE, "stopped"),
    (dict(log_late=True), WARN, "log data arrives late (4 log packets"),
    (dict(restarts=2, last_unexpected_error="boom"), WARN, "restarted 2 time(s), last after: boom"),
    (dict(watchdog=SimpleNamespace(message="watchdog", locked_until_restart=True), log_late=True), ERROR,
     "motors stopped: watchdog"),
    (dict(watchdog=SimpleNamespace(message="", locked_until_restart=True), log_late=True), WARN, "arrives late"),
    (dict(), OK, "running"),
])
def test_the_first_condition_that_holds_sets_the_level_and_message(changes, level, words):
    status = worker_status(worker(**changes))
    assert status.level == level
    assert words in status.message


def test_an_emergency_outranks_every_state_but_a_failed_worker():
    assert "emergency" in worker_status(worker(state=WorkerState.LOST, emergency_active=True)).message
    assert "gave up" in worker_status(worker(state=WorkerState.FAILED, emergency_active=True)).message


def test_safety_replaces_a_milder_message_and_reports_are_added():
    w = worker(restarts=1, safety=_Safety(ERROR, "safety landing: silence"),
               reports=_Reports([Entry("estimator", WARN, "variance high", (("var", "0.2"),))]))
    status = worker_status(w)
    assert status.level == ERROR
    assert status.message == "safety landing: silence; estimator: variance high"
    values = dict(status.values)
    assert values["link_quality"] == "0.950" and values["estimator: var"] == "0.2"
    assert values["safety_reaction"] == "none"


def test_topic_timing_values_by_topic_name():
    timing = {"pose": SimpleNamespace(age=0.01, rate=100.0, lost=0),
              "cmd_vel": SimpleNamespace(age=0.5, rate=2.0, lost=3)}
    names = [k for k, _ in worker_status(worker(topic_timing=timing)).values]
    assert names[-6:] == ["cmd_vel age_s", "cmd_vel rate_hz", "cmd_vel lost", "pose age_s", "pose rate_hz",
                          "pose lost"]
