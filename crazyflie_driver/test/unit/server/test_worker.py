"""CrazyflieWorker with a fake Crazyflie: what goes on the wire, when, and what the listener hears."""
from __future__ import annotations

import threading
import time

import pytest

from crazyflie_driver.errors import LogConfigError, RadioNotFound, UnknownName
from crazyflie_driver.server.log_plan import LogBlockSpec
from crazyflie_driver.server.setpoint import Setpoint
from crazyflie_driver.server.worker import MAX_RESTARTS, CrazyflieWorker, WorkerConfig, WorkerState
from support.worker_doubles import LOG_VARS, FakeCrazyflie, Recorder, started, wait_for


def test_connect_sequence_order_blocks_and_params():
    cfg = WorkerConfig(uri="radio://0/80/2M/E7E7E7E701", tf_prefix="cf1",
                       log_blocks=(LogBlockSpec("attitude", 50, ("stabilizer.roll", "stabilizer.pitch")),))
    w, cf, rec = started(config=cfg)
    try:
        order = [c for c in cf.calls if c != "log.create_block"]
        assert order == ["connect", "log.reset", "params.fetch_toc", "params.read_all", "log.fetch_toc"]
        assert rec.params["ring.headlightEnable"] == 0
        periods = sorted((b.period_ms, tuple(b.variables)) for b in cf.log.blocks)
        imu = [b for b in cf.log.blocks if b.period_ms == 10]
        assert [b.variables for b in imu] == [["acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z"]]
        slow = [v for b in cf.log.blocks if b.period_ms == 100 for v in b.variables]
        assert sorted(slow) == sorted(["baro.temp", "mag.x", "mag.y", "mag.z", "baro.pressure",
                                       "pm.vbat", "radio.rssi"])
        assert all(sum(1 if LOG_VARS[v] == "uint8_t" else 4 for v in b.variables) <= 26
                   for b in cf.log.blocks)
        assert (50, ("stabilizer.roll", "stabilizer.pitch")) in periods
        # thrust lock released with a zero setpoint before anything else is sent
        assert cf.packets[0][1:] == ("setpoint", (0.0, 0.0, 0.0, 0))
        # log packets are split back into topics
        battery_block = next(b for b in cf.log.blocks if "pm.vbat" in b.variables)
        vals = [float(i) for i in range(len(battery_block.variables))]
        battery_block.deliver(1234, vals)
        got = {t: v for t, ts, v in rec.logs}
        assert got["battery"] == [float(battery_block.variables.index("pm.vbat"))]
        if "radio.rssi" in battery_block.variables:
            assert rec.rssi == [float(battery_block.variables.index("radio.rssi"))]
        imu[0].deliver(77, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
        assert ("imu", 77, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]) in rec.logs
    finally:
        w.stop()


def test_radio_not_there_yet_is_retried_but_not_forever():
    cf = FakeCrazyflie()
    cf.radio_missing_for = 2
    w, cf, _ = started(cf=cf)
    assert cf.calls.count("connect") == 3 and w.state == WorkerState.RUNNING
    w.stop()
    cf = FakeCrazyflie()
    cf.radio_missing_for = 100
    w = CrazyflieWorker(WorkerConfig(uri=cf.uri), cf, Recorder(), device_retry_window=0.6)
    w.start()
    with pytest.raises(RadioNotFound):
        w.wait_ready(3.0)


def test_missing_sensor_skips_its_topic_only():
    cf = FakeCrazyflie()
    for v in ("mag.x", "mag.y", "mag.z"):
        del cf.log_vars[v]
    w, cf, rec = started(cf=cf)
    try:
        assert w.missing_fixed_topics == ["magnetic_field"]
        assert "battery" in w.log_topics and "imu" in w.log_topics
    finally:
        w.stop()


def test_switched_off_imu_asks_the_firmware_for_no_imu_block():
    on, cf_on, _ = started(config=WorkerConfig(uri="radio://0/80/2M/E7E7E7E701"))
    off, cf_off, _ = started(config=WorkerConfig(uri="radio://0/80/2M/E7E7E7E701",
                                                 disabled_topics=frozenset({"imu"})))
    try:
        imu_vars = {"acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z"}
        assert all(not imu_vars & set(b.variables) for b in cf_off.log.blocks)
        assert any(imu_vars <= set(b.variables) for b in cf_on.log.blocks)
        assert "imu" not in off.log_topics and "battery" in off.log_topics
        # the 10 ms block (imu, with supervisor.info riding along) is gone: 100 packets/s fewer
        assert on.log_packet_rate - off.log_packet_rate == pytest.approx(100.0)
    finally:
        on.stop()
        off.stop()


