#!/usr/bin/env python3
"""customLogBlocks.launch sim:=true: the custom log topics arrive at their periods with sane values.

The launch file asks for ``log1`` = [pm.vbat] every 10 ms and ``log2`` = [acc.x, acc.y, acc.z]
every 100 ms (genericLogTopicFrequencies holds periods in ms). Checked here, with the Crazyflie
resting on the ground:
- rates per second of WORLD time (the firmware's log timers run on world time, which may fall
  behind the wall clock on a busy machine), counted by the messages' ``onboard_timestamp`` (the
  Crazyflie's own clock), so none may be lost, and their spacing, which must be the period
  whatever the host's load;
- log1's single value is a plausible LiPo voltage and agrees with the world's true battery;
- log2's three values are in g, in the requested order: about (0, 0, 1) at rest.

Private params: ``sim_address``, ``measure_s`` (seconds of world time to count over, 4).
"""
from __future__ import annotations

import statistics
import sys
import threading
import time
import unittest
from typing import Any, Dict, List, Tuple

import rospy
import rostest

from crazyflie_driver.msg import GenericLogData
from support.flight_support import WorldProbe, wait_until

NAME = "crazyflie"
PERIOD_MS = {"log1": 10, "log2": 100}         # as customLogBlocks.launch asks
TIMESTAMP_WRAP = 1 << 24                       # the log packet carries a 24-bit ms timestamp


