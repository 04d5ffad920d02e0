"""The swarm demo's pieces without ROS: the figure-8 it computes, its swarm files, its flight plan."""
from __future__ import annotations

import math
import pathlib

import numpy as np
import pytest

from crazyflie_demo.figure8 import curve, figure8_pieces, position_at, trajectory_duration
from crazyflie_demo.swarm_flight import Flight, Phase, Plan, pyramid_goals
from crazyflie_demo.swarm_grid import SHIPPED, channel_blocks, grid_positions, swarm_file_text
from crazyflie_driver.protocol.trajectory import PIECE_BYTES, evaluate, pack_poly4d
from crazyflie_driver.server.swarm.config import load_swarm_file

CONFIG = pathlib.Path(__file__).resolve().parents[2] / "config"
TRAJECTORY_MEMORY_BYTES = 4096


def sampled(pieces, n=8001):
    t = np.linspace(0.0, trajectory_duration(pieces), n)
    return t, np.array([position_at(pieces, x) for x in t])


def test_figure8_has_crazyswarms_speeds_and_starts_and_ends_at_rest():
    pieces = figure8_pieces()
    t, p = sampled(pieces)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(t)
    assert speed.mean() == pytest.approx(0.76, abs=0.01)            # Crazyswarm: 0.76 m/s mean
    assert 1.4 < speed.max() <= 1.5                                  # ... 1.5 m/s top
    assert np.allclose(p[0], 0.0) and np.allclose(p[-1], 0.0, atol=1e-9)
    assert speed[0] < 1e-3 and speed[-1] < 1e-3
    assert np.ptp(p[:, 0]) == pytest.approx(2.0, abs=0.01) and np.ptp(p[:, 1]) == pytest.approx(1.0, abs=0.01)
    assert (p[:, 2] == 0).all()


def test_figure8_pieces_follow_the_curve_and_join_smoothly():
    pieces = figure8_pieces()
    t, p = sampled(pieces)
    exact = np.array([[curve(x)[0][0], curve(x)[1][0]] for x in t])
    assert np.abs(p[:, :2] - exact).max() < 1e-4                     # 0.1 mm
    for a, b in zip(pieces, pieces[1:]):                             # position, velocity, acceleration, jerk
        for k in range(4):
            def deriv(c, t, k=k):
                return sum(math.factorial(n) / math.factorial(n - k) * c[n] * t ** (n - k) for n in range(k, 8))
            for axis in ("x", "y"):
                assert deriv(getattr(a, axis), a.duration) == pytest.approx(deriv(getattr(b, axis), 0.0), abs=1e-6)
    assert len(pack_poly4d(pieces)) == len(pieces) * PIECE_BYTES <= TRAJECTORY_MEMORY_BYTES


def test_grid_positions_and_channel_blocks():
    pos = grid_positions(49)
    assert len(pos) == 49 and pos[0] == (-1.5, -1.5) and pos[-1] == (1.5, 1.5)
    assert pos[1][0] - pos[0][0] == pytest.approx(0.5)
    chans = channel_blocks(49)
    assert [chans.count(c) for c in (80, 90, 100)] == [17, 16, 16]
    assert channel_blocks(1) == [80]
    with pytest.raises(ValueError):
        grid_positions(0)


@pytest.mark.parametrize("n", SHIPPED)
def test_shipped_swarm_files_are_the_generators_and_load_as_the_server_reads_them(n):
    path = CONFIG / ("swarm%d.yaml" % n)
    assert path.read_text() == swarm_file_text(n)
    swarm = load_swarm_file(str(path))
    assert len(swarm.crazyflies) == n
    assert swarm.dongles_needed == min(n, 3)
    assert dict(swarm.crazyflies[0].params)["stabilizer.controller"] == 2
    if n == 49:
        assert [len(v) for v in swarm.radios().values()] == [17, 16, 16]
        assert swarm.crazyflies[48].uri == "radio://2/100/2M/E7E7E7E731"


def test_pyramid_goals_raise_the_inner_rings_and_keep_every_crazyflie_over_its_start():
    start = {"cf%d" % (i + 1): (x, y, 1.0) for i, (x, y) in enumerate(grid_positions(49))}
    goals = pyramid_goals(start, 1.0, 0.15)
    assert goals["cf25"] == pytest.approx((0.0, 0.0, 1.45))         # centre: three rings up
    assert goals["cf1"] == pytest.approx((-1.5, -1.5, 1.0))         # corner: the outer ring
    assert all(goals[n][:2] == start[n][:2] for n in start)


