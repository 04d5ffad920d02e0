"""Diagnostics: figures -> OK/WARN/ERROR (pure), the recorders, and a served Crazyflie's link figures
under injected packet loss on the real radio path."""
from __future__ import annotations

import time

import pytest

from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.server import diagnostic_thresholds as T
from crazyflie_driver.server.diagnostics import (
    ABOVE,
    BELOW,
    ERROR,
    OK,
    STALE,
    WARN,
    BottleneckFigures,
    CounterWindow,
    CrazyflieDiagnostics,
    CrazyflieHealth,
    LinkFigures,
    RadioFigures,
    Reports,
    ack_ratio_tolerance,
    battery_entry,
    bottleneck_entry,
    commands_entry,
    graded,
    link_entry,
    radio_entry,
    supervisor_entry,
    world_speed_share,
    worst,
)
from crazyflie_driver.server.status import worker_status
from crazyflie_driver.server.worker import CrazyflieWorker, WorkerConfig
from support.radio_rig import RadioRig


def figures(round_trips=200, acked=200, busy_s=0.2, log=100, lost=0, state="running", span=2.0):
    return LinkFigures(span, round_trips, acked, 0, busy_s, 0, log, lost, 40.0, state)


def test_worst_orders_levels():
    assert worst([]) == OK
    assert worst([OK, STALE]) == STALE
    assert worst([STALE, WARN]) == WARN
    assert worst([WARN, ERROR, OK]) == ERROR


@pytest.mark.parametrize("value, direction, level, why", [
    (0.95, BELOW, OK, ""), (0.9, BELOW, OK, ""), (0.89, BELOW, WARN, "0.89 < 0.90"),
    (0.5, BELOW, WARN, "0.50 < 0.90"), (0.49, BELOW, ERROR, "0.49 < 0.50"), (2.0, BELOW, OK, ""),
    (10.0, ABOVE, OK, ""), (10.5, ABOVE, WARN, "10.50 > 10.00"), (50.0, ABOVE, WARN, "50.00 > 10.00"),
    (50.1, ABOVE, ERROR, "50.10 > 50.00"), (-1.0, ABOVE, OK, ""),
])
def test_graded_follows_the_direction_and_leaves_a_threshold_itself_alone(value, direction, level, why):
    warn, error = (0.9, 0.5) if direction == BELOW else (10.0, 50.0)
    sign = "<" if direction == BELOW else ">"
    assert graded(value, warn, error, "%(value).2f " + sign + " %(limit).2f", direction) == (level, why)


def test_graded_takes_a_reason_per_level_and_refuses_an_unknown_direction():
    reasons = ("%(value).1f V low", "%(value).1f V critical")
    assert graded(3.1, 3.2, 3.0, reasons) == (WARN, "3.1 V low")
    assert graded(2.9, 3.2, 3.0, reasons) == (ERROR, "2.9 V critical")
    with pytest.raises(ValueError):
        graded(1.0, 2.0, 3.0, "%(value)s", "sideways")


@pytest.mark.parametrize("acked, level", [(200, OK), (180, OK), (179, WARN), (100, WARN), (99, ERROR), (0, ERROR)])
def test_link_ack_ratio_levels(acked, level):
    e = link_entry(figures(acked=acked, busy_s=0.2))
    assert e.level == level, e.message
    assert dict(e.values)["ack ratio"] == "%.3f" % (acked / 200)
    if level != OK:
        assert "ack ratio %.2f" % (acked / 200) in e.message


def test_link_needs_enough_round_trips_for_a_verdict():
    e = link_entry(figures(round_trips=T.MIN_ROUND_TRIPS - 1, acked=0, busy_s=0.001))
    assert e.level == OK
    assert link_entry(figures(round_trips=T.MIN_ROUND_TRIPS, acked=0, busy_s=0.001)).level == ERROR


@pytest.mark.parametrize("busy_s, level", [(2.0, OK), (2.2, WARN), (10.2, ERROR)])
def test_link_round_trip_time_levels(busy_s, level):
    e = link_entry(figures(busy_s=busy_s))     # 200 round trips
    assert e.level == level
    assert dict(e.values)["mean round trip [ms]"] == "%.2f" % (busy_s / 200 * 1e3)