class Recorder:
    """Every message of one topic with its monotonic arrival time."""

    def __init__(self, topic: str) -> None:
        self.lock = threading.Lock()
        self.rows: List[Tuple[float, Any]] = []
        self.sub = rospy.Subscriber(topic, GenericLogData, self.on_msg, queue_size=1000)

    def on_msg(self, msg: GenericLogData) -> None:
        with self.lock:
            self.rows.append((time.monotonic(), msg))

    def between(self, t0: float, t1: float) -> List[Any]:
        with self.lock:
            return [m for t, m in self.rows if t0 <= t < t1]

    def count(self) -> int:
        with self.lock:
            return len(self.rows)

    def onboard_window(self, t0: float, span_ms: int) -> List[Any]:
        """The messages the Crazyflie timestamped in ``span_ms`` from the first one to arrive after wall
        time ``t0``: counted by its clock, so the host's delivery latency cannot move the window's edges.
        Waits (up to 10 s) for a message stamped past the window's end."""
        def first_after():
            with self.lock:
                return next((m for t, m in self.rows if t >= t0), None)
        if not wait_until(lambda: first_after() is not None, 10.0):
            return []
        ts0 = first_after().onboard_timestamp

        def offset(m) -> int:
            return (m.onboard_timestamp - ts0) % TIMESTAMP_WRAP

        def past_end() -> bool:
            with self.lock:
                return any(t >= t0 and span_ms <= offset(m) < TIMESTAMP_WRAP // 2 for t, m in self.rows)
        wait_until(past_end, 10.0)
        with self.lock:
            return [m for t, m in self.rows if offset(m) < span_ms]


def spacings_ms(msgs: List[Any]) -> List[int]:
    """Differences of consecutive onboard timestamps, modulo the 24-bit wrap."""
    ts = [m.onboard_timestamp for m in msgs]
    return [(b - a) % TIMESTAMP_WRAP for a, b in zip(ts, ts[1:])]


class CustomLogBlocks(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("custom_log_blocks_test")
        cls.probe = WorldProbe(rospy.get_param("~sim_address"))
        cls.probe.wait_ready([NAME])
        cls.measure_s = float(rospy.get_param("~measure_s", 4.0))
        cls.rec = {name: Recorder("/%s/%s" % (NAME, name)) for name in PERIOD_MS}
        if not wait_until(lambda: all(r.count() >= 2 for r in cls.rec.values()), 30.0):
            raise AssertionError("custom log topics silent after 30 s: %s"
                                 % {n: r.count() for n, r in cls.rec.items()})
        # one measurement window shared by the tests: (wall t0, t1), world seconds elapsed
        w0, t0 = cls.probe.clock.now(), time.monotonic()
        w1 = cls.probe.clock.wait_until(lambda: False, cls.measure_s, start=w0)[1]
        t1 = time.monotonic()
        cls.window = (t0, t1)
        cls.world_s = max(w1 - w0, 1e-3)
        cls.msgs: Dict[str, List[Any]] = {n: r.between(t0, t1) for n, r in cls.rec.items()}
        cls.state = cls.probe.state(NAME)

    def test_a_rates_per_world_second(self):
        span_s = self.measure_s
        for name, period in PERIOD_MS.items():
            # counted by the Crazyflie's own clock (world time): messages it stamped within span_s
            n = len(self.rec[name].onboard_window(self.window[0], int(span_s * 1000)))
            rate, expected = n / span_s, 1000.0 / period
            print("LOG %s: %d messages stamped in %.2f onboard s: %.1f /s (expected %.0f); %d arrived in the "
                  "%.2f world-s window" % (name, n, span_s, rate, expected, len(self.msgs[name]), self.world_s))
            # one message either side of the window, plus 5 %
            tolerance = 1.0 / span_s + 0.05 * expected
            self.assertAlmostEqual(rate, expected, delta=tolerance, msg=name)

    def test_b_onboard_timestamps_step_by_the_period(self):
        for name, period in PERIOD_MS.items():
            gaps = spacings_ms(self.msgs[name])
            self.assertGreater(len(gaps), 10 if period <= 10 else 3, name)
            median = statistics.median(gaps)
            on_period = sum(1 for g in gaps if abs(g - period) <= 1) / len(gaps)
            print("LOG %s: onboard_timestamp spacing median %.1f ms, min %d, max %d, %.0f %% within 1 ms of %d"
                  % (name, median, min(gaps), max(gaps), 100 * on_period, period))
            self.assertAlmostEqual(median, period, delta=1, msg=name)
            self.assertGreaterEqual(on_period, 0.95, "%s: spacings %s" % (name, gaps))
            self.assertTrue(all(g > 0 for g in gaps), "%s: timestamps must increase" % name)

    def test_c_log1_is_the_battery_voltage(self):
        values = [m.values for m in self.msgs["log1"]]
        self.assertTrue(all(len(v) == 1 for v in values), "log1 carries pm.vbat only")
        vbat = [v[0] for v in values]
        print("LOG log1 pm.vbat: %.3f..%.3f V, world's battery %.3f V" % (min(vbat), max(vbat), self.state["vbat"]))
        for v in vbat:
            self.assertTrue(3.0 <= v <= 4.3, "pm.vbat %.3f V is not a LiPo voltage" % v)
        self.assertAlmostEqual(statistics.mean(vbat), self.state["vbat"], delta=0.05)

    def test_d_log2_is_acceleration_in_g_at_rest(self):
        self.assertTrue(self.state["on_ground"])
        values = [m.values for m in self.msgs["log2"]]
        self.assertTrue(all(len(v) == 3 for v in values), "log2 carries acc.x, acc.y, acc.z")
        mean = [statistics.mean(v[k] for v in values) for k in range(3)]
        print("LOG log2 mean acc at rest: x %.3f y %.3f z %.3f g" % tuple(mean))
        self.assertLess(abs(mean[0]), 0.05, "acc.x at rest")
        self.assertLess(abs(mean[1]), 0.05, "acc.y at rest")
        self.assertAlmostEqual(mean[2], 1.0, delta=0.05, msg="acc.z at rest is 1 g (not m/s²)")
        for v in values:
            self.assertAlmostEqual(v[2], 1.0, delta=0.1)


if __name__ == "__main__":
    rostest.rosrun("crazyflie_demo", "custom_log_blocks", CustomLogBlocks, sys.argv)