def test_unknown_custom_variable_fails_the_add_clearly():
    cfg = WorkerConfig(uri="radio://0/80/2M/E7E7E7E701",
                       log_blocks=(LogBlockSpec("x", 10, ("acc.x", "foo.bar")),))
    w = CrazyflieWorker(cfg, FakeCrazyflie(), Recorder())
    w.start()
    with pytest.raises(UnknownName, match="foo.bar"):
        w.wait_ready(2.0)
    assert w.state == WorkerState.FAILED


def test_too_many_log_blocks_fail_the_add_before_any_block_is_created():
    """14 custom topics fit next to the driver's 2 blocks; 15 do not: the add fails naming the
    limit and what uses it, and no block was sent."""
    custom = tuple(LogBlockSpec("t%d" % i, 100, ("pm.vbat",)) for i in range(15))
    cf = FakeCrazyflie()
    w = CrazyflieWorker(WorkerConfig(uri=cf.uri, tf_prefix="cf1", log_blocks=custom), cf, Recorder())
    w.start()
    with pytest.raises(LogConfigError, match="17 log blocks needed, the Crazyflie's firmware holds at most 16"):
        w.wait_ready(2.0)
    assert "log.create_block" not in cf.calls
    w, cf, _ = started(config=WorkerConfig(uri=cf.uri, tf_prefix="cf1", log_blocks=custom[:14]))
    try:
        assert len(cf.log.blocks) == 16
    finally:
        w.stop()


def test_queued_log_data_is_drained_without_waiting_for_the_keepalive_period():
    w, cf, rec = started(keepalive_period=0.05)
    try:
        time.sleep(0.06)
        battery = next(b for b in cf.log.blocks if "pm.vbat" in b.variables)
        t0 = time.monotonic()
        cf.downlink.extend((battery, i, [3.7] * len(battery.variables)) for i in range(6))
        assert wait_for(lambda: len([entry for entry in rec.logs if entry[0] == "battery"]) == 6, 1.0)
        assert time.monotonic() - t0 < 0.1      # not 6 x 50 ms
    finally:
        w.stop()


def test_setpoint_sent_at_once_and_only_latest_counts():
    w, cf, _ = started(keepalive_period=0.5)   # no keep-alive can hide a slow wake-up
    try:
        time.sleep(0.05)
        t0 = time.monotonic()
        w.cmd_vel(1.0, 2.0, 30000.0, 10.0)
        assert wait_for(lambda: len(cf.of_kind("setpoint")) >= 2)
        sp = cf.of_kind("setpoint")[-1]
        assert sp[0] - t0 < 0.01
        assert sp[2] == (2.0, -1.0, 10.0, 30000)
        # a burst while the thread is busy: only the last one goes out
        with w._send_lock:
            for i in range(5):
                w.cmd_vel(0.0, 0.0, 1000.0 * i, 0.0)
        assert wait_for(lambda: len(cf.of_kind("setpoint")) >= 3)
        time.sleep(0.05)
        sps = cf.of_kind("setpoint")
        assert len(sps) == 3 and sps[-1][2][3] == 4000
    finally:
        w.stop()


def test_emergency_is_immediate_idempotent_and_final():
    w, cf, _ = started()
    try:
        w.cmd_vel(0.0, 0.0, 40000.0, 0.0)
        assert wait_for(lambda: any(p[2][3] == 40000 for p in cf.of_kind("setpoint")))
        w.emergency()
        n_estop = len(cf.of_kind("estop"))
        assert n_estop == 1
        t_estop = cf.of_kind("estop")[0][0]
        w.emergency()
        assert w.emergency_active
        assert w.cmd_vel(0.0, 0.0, 50000.0, 0.0) is False
        time.sleep(0.1)
        after = [p for p in cf.packets if p[0] > t_estop]
        assert after, "zero-thrust setpoints keep going after the e-stop"
        assert all(p[1] in ("setpoint", "estop") for p in after)
        assert all(p[2] == (0.0, 0.0, 0.0, 0) for p in after if p[1] == "setpoint")
        assert not any(p[1] == "null" for p in after)
    finally:
        w.stop()