@pytest.mark.parametrize("log, lost, level", [(90, 10, OK), (89, 11, WARN), (49, 51, ERROR), (5, 4, OK)])
def test_link_log_receive_ratio_levels(log, lost, level):
    assert link_entry(figures(log=log, lost=lost)).level == level


def test_link_lost_is_an_error_and_rates_are_per_second():
    e = link_entry(figures(state="lost", round_trips=10, acked=0, busy_s=0.03))
    assert e.level == ERROR and "link lost" in e.message
    v = dict(link_entry(figures(round_trips=300, acked=300, busy_s=0.3, span=1.5)).values)
    assert v["round trips/s"] == "200.0"
    assert v["log packets/s"] == "66.7"


def test_ack_ratio_tolerance_shrinks_with_the_sample():
    assert ack_ratio_tolerance(0.7, 100) == pytest.approx(4 * (0.21 / 100) ** 0.5)
    assert ack_ratio_tolerance(0.7, 400) == pytest.approx(ack_ratio_tolerance(0.7, 100) / 2)
    assert ack_ratio_tolerance(1.0, 100) > 0        # never zero: one packet in the sample is 1/n


@pytest.mark.parametrize("vbat, state, age, level, words", [
    (3.9, 0, 0.1, OK, "3.90 V, 0 (battery)"),
    (3.15, 0, 0.1, WARN, "3.15 V < 3.2 V (low)"),
    (2.95, 0, 0.1, ERROR, "critical"),
    (3.5, 3, 0.1, WARN, "low power"),
    (3.5, 4, 0.1, ERROR, "shutdown"),
    (3.9, 0, 1.5, WARN, "1.5 s old"),
])
def test_battery_levels(vbat, state, age, level, words):
    e = battery_entry(vbat, state, age)
    assert e.level == level
    assert words in e.message


def test_battery_without_samples():
    assert battery_entry(None, None, None).level == STALE
    assert battery_entry(None, None, None, logging_on=False).message == "n/a (logging off)"


def test_supervisor_entry():
    assert supervisor_entry(None, None, False).message == "n/a (this firmware has no supervisor state)"
    assert supervisor_entry(None, None, True).level == STALE
    ok = supervisor_entry(0b1_1001, 0.01, True)          # can_arm, can_fly, flying
    assert ok.level == OK and ok.message == "can_arm, can_fly, flying"
    assert supervisor_entry(1 << 6, 0.01, True).level == ERROR          # locked
    assert supervisor_entry(1 << 5, 0.01, True).level == WARN           # tumbled


def test_commands_entry():
    assert commands_entry(None, None, 0).message == "last setpoint never s ago, last pose never s ago"
    e = commands_entry(0.02, 0.01, 30)
    assert e.level == OK and dict(e.values)["poses sent"] == "30"
    e = commands_entry(0.02, 0.8, 30)
    assert e.level == WARN and "no pose sent for 0.8 s" in e.message


def test_radio_entry_levels():
    base = dict(index=0, span_s=2.0, broadcasts=0, crazyflies=("cf1", "cf2"), capacity_per_s=435.0)
    e = radio_entry(RadioFigures(round_trips_per_s=200.0, **base))
    assert e.level == OK and e.part == "radio 0"
    assert e.message == "200 round trips/s + 0 broadcasts/s of 435/s (46 %), 2 Crazyflie(s)"
    e = radio_entry(RadioFigures(round_trips_per_s=400.0, **base))
    assert e.level == WARN and "in use 92 %" in e.message
    e = radio_entry(RadioFigures(round_trips_per_s=100.0, planned_load=1.2, advice="log less", **base))
    assert e.level == ERROR and e.message.endswith(": log less")


def test_reports_board():
    r = Reports()
    r.set("battery reaction", WARN, "landing", (("vbat [V]", 3.1),))
    r.set("alpha", OK, "fine")
    assert [e.part for e in r.entries()] == ["alpha", "battery reaction"]
    assert r.entries()[1].values == (("vbat [V]", "3.1"),)
    r.clear("alpha")
    r.clear("never set")
    assert [e.part for e in r.entries()] == ["battery reaction"]
    with pytest.raises(ValueError):
        r.set("x", 7, "no such level")


