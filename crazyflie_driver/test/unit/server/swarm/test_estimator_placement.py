"""A swarm takeoff waits for the estimators it needs placed, and names those that never were."""
from __future__ import annotations

import threading
import time

from crazyflie_driver.server.swarm.estimator_placement import EstimatorPlacement, refusal


def test_missing_names_those_not_placed_in_their_order():
    p = EstimatorPlacement()
    p.placed("cf2")
    assert p.is_placed("cf2") and not p.is_placed("cf1")
    assert p.missing(["cf3", "cf2", "cf1"], wait_s=0.0) == ["cf3", "cf1"]
    assert p.missing([], wait_s=0.0) == []


def test_missing_returns_as_soon_as_the_last_one_is_placed():
    p = EstimatorPlacement()
    p.placed("cf1")
    placer = threading.Timer(0.05, p.placed, args=("cf2",))
    placer.start()
    t0 = time.monotonic()
    assert p.missing(["cf1", "cf2"], wait_s=30.0) == []
    assert time.monotonic() - t0 < 29.0         # woken by the placement, not by the time limit
    placer.join()


def test_missing_gives_up_after_its_wait():
    p = EstimatorPlacement()
    t0 = time.monotonic()
    assert p.missing(["cf1"], wait_s=0.05) == ["cf1"]
    assert time.monotonic() - t0 >= 0.05


def test_refusal_names_them_and_says_what_to_check():
    text = refusal(["cf2", "cf3"], 5.0)
    assert text.startswith("cf2, cf3: no first motion-capture pose")
    assert "within 5 s" in text and "~mocap_pattern" in text and "nothing was sent" in text
