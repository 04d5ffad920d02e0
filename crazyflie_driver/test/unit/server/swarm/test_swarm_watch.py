"""Stale poses and lost links: named once, landed after the hold, never sent up again by the watch."""
from __future__ import annotations

import pytest

from crazyflie_driver.server.swarm.watch import LANDING, NO_POSE_YET, OK, STALE, SwarmWatch


def kinds(events):
    return [(e.name, e.kind) for e in events]


def test_stale_then_land_after_the_hold_while_the_others_stay_ok():
    w = SwarmWatch(["cf1", "cf2"], stale_after=0.1, hold=0.5)
    assert w.state("cf1", 0.0) == NO_POSE_YET and w.check(0.0) == []
    for t in (0.0, 0.01, 0.02):
        w.pose_seen("cf1", t)
        w.pose_seen("cf2", t)
    assert w.check(0.1) == []
    for k in range(1, 80):                       # cf2 keeps its poses at 100 Hz
        w.pose_seen("cf2", 0.02 + 0.01 * k)
        events = w.check(0.02 + 0.01 * k)
        if events:
            break
    assert kinds(events) == [("cf1", "stale")] and events[0].age == pytest.approx(0.11, abs=0.011)
    assert w.state("cf1", 0.2) == STALE and w.state("cf2", 0.2) == OK
    w.pose_seen("cf2", 0.6)
    assert w.check(0.6) == []                    # stale since 0.12: hold not over
    w.pose_seen("cf2", 0.63)
    events = w.check(0.63)
    assert kinds(events) == [("cf1", "land")] and "no pose for 0.61 s" in events[0].reason
    w.pose_seen("cf2", 0.7)
    assert w.check(0.7) == [] and w.state("cf1", 0.7) == LANDING
    w.pose_seen("cf1", 0.8)
    w.pose_seen("cf2", 0.8)
    assert kinds(w.check(0.8)) == [("cf1", "fresh")]
    assert w.state("cf1", 0.8) == LANDING         # told to land: stays so until rearmed
    w.rearm("cf1")
    assert w.state("cf1", 0.8) == OK


def test_a_pose_back_within_the_hold_cancels_the_landing():
    w = SwarmWatch(["cf1"], stale_after=0.1, hold=0.5)
    w.pose_seen("cf1", 0.0)
    assert kinds(w.check(0.2)) == [("cf1", "stale")]
    w.pose_seen("cf1", 0.4)
    assert kinds(w.check(0.4)) == [("cf1", "fresh")]
    assert kinds(w.check(0.55)) == [("cf1", "stale")]     # a new episode: stale since 0.5
    assert w.check(0.99) == []
    assert kinds(w.check(1.0)) == [("cf1", "land")]


def test_link_lost_lands_after_the_hold_and_a_link_back_in_time_does_not():
    w = SwarmWatch(["cf1", "cf2"], stale_after=0.1, hold=0.5)
    w.link("cf1", False, 1.0)
    w.link("cf2", False, 1.0)
    w.link("cf2", True, 1.3)
    assert w.check(1.4) == []
    events = w.check(1.5)
    assert kinds(events) == [("cf1", "land")] and events[0].reason == "radio link lost for 0.50 s"


def test_bad_settings_refused():
    with pytest.raises(ValueError, match="stale_after"):
        SwarmWatch(["cf1"], stale_after=0.0)