def test_counter_window_keeps_about_its_span():
    w = CounterWindow(2.0)
    assert w.update(0.0, {"n": 0}) == (0.0, {"n": 0})
    assert w.update(1.0, {"n": 10}) == (1.0, {"n": 10})
    assert w.update(2.0, {"n": 30}) == (2.0, {"n": 30})
    assert w.update(3.0, {"n": 60}) == (2.0, {"n": 50})
    assert w.update(3.5, {"n": 70}) == (2.5, {"n": 60})      # the oldest snapshot at least 2 s old


def test_health_recorder():
    t = [10.0]
    h = CrazyflieHealth(lambda: t[0])
    h.on_log("battery", [3.7], 10.0)
    h.on_log("power_state", [3.0], 10.0)
    h.on_log("supervisor", [24.0], 10.0)
    h.on_log("imu", [0.0] * 6, 10.0)
    h.setpoint_given()
    t[0] = 10.5
    h.pose_sent()
    assert (h.vbat, h.pm_state, h.supervisor_bits) == (3.7, 3, 24)
    assert (h.setpoint_at, h.pose_at, h.poses) == (10.0, 10.5, 1)


def wait_for(cond, timeout=20.0):
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "condition not met in %.0f s" % timeout
        time.sleep(0.01)


@pytest.mark.parametrize("loss", [30.0, 80.0])
def test_served_crazyflie_link_figures_follow_injected_loss(loss):
    """The real radio path (fake dongle, no modelled delay) with packet loss on the dongle: the ack
    ratio the link entry shows is 1 - loss within 4 binomial sigmas of its sample; the level follows."""
    rig = RadioRig()
    cf = Crazyflie(rig.uri, radio_manager=rig.manager, timeout=1.0)
    worker = CrazyflieWorker(WorkerConfig(str(rig.uri), "cf1", enable_logging=False, enable_parameters=False), cf,
                             keepalive_period=0.002)
    worker.start()
    try:
        worker.wait_ready(10.0)
        diag = CrazyflieDiagnostics(window_s=0.5)
        diag.entries(worker)
        rig.medium.set_dongle_faults(0, packet_loss=loss)
        diag.window.reset()
        diag.entries(worker)
        stats = cf.link.stats
        start = stats.sent
        wait_for(lambda: stats.sent - start >= 300)
        link = diag.entries(worker)[0]
        f = diag.link
        assert f.round_trips >= 300
        expected = 1.0 - loss / 100.0
        assert abs(f.ack_ratio - expected) <= ack_ratio_tolerance(expected, f.round_trips), (f, expected)
        assert link.level == (WARN if loss == 30.0 else ERROR), link.message
        assert "ack ratio %.2f" % f.ack_ratio in link.message
        rig.medium.set_dongle_faults(0, packet_loss=0.0)
        diag.window.reset()
        diag.entries(worker)
        start = stats.sent
        wait_for(lambda: stats.sent - start >= 100)
        assert diag.entries(worker)[0].level == OK
        assert diag.link.ack_ratio == 1.0
    finally:
        worker.stop()


def test_reports_raise_the_status_topic():
    rig = RadioRig()
    cf = Crazyflie(rig.uri, radio_manager=rig.manager, timeout=1.0)
    worker = CrazyflieWorker(WorkerConfig(str(rig.uri), "cf1", enable_logging=False, enable_parameters=False), cf)
    worker.start()
    try:
        worker.wait_ready(10.0)
        assert worker_status(worker).level == OK
        worker.reports.set("battery reaction", ERROR, "3.0 V: landing", (("vbat [V]", "3.00"),))
        st = worker_status(worker)
        assert st.level == ERROR
        assert st.message == "running; battery reaction: 3.0 V: landing"
        assert ("battery reaction: vbat [V]", "3.00") in st.values
        parts = [e.part for e in CrazyflieDiagnostics().entries(worker)]
        assert parts == ["link", "battery", "supervisor", "commands", "battery reaction"]
        worker.reports.clear("battery reaction")
        assert worker_status(worker).level == OK
    finally:
        worker.stop()