def test_emergency_from_many_threads_never_lets_a_setpoint_through():
    w, cf, _ = started()
    try:
        stop = threading.Event()

        def spam():
            while not stop.is_set():
                w.cmd_vel(0.0, 0.0, 45000.0, 0.0)

        spammer = threading.Thread(target=spam)
        spammer.start()
        time.sleep(0.05)
        threads = [threading.Thread(target=w.emergency) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        first = cf.of_kind("estop")[0][0]
        time.sleep(0.05)
        stop.set()
        spammer.join()
        assert not [p for p in cf.of_kind("setpoint") if p[0] > first and p[2][3] != 0]
    finally:
        w.stop()


def test_link_quality_warning_per_crazyflie():
    good, bad = FakeCrazyflie("radio://0/80/2M/E7E7E7E701"), FakeCrazyflie("radio://0/80/2M/E7E7E7E702")
    wg, _, rg = started(cf=good, config=WorkerConfig(uri=good.uri, tf_prefix="a"))
    wb, _, rb = started(cf=bad, config=WorkerConfig(uri=bad.uri, tf_prefix="b"), link_lost_timeout=10.0,
                        quality_warning_interval=10.0)
    try:
        bad.acking = False
        time.sleep(0.5)   # ~50 round trips, all unacked on the bad one
        assert rb.quality and rb.quality[0][1] is True and rb.quality[0][0] < 0.7
        assert rg.quality == []
        bad.acking = True
        assert wait_for(lambda: rb.quality[-1][1] is False, 2.0)
        assert rb.quality[-1][0] >= 0.8          # hysteresis: recovered means clearly above 0.7
        assert len(rb.quality) == 2              # one warning, one recovery: no flapping
    finally:
        wg.stop()
        wb.stop()


def test_lost_link_is_reported_retried_slowly_and_restored():
    w, cf, rec = started(link_lost_timeout=0.1, lost_retry_period=0.1)
    try:
        cf.acking = False
        assert wait_for(lambda: rec.lost, 1.0)
        assert w.state == WorkerState.LOST
        n0 = len(cf.packets)
        time.sleep(0.5)
        assert 3 <= len(cf.packets) - n0 <= 7            # ~every 0.1 s, not every 10 ms
        resets = cf.log.resets
        cf.acking = True
        assert wait_for(lambda: rec.restored == 1, 1.0)
        assert w.state == WorkerState.RUNNING
        assert cf.log.resets == resets + 1 and cf.log.blocks    # logging set up again
    finally:
        w.stop()


def test_unplugged_dongle_is_reported_without_killing_the_worker():
    w, cf, rec = started(lost_retry_period=0.05)
    try:
        cf.unplugged = True
        assert wait_for(lambda: rec.lost, 1.0)
        assert "unplugged" in rec.lost[0]
        cf.unplugged = False
        assert wait_for(lambda: rec.restored == 1, 1.0)
    finally:
        w.stop()


def test_rssi_from_acks_when_they_carry_it():
    cf = FakeCrazyflie()
    cf.link.stats.rssi = 42.0
    w, cf, rec = started(cf=cf)
    try:
        assert not any("radio.rssi" in b.variables for b in cf.log.blocks)
        assert wait_for(lambda: len(rec.rssi) >= 2, 1.0) and rec.rssi[0] == 42.0
    finally:
        w.stop()


def test_update_params_applies_known_and_reports_unknown():
    w, cf, _ = started()
    try:
        written, errors = w.update_params({"ring.headlightEnable": True, "nope.x": 1,
                                           "pid_rate.roll_kp": "300"})
        assert sorted(written) == ["pid_rate.roll_kp", "ring.headlightEnable"]
        assert cf.params.values["ring.headlightEnable"] == 1
        assert cf.params.values["pid_rate.roll_kp"] == 300.0
        assert len(errors) == 1 and "nope.x" in errors[0]
    finally:
        w.stop()


def test_unexpected_error_in_the_loop_is_logged_once_stops_setpoints_and_restarts(caplog):
    w, cf, rec = started()
    try:
        w.set_setpoint(Setpoint(1.0, 2.0, 3.0, 30000))
        assert wait_for(lambda: len(cf.of_kind("setpoint")) >= 2)
        cf.inject.append(OverflowError("int too large to convert"))
        w.set_setpoint(Setpoint(5.0, 5.0, 5.0, 40000))       # the one whose send fails
        assert wait_for(lambda: rec.worker_errors)
        failed_at = time.monotonic()
        message, gave_up = rec.worker_errors[0]
        assert not gave_up and "OverflowError" in message and cf.uri in message
        # the loop runs again: keep-alives flow, the failed setpoint is never replayed
        assert wait_for(lambda: w.state == WorkerState.RUNNING and
                        len([p for p in cf.of_kind("null") if p[0] > failed_at]) >= 5)
        assert all(p[2] != (5.0, 5.0, 5.0, 40000) for p in cf.of_kind("setpoint"))
        assert w.restarts == 1 and "OverflowError" in w.last_unexpected_error
        # and it still flies: the next setpoint goes out
        w.set_setpoint(Setpoint(0.0, 0.0, 0.0, 20000))
        assert wait_for(lambda: cf.of_kind("setpoint")[-1][2] == (0.0, 0.0, 0.0, 20000))
        # the same error again: logged, but the traceback only the first time
        cf.inject.append(OverflowError("int too large to convert"))
        w.set_setpoint(Setpoint(5.0, 5.0, 5.0, 40000))
        assert wait_for(lambda: len(rec.worker_errors) == 2 and w.state == WorkerState.RUNNING)
        records = [r for r in caplog.records if "worker loop failed" in r.getMessage()]
        assert len(records) == 2
        assert records[0].exc_info is not None and records[1].exc_info is None
        assert "2 times" in records[1].getMessage()
    finally:
        w.stop()
    assert cf.closed


def test_a_worker_that_keeps_failing_gives_up_and_closes_the_link():
    w, cf, rec = started()
    cf.inject.extend(RuntimeError("bug %d" % i) for i in range(MAX_RESTARTS + 1))
    assert wait_for(lambda: w.state == WorkerState.FAILED, 5.0)
    assert [g for _, g in rec.worker_errors] == [False] * MAX_RESTARTS + [True]
    assert "remove and add it again" in rec.worker_errors[-1][0]
    assert cf.closed
    n = len(cf.packets)
    time.sleep(0.1)
    assert len(cf.packets) == n         # nothing is sent once it gave up
    w.stop()
    assert w.state == WorkerState.FAILED


def test_a_failing_log_listener_does_not_stop_the_worker(caplog):
    class Failing(Recorder):
        def on_log(self, topic, ts, values):
            raise ValueError("cannot publish")
    w, cf, rec = started(listener=Failing())
    try:
        imu = next(b for b in cf.log.blocks if b.period_ms == 10)
        for i in range(3):
            cf.downlink.append((imu, i, [0.0] * 6))
        assert wait_for(lambda: w.listener_errors == 3)
        assert w.state == WorkerState.RUNNING and not rec.worker_errors
        assert len([r for r in caplog.records if "publishing imu failed" in r.getMessage()]) == 1
        n = len(cf.of_kind("null"))
        assert wait_for(lambda: len(cf.of_kind("null")) > n + 5)
    finally:
        w.stop()


def test_out_of_range_cmd_vel_is_held_and_non_finite_is_refused_keeping_the_last_setpoint():
    w, cf, _ = started(keepalive_period=0.5)
    try:
        w.cmd_vel(1e39, -1e30, 1e39, 1e39)          # finite but beyond float32: once killed the worker
        assert wait_for(lambda: len(cf.of_kind("setpoint")) >= 2)
        assert cf.of_kind("setpoint")[-1][2] == (-90.0, -90.0, 2000.0, 60000)
        w.cmd_vel(0.0, 1.0, 30000.0, 0.0)
        assert wait_for(lambda: cf.of_kind("setpoint")[-1][2] == (1.0, -0.0, 0.0, 30000))
        for bad in (float("nan"), float("inf"), float("-inf")):
            with pytest.raises(ValueError, match="angular.z"):
                w.cmd_vel(0.0, 5.0, 50000.0, bad)
        assert w._pending is None and w.state == WorkerState.RUNNING
        w.cmd_vel(0.0, 2.0, 31000.0, 0.0)                  # still flyable
        assert wait_for(lambda: cf.of_kind("setpoint")[-1][2] == (2.0, -0.0, 0.0, 31000))
    finally:
        w.stop()


def test_update_params_refuses_non_finite_and_out_of_range_values_without_writing_them():
    w, cf, _ = started()
    try:
        written, errors = w.update_params({"pid_rate.roll_kp": float("nan"), "ring.headlightEnable": 256,
                                           "flightmode.althold": float("inf")})
        assert written == [] and len(errors) == 3
        assert cf.params.values == {"ring.headlightEnable": 0, "pid_rate.roll_kp": 250.0, "flightmode.althold": 0}
        assert "pid_rate.roll_kp (float): nan is not a finite number" in " ".join(errors)
        assert "out of range 0..255" in " ".join(errors)
    finally:
        w.stop()


class StampRecorder(Recorder):
    def __init__(self):
        super().__init__()
        self.ages, self.late = [], []

    def on_log_stamped(self, topic, ts, values, age_s):
        self.ages.append((topic, age_s))
        super().on_log_stamped(topic, ts, values, age_s)

    def on_log_late(self, message, late):
        self.late.append((message, late))

    def late_cause(self):
        return "the simulated world: it runs at 0.52 of its speed"


def test_late_log_data_is_measured_from_onboard_stamps_and_said_once(caplog):
    rec = StampRecorder()
    w, cf, _ = started(listener=rec)
    try:
        imu = next(b for b in cf.log.blocks if b.period_ms == 10)
        t0 = time.monotonic()
        cf.downlink.append((imu, 5000, [0.0] * 6))    # on time: the reference
        assert wait_for(lambda: rec.ages)
        time.sleep(0.7)
        # queued behind others: sampled 90 and 100 ms later, fetched ~0.7 s later; the 8 packets
        # between the first two were lost (the transmit queue overflowed)
        cf.downlink.extend([(imu, 5090, [0.0] * 6), (imu, 5100, [0.0] * 6)])
        assert wait_for(lambda: len(rec.ages) == 3)
        late_age = time.monotonic() - t0 - 0.1
        assert rec.ages[-1][0] == "imu" and rec.ages[-1][1] == pytest.approx(late_age, abs=0.05)
        assert [late for _, late in rec.late] == [True]       # said once for both
        assert "late" in rec.late[0][0] and "8 log packets lost" in rec.late[0][0]
        # what limits the flow is the server's judgement (diagnostics.bottleneck_entry), never assumed
        assert rec.late[0][0].endswith("; bottleneck: the simulated world: it runs at 0.52 of its speed")
        assert w.topic_timing["imu"].lost == 8 and w.log_late
        # fresh data again (the queue drained): on time, said once
        cf.downlink.append((imu, int((time.monotonic() - t0) * 1000) + 5000, [0.0] * 6))
        assert wait_for(lambda: len(rec.late) == 2)
        assert [late for _, late in rec.late] == [True, False] and not w.log_late
        assert len([r for r in caplog.records if "arrives" in r.getMessage()]) == 1
    finally:
        w.stop()


def test_a_world_that_stops_is_a_lost_link_unless_the_server_is_exiting(caplog):
    """A simulated world stopped by the same Ctrl-C as the server goes first: expected, no error. A
    world that stops while the server runs stays an error."""
    from crazyflie_driver.errors import RadioMediumGone
    gone = RadioMediumGone("no simulated world at 127.0.0.1:1: Connection refused")
    w, cf, rec = started(link_lost_timeout=0.1, lost_retry_period=0.1)
    try:
        with caplog.at_level("INFO"):
            cf.inject = [gone] * 100000
            assert wait_for(lambda: rec.lost, 1.0)
        assert w.state == WorkerState.LOST
        assert any(r.levelname == "ERROR" and "link lost: no simulated world" in r.getMessage()
                   for r in caplog.records)
    finally:
        w.stop()
    caplog.clear()
    w, cf, rec = started(link_lost_timeout=0.1, lost_retry_period=0.1)
    try:
        with caplog.at_level("INFO"):
            w.server_exiting()
            cf.inject = [gone] * 100000
            assert wait_for(lambda: w.state == WorkerState.LOST, 1.0)
            time.sleep(0.3)                       # past link_lost_timeout: still no error
        assert rec.lost == [] and w.safe_to_close()
        assert [r.getMessage() for r in caplog.records if r.levelno >= 30] == []
        assert any("link closed: no simulated world" in r.getMessage() for r in caplog.records)
    finally:
        w.stop()
