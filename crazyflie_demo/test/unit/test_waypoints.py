"""Waypoint sequencing and joystick button edges of the demo scripts."""
import pytest

from crazyflie_demo.joystick_buttons import ButtonEdges, actions_for
from crazyflie_demo.waypoints import WaypointFollower, angle_difference_deg


def test_advances_only_after_holding_for_sleep():
    f = WaypointFollower([[0, 0, 0.5, 0, 2], [1, 0, 0.5, 0, 1]])
    assert f.update(0.0, (0, 0, 0.1), 0).x == 0          # not there yet
    assert f.update(1.0, (0.1, -0.1, 0.45), 5).x == 0    # reached, wait starts
    assert f.update(2.9, (0.1, -0.1, 0.45), 5).x == 0    # 1.9 s held
    assert f.update(3.0, (0.1, -0.1, 0.45), 5).x == 1    # 2 s held: next
    assert f.index == 1 and not f.finished


def test_leaving_tolerance_restarts_the_wait():
    f = WaypointFollower([[0, 0, 0.5, 0, 1], [1, 0, 0.5, 0, 0]])
    f.update(0.0, (0, 0, 0.5), 0)
    f.update(0.8, (0.4, 0, 0.5), 0)                      # drifted out (0.4 > 0.3)
    assert f.update(1.2, (0, 0, 0.5), 0).x == 0          # wait restarted at 1.2
    assert f.update(2.2, (0, 0, 0.5), 0).x == 1


def test_yaw_tolerance_wraps_around():
    f = WaypointFollower([[0, 0, 0.5, 179, 0], [0, 0, 0.5, 0, 0]])
    assert f.update(0.0, (0, 0, 0.5), -179).yaw_deg == 0  # 2° apart across ±180
    assert angle_difference_deg(-179, 179) == pytest.approx(2)
    g = WaypointFollower([[0, 0, 0.5, 90, 0]])
    g.update(0.0, (0, 0, 0.5), 75)
    assert not g.finished                                # 15° off


def test_finished_after_last_waypoint_held():
    f = WaypointFollower([[0, 0, 0.5, 0, 0], [0, 0, 1.0, 0, 0.5]])
    f.update(0.0, (0, 0, 0.5), 0)
    f.update(1.0, (0, 0, 1.0), 0)
    assert not f.finished
    f.update(1.5, (0, 0, 1.0), 0)
    assert f.finished and f.index == 1 and f.reached_times == [0.0, 1.5]


def test_bad_waypoint_is_a_clear_error():
    with pytest.raises(ValueError, match="x, y, z, yaw_deg, sleep_s"):
        WaypointFollower([[0, 0, 0.5]])
    with pytest.raises(ValueError, match="no waypoints"):
        WaypointFollower([])


def test_buttons_fire_on_press_only():
    e = ButtonEdges()
    assert e.pressed([0, 0, 1, 0, 0]) == [2]
    assert e.pressed([0, 0, 1, 0, 0]) == []              # held
    assert e.pressed([1, 0, 0, 0, 1]) == [0, 4]
    assert actions_for([0, 4]) == ["land", "headlight"]
    assert actions_for([1, 2]) == ["emergency"]          # emergency wins
    assert actions_for([3, 7]) == []