def test_plan_is_the_firmware_planners_path_and_the_figure8_relative_to_its_start():
    from crazyflie_driver.sim.onboard.planner import poly7_nojerk
    plan = Plan((0.5, -1.0, 0.0))
    plan.add(Phase("takeoff", 2.5, 1.0), 10.0, "cf1")
    c = poly7_nojerk(2.5, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0))        # what the simulated firmware flies
    for dt in (0.3, 1.25, 2.0):
        assert plan.at(10.0 + dt)[2] == pytest.approx(sum(ci * dt ** i for i, ci in enumerate(c)), abs=1e-9)
    assert plan.at(5.0) == (0.5, -1.0, 0.0) and plan.at(13.0) == pytest.approx((0.5, -1.0, 1.0))
    plan.add(Phase("figure8", 8.0), 20.0, "cf1")
    rel = evaluate(figure8_pieces()[2], 0.1)
    assert plan.at(21.1) == pytest.approx((0.5 + rel[0], -1.0 + rel[1], 1.0))
    plan.add(Phase("formation", 3.0, goals={"cf1": (0.5, -1.0, 1.3)}), 30.0, "cf1")
    plan.add(Phase("land", 3.0, 0.0), 35.0, "cf1")
    assert plan.at(33.5) == pytest.approx((0.5, -1.0, 1.3)) and plan.at(40.0) == pytest.approx((0.5, -1.0, 0.0))


def test_flight_errors_per_phase():
    flight = Flight({"cf1": (0.0, 0.0, 0.0), "cf2": (0.5, 0.0, 0.0)})
    flight.phase(Phase("takeoff", 2.0, 1.0), 1.0)
    flight.phase(Phase("figure8", 8.0), 4.0)
    for k in range(1300):
        t = k * 0.01
        p1 = flight.tracks["cf1"].plan.at(t)
        p2 = flight.tracks["cf2"].plan.at(t)
        flight.sample(t, {"cf1": p1, "cf2": (p2[0], p2[1] + 0.02, p2[2])})     # cf2 2 cm off
    st = flight.phase_stats("figure8")
    assert st["crazyflies"] == 2 and st["worst"] == "cf2"
    assert st["worst_mean"] == pytest.approx(0.02) and st["mean"] == pytest.approx(0.01)
    lines = flight.summary_lines()
    assert lines[0].startswith("takeoff") and "figure8" in lines[1] and "cf2 2.0 cm" in lines[1]
    assert Phase.from_json(Phase("formation", 3.0, goals={"cf1": (1.0, 2.0, 3.0)}).to_json()).goals == \
        {"cf1": (1.0, 2.0, 3.0)}


def test_plot_is_written(tmp_path):
    pytest.importorskip("matplotlib")
    from crazyflie_demo.swarm_flight import plot_flight
    flight = Flight({"cf1": (0.0, 0.0, 0.0)})
    flight.phase(Phase("takeoff", 2.0, 1.0), 0.0)
    for k in range(300):
        flight.sample(k * 0.01, {"cf1": flight.tracks["cf1"].plan.at(k * 0.01)})
    out = plot_flight(flight, str(tmp_path / "swarm.png"), "test")
    assert pathlib.Path(out).stat().st_size > 10000


def test_pyramid_of_an_even_grid():
    start = {"cf%d" % (i + 1): (x, y, 1.0) for i, (x, y) in enumerate(grid_positions(16))}
    goals = pyramid_goals(start, 1.0, 0.15)
    assert sorted({round(g[2], 3) for g in goals.values()}) == [1.0, 1.15]      # inner 2 x 2 one step up
    assert goals["cf6"][2] == pytest.approx(1.15) and goals["cf1"][2] == pytest.approx(1.0)


def test_each_crazyflie_is_judged_from_when_its_commander_began_the_phase():
    flight = Flight({"cf1": (0.0, 0.0, 1.0)})
    index = flight.phase(Phase("figure8", 8.0), 10.0)          # announced at 10.0
    flight.set_start(index, "cf1", 10.3)                          # the broadcast reached it at 10.3
    plan = flight.tracks["cf1"].plan
    for t in (10.5, 12.0, 15.0):
        flight.sample(t, {"cf1": plan.at(t)})
    assert plan.at(12.0) == pytest.approx(tuple(a + b for a, b in zip((0.0, 0.0, 1.0), position_at(
        figure8_pieces(), 1.7))))
    assert max(flight.tracks["cf1"].errors) == pytest.approx(0.0)
