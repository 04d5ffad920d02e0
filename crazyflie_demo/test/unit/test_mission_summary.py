"""Mission bookkeeping: hold error only while holding a waypoint, rest-to-rest battery, reach times."""
from __future__ import annotations

import math

import pytest

from crazyflie_demo.mission_summary import VehicleTrack, plot_tracks, summary_lines


def test_hold_error_counts_from_arrival_until_the_goal_moves():
    tr = VehicleTrack("cf")
    tr.add_goal(0.0, (0.0, 0.0, 0.5))
    tr.add_pose(0.0, (0.0, 0.0, 0.0))          # on the ground: approaching, not holding
    tr.add_pose(0.1, (0.0, 0.0, 0.3))          # 0.2 m away: still approaching
    assert tr.hold_errors == []
    tr.add_pose(0.2, (0.0, 0.0, 0.45))         # 5 cm: arrived
    tr.add_pose(0.3, (0.0, 0.0, 0.38))         # an excursion after arriving counts
    assert tr.hold_errors == pytest.approx([0.05, 0.12])
    tr.add_goal(0.4, (1.0, 0.0, 0.5))          # next waypoint: approaching again
    tr.add_pose(0.5, (0.5, 0.0, 0.5))
    assert len(tr.hold_errors) == 2
    assert tr.rms_hold_error() == pytest.approx(math.sqrt((0.05 ** 2 + 0.12 ** 2) / 2))


def test_battery_used_is_resting_voltage_before_the_motors_start_minus_after_they_stop():
    tr = VehicleTrack("cf")
    for k in range(10):
        tr.add_battery(k * 0.1, 4.10)          # at rest
    tr.add_thrust(0.95, 0.0)
    tr.add_thrust(1.0, 20000.0)                # motors start at 1.0
    for k in range(10, 60):
        tr.add_battery(k * 0.1, 3.80)          # under load: sagging
        tr.add_thrust(k * 0.1, 36000.0)
    tr.add_thrust(6.0, 0.0)                    # motors stop at 6.0
    assert math.isnan(tr.battery_used())       # nothing at rest after that yet
    for k in range(60, 80):
        tr.add_battery(k * 0.1, 4.08 if k * 0.1 > 6.3 else 3.8)
    assert tr.battery_used() == pytest.approx(0.02)
    tr.add_thrust(8.0, 30000.0)                # flying again: not stopped any more
    assert math.isnan(tr.battery_used())


def test_reach_times_in_order_and_in_the_summary(tmp_path):
    tr = VehicleTrack("cf", waypoint_count=3)
    tr.add_goal(0.0, (0.0, 0.0, 0.5))
    tr.add_pose(1.0, (0.0, 0.0, 0.1))          # take-off at 1.0
    tr.reach_waypoint(4.0, 0)
    tr.reach_waypoint(4.0, 0)                  # a repeat is ignored
    tr.reach_waypoint(7.5, 1)
    tr.reach_waypoint(9.0, 2)
    assert tr.reached_times == [4.0, 7.5, 9.0] and tr.waypoints_reached == 3
    lines = summary_lines([tr])
    assert any("1:3.0  2:6.5  3:8.0" in line for line in lines)
    assert lines[1].split()[:2] == ["cf", "3/3"]
    path = plot_tracks([tr], {"cf": [[0, 0, 0.5, 0, 2]]}, str(tmp_path / "p.png"))
    assert (tmp_path / "p.png").stat().st_size > 10000 and path.endswith("p.png")
