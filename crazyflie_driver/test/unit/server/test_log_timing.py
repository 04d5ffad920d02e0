"""Onboard timestamps -> ages on arrival; lost packets from the timestamps; rates per onboard second."""
from __future__ import annotations

import pytest

from crazyflie_driver.server.log_timing import MAX_DRIFT, ONBOARD_CLOCK_WRAP_MS, OnboardClock, TopicTiming


def test_age_is_the_delay_beyond_the_quickest_packet():
    c = OnboardClock()
    assert c.age(c.onboard_seconds(1000), 50.002) == 0.0            # first packet: the reference
    assert c.age(c.onboard_seconds(1010), 50.012) == pytest.approx(0.0)
    assert c.age(c.onboard_seconds(1020), 50.522) == pytest.approx(0.5, abs=1e-3)   # queued for half a second
    # a quicker packet lowers the reference; later ages are measured from it
    assert c.age(c.onboard_seconds(1600), 50.601) == pytest.approx(0.0)
    assert c.age(c.onboard_seconds(1610), 50.612) == pytest.approx(0.001, abs=1e-4)


def test_a_queue_that_stays_full_cannot_hide_its_delay():
    c = OnboardClock()
    c.age(c.onboard_seconds(0), 0.0)
    ages = []
    for k in range(1, 6001):                 # 60 s, every packet 3 s late
        ages.append(c.age(c.onboard_seconds(k * 10), k * 0.01 + 3.0))
    assert ages[-1] == pytest.approx(3.0 - MAX_DRIFT * 63.0, abs=1e-3)
    assert min(ages) > 2.9


def test_drift_is_followed_and_the_clock_unwraps():
    c = OnboardClock()
    drift = 50e-6                            # host runs 50 ppm faster, packets always on time
    raw = ONBOARD_CLOCK_WRAP_MS - 5000
    ages = []
    for k in range(0, 20000):                # 200 s across the 24-bit wrap
        onboard_ms = (raw + k * 10) % ONBOARD_CLOCK_WRAP_MS
        ages.append(c.age(c.onboard_seconds(onboard_ms), 100.0 + k * 0.01 * (1 + drift)))
    assert max(ages) < 0.001


def test_a_restarted_crazyflie_starts_a_new_mapping():
    c = OnboardClock()
    c.age(c.onboard_seconds(600000), 10.0)
    assert c.age(c.onboard_seconds(100), 12.0) == 0.0


def test_topic_timing_counts_lost_packets_and_the_rate_of_arrivals():
    t = TopicTiming(10)
    stamps = list(range(0, 1000, 10)) + list(range(1050, 2000, 10))   # 5 packets missing: 1000..1040
    for k, ms in enumerate(stamps):
        t.record(ms / 1000.0, 0.2, 10.0 + k * 0.02)      # they arrive at 50 per second
    assert t.lost == 5 and t.count == 195 and t.age == 0.2
    assert t.rate == pytest.approx(50.0, rel=0.01)
