"""The mission monitor's decisions without ROS: settings, waypoint and landing reports, the watch's end."""
from __future__ import annotations

import os
import re

import pytest

from crazyflie_demo.mission_monitor import (
    LANDED_HEIGHT_M,
    LANDING_SETTLE_S,
    Mission,
    MonitorConfig,
    Watch,
    result_line,
    result_word,
)


def _params(**given):
    return lambda key, default: given.get(key.lstrip("~"), default)


def test_defaults_watch_the_chapters_two_vehicles_on_their_vicon_frames():
    c = MonitorConfig.from_params(_params())
    assert c.names == ("crazyflie1", "crazyflie2")
    assert c.frames == ("vicon/crazyflie1/crazyflie1", "vicon/crazyflie2/crazyflie2")
    assert (c.world, c.timeout_s, c.rate_hz, c.rest_after_landing_s, c.result_file) == ("world", 180.0, 50.0, 1.0, "")


def test_parameters_are_read_as_given():
    c = MonitorConfig.from_params(_params(vehicles=["cf1"], worldFrame="/map", timeout="30", plot="~/m.png",
                                          result_file="~/r.txt"))
    assert (c.names, c.frames, c.world, c.timeout_s) == (("cf1",), ("vicon/cf1/cf1",), "map", 30.0)
    assert c.plot_path == os.path.expanduser("~/m.png") and c.result_file == os.path.expanduser("~/r.txt")


@pytest.mark.parametrize("given, says", [
    (dict(vehicles=[]), "~vehicles is empty"),
    (dict(vehicles=["a", "b"], frames=["a"]), "1 frames for 2 ~vehicles"),
    (dict(rate=0), "~rate must be > 0"),
    (dict(timeout=-5), "~timeout must be > 0"),
    (dict(timeout="soon"), "~timeout must be a number, got 'soon'"),
    (dict(rest_after_landing=-1), "~rest_after_landing must be >= 0"),
])
def test_bad_parameters_are_refused_with_what_to_fix(given, says):
    with pytest.raises(ValueError, match=re.escape(says)):
        MonitorConfig.from_params(_params(**given))


def _mission(waypoints=3):
    m = Mission(["cf1", "cf2"])
    for n in ("cf1", "cf2"):
        assert m.wants_waypoints(n)
        m.set_waypoints(n, [[0.0, 0.0, 0.5]] * waypoints)
        assert not m.wants_waypoints(n)
    return m


def test_flying_to_a_waypoint_reaches_every_one_before_it_once():
    m = _mission()
    assert m.on_waypoint("cf1", 1.0, 0) == ["[cf1] flying to waypoint 1/3"]
    assert m.on_waypoint("cf1", 4.0, 2) == ["[cf1] waypoint 1/3 reached", "[cf1] waypoint 2/3 reached",
                                            "[cf1] flying to waypoint 3/3"]
    assert m.on_waypoint("cf1", 5.0, 2) == ["[cf1] flying to waypoint 3/3"]      # a repeat reaches nothing new
    assert m.tracks["cf1"].reached_times == [4.0, 4.0] and m.tracks["cf2"].reached_times == []


def test_finishing_reaches_the_rest_once_and_completes_only_when_every_vehicle_has():
    m = _mission()
    assert m.on_finished("cf1", 9.0, False) == []
    m.on_waypoint("cf1", 4.0, 1)
    assert m.on_finished("cf1", 9.0, True) == ["[cf1] all 3 waypoints reached, landing"]
    assert m.on_finished("cf1", 9.5, True) == []
    assert m.tracks["cf1"].reached_times == [4.0, 9.0, 9.0] and m.tracks["cf1"].finished_time == 9.0
    assert not m.complete()                                    # cf2 has reached none
    m.on_finished("cf2", 9.0, True)
    assert m.complete()
    assert not Mission(["cf1"]).complete()                     # no waypoints known: not a complete mission


def test_a_vehicle_has_landed_when_low_and_settled_after_finishing():
    m = _mission()
    assert m.on_pose("cf1", 1.0, (0.0, 0.0, 0.01)) == []      # on the ground before the mission: not landed
    m.on_finished("cf1", 10.0, True)
    low = LANDED_HEIGHT_M / 2
    assert m.on_pose("cf1", 10.0 + LANDING_SETTLE_S / 2, (0.0, 0.0, low)) == []           # just finished
    assert m.on_pose("cf1", 10.0 + 2 * LANDING_SETTLE_S, (0.0, 0.0, 2 * LANDED_HEIGHT_M)) == []   # still up
    assert m.on_pose("cf1", 12.5, (0.0, 0.0, low)) == ["[cf1] landed"]
    assert m.on_pose("cf1", 13.0, (0.0, 0.0, low)) == []       # said once
    assert m.tracks["cf1"].landed_time == 12.5
    assert m.progress() == "cf1: wp 3/3 z=%.2f" % low          # cf2 has no pose yet


def test_all_landed_waits_for_every_vehicle_to_land_with_motors_off_and_rest():
    m = _mission()
    for n in ("cf1", "cf2"):
        m.on_thrust(n, 1.0, 40000.0)
        m.on_finished(n, 10.0, True)
        m.on_pose(n, 12.0, (0.0, 0.0, 0.0))
    assert not m.all_landed(20.0, 1.0)                         # motors still running
    m.on_thrust("cf1", 12.5, 0.0)
    m.on_thrust("cf2", 13.0, 0.0)
    assert not m.all_landed(13.5, 1.0)                         # cf2 has rested 0.5 s only
    assert m.all_landed(14.1, 1.0)


def test_the_report_has_the_summary_and_writes_the_plot(tmp_path):
    m = _mission()
    m.on_goal("cf1", 0.0, (0.0, 0.0, 0.5))
    m.on_battery("cf1", 0.0, 4.1)
    m.on_pose("cf1", 1.0, (0.0, 0.0, 0.5))
    lines, path = m.report(str(tmp_path / "mission.png"))
    assert lines[0].split() == ["vehicle", "waypoints", "flight", "s", "hold", "RMS", "m", "battery", "V"]
    assert [ln.split()[0] for ln in lines[1:3]] == ["cf1", "cf2"]
    assert os.path.isfile(path)


def test_the_watch_prints_progress_each_period_and_ends_on_landing_or_timeout():
    w = Watch(start=100.0, timeout_s=60.0, progress_period_s=5.0)
    assert [t for t in (101.0, 105.5, 106.0, 110.0, 110.6) if w.progress_due(t)] == [105.5, 110.6]
    assert w.verdict(150.0, all_landed=False) is None
    assert w.verdict(150.0, all_landed=True) == "landed"
    assert w.verdict(160.5, all_landed=False) == "timeout"
    assert w.verdict(160.5, all_landed=True) == "landed"          # landing counts even at the deadline


def test_the_result_words():
    assert (result_word(True), result_word(False)) == ("ok", "incomplete")
    assert result_line(True) == "result: every waypoint reached"
    assert result_line(False) == "result: NOT every waypoint reached"