def test_the_bottleneck_is_the_one_seen_not_assumed_to_be_the_radio():
    """The swarm run that blamed the radios: a world at 0.52 of real time with radios 29-38 % loaded. The
    world is named, with the radios' figures; a host whose timers wake late is named next; a radio only
    when it is near its capacity; none when nothing is."""
    radios = ((0, 0.29), (1, 0.38), (2, 0.33))
    world = bottleneck_entry(BottleneckFigures(0.52, 0.004, radios))
    assert world.level == WARN and world.message.startswith("the simulated world: it runs at 0.52 of its speed")
    assert "radio load 0: 29 %, 1: 38 %, 2: 33 %" in world.message and "radio 1:" not in world.message
    host = bottleneck_entry(BottleneckFigures(1.0, 0.2, radios))
    assert host.level == WARN and host.message.startswith("the host's CPU: crazyflie_server's timers wake 200 ms late")
    radio = bottleneck_entry(BottleneckFigures(None, 0.004, ((0, 0.29), (1, 0.93))))
    assert radio.level == WARN and radio.message.startswith("radio 1: in use 93 % of its capacity")
    assert "no simulated world figures" in radio.message
    none = bottleneck_entry(BottleneckFigures(0.99, 0.004, radios))
    assert none.level == OK and none.message.startswith("none seen")
    assert ("radio 1 load", "0.38") in none.values
    assert bottleneck_entry(BottleneckFigures()).level == OK


def test_the_worlds_speed_share_comes_from_its_diagnostics_values():
    assert world_speed_share({"real-time factor": "0.520", "speed": "1.000"}) == pytest.approx(0.52)
    assert world_speed_share({"real-time factor": "1.0", "speed": "2.0"}) == pytest.approx(0.5)
    assert world_speed_share({"real-time factor": "40.0", "speed": "0.000"}) is None     # as fast as it can
    assert world_speed_share({"speed": "1.0"}) is None and world_speed_share({"real-time factor": "x",
                                                                            "speed": "1"}) is None


def test_with_the_sensor_topics_off_a_battery_watch_still_feeds_the_safety_monitor():
    """Swarm mode's workers log no sensor topic; ``battery_watch_ms`` logs pm.vbat alone for the battery
    reaction (one block, that period), and nothing else (its samples reaching the reaction: the swarm
    rows of bench/bench_faults_swarm.py)."""
    rig = RadioRig()
    cf = Crazyflie(rig.uri, radio_manager=rig.manager, timeout=1.0)
    worker = CrazyflieWorker(WorkerConfig(str(rig.uri), "cf1", enable_logging=False, enable_parameters=False,
                                          battery_watch_ms=100), cf)
    worker.start()
    try:
        worker.wait_ready(10.0)
        assert [(b.period_ms, [t[0] for t in b.topics]) for b in worker._log_plan] == [(100, ["battery"])]
        assert worker.log_topics == ["battery"]          # its block was created on the Crazyflie
    finally:
        worker.stop()
    switched = CrazyflieWorker(WorkerConfig(str(rig.uri), "cf1", enable_logging=True, enable_parameters=False,
                                            battery_watch_ms=100, disabled_topics=frozenset({"battery", "imu"})),
                               Crazyflie(rig.uri, radio_manager=rig.manager, timeout=1.0))
    switched.start()      # the battery topic switched off: the watch still logs it, alone in its block
    try:
        switched.wait_ready(10.0)
        topics = [[t[0] for t in b.topics] for b in switched._log_plan]
        assert ["battery"] in topics and not any("imu" in t for t in topics)
        assert sum(t.count("battery") for t in topics) == 1
    finally:
        switched.stop()
    plain = CrazyflieWorker(WorkerConfig(str(rig.uri), "cf1", enable_logging=False, enable_parameters=False),
                            Crazyflie(rig.uri, radio_manager=rig.manager, timeout=1.0))
    plain.start()
    try:
        plain.wait_ready(10.0)
        assert plain._log_plan == []
    finally:
        plain.stop()
