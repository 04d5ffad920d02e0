"""uav_trajectory without ROS: the CSV format, eval's derivatives and body rates, the shipped files."""
from __future__ import annotations

import math
import pathlib

import numpy as np
import pytest

from crazyflie_driver.errors import TrajectoryError
from crazyflie_driver.protocol.trajectory import evaluate, pack_poly4d
from uav_trajectory import HEADER, Trajectory
from uav_trajectory.examples import EXAMPLES, figure8, takeoff

FILES = pathlib.Path(__file__).resolve().parents[2] / "trajectories"


def row(duration, x=(), y=(), z=(), yaw=()):
    pad = lambda c: list(c) + [0.0] * (8 - len(c))     # noqa: E731
    return [duration] + pad(x) + pad(y) + pad(z) + pad(yaw)


def write(tmp_path, rows, header=True, trailing_comma=False):
    p = tmp_path / "t.csv"
    lines = ([",".join(HEADER)] if header else []) + [",".join("%r" % v for v in r) + ("," if trailing_comma else "")
                                                      for r in rows]
    p.write_text("\n".join(lines) + "\n")
    return str(p)


def test_a_known_polynomial_evaluates_with_its_derivatives(tmp_path):
    # x = 1 + 2t + 3t², y = t³, z = 0.5, yaw = 0.1t
    path = write(tmp_path, [row(2.0, x=(1, 2, 3), y=(0, 0, 0, 1), z=(0.5,), yaw=(0, 0.1))], trailing_comma=True)
    t = Trajectory().loadcsv(path)
    assert t.n_pieces() == 1 and t.duration == 2.0
    s = t.eval(1.5)
    assert s.pos == pytest.approx([1 + 3 + 6.75, 3.375, 0.5])
    assert s.vel == pytest.approx([2 + 9, 6.75, 0.0])
    assert s.acc == pytest.approx([6, 9, 0])
    assert s.yaw == pytest.approx(0.15)
    assert t.polynomials[0].px.p.tolist() == [1, 2, 3, 0, 0, 0, 0, 0]     # Crazyswarm's attribute names


def test_pieces_follow_each_other_in_time(tmp_path):
    path = write(tmp_path, [row(1.0, x=(0, 1)), row(2.0, x=(1, 0, 1))])
    t = Trajectory().loadcsv(path)
    assert t.duration == 3.0
    assert t.eval(0.5).pos[0] == pytest.approx(0.5)
    assert t.eval(2.0).pos[0] == pytest.approx(2.0)          # 1 s into the second piece
    assert t.eval(3.0).pos[0] == pytest.approx(5.0)          # the end is included
    with pytest.raises(TrajectoryError, match="outside"):
        t.eval(3.1)
    with pytest.raises(TrajectoryError, match="outside"):
        t.eval(-0.1)


def test_body_rates_follow_from_the_jerk():
    """A hover with yaw rate only turns about z; a pure sideways jerk tilts about x (thrust is g)."""
    t = Trajectory.from_pieces(takeoff().pieces())
    assert t.eval(0.0).omega == pytest.approx([0, 0, 0])
    from uav_trajectory import Polynomial4D
    spin = Polynomial4D(1.0, [0] * 8, [0] * 8, [1] + [0] * 7, [0, 0.7] + [0] * 6)
    assert spin.eval(0.3).omega == pytest.approx([0, 0, 0.7])
    # y = t³/6: jerk 1 m/s³ along +y at rest -> roll rate -1/g (right-handed, the body tilts toward +y)
    side = Polynomial4D(1.0, [0] * 8, [0, 0, 0, 1 / 6] + [0] * 4, [1] + [0] * 7, [0] * 8)
    assert side.eval(0.0).omega == pytest.approx([-1 / 9.81, 0, 0])


@pytest.mark.parametrize("rows, message", [
    ([[1.0, 2.0]], "2 values"),
    ([row(0.0)], "duration"),
    ([row(-1.0)], "duration"),
    ([row(1.0)[:-1] + ["nan"]], "not a finite number"),
    ([row(1.0)[:5] + ["a"] + row(1.0)[6:]], "could not convert"),
    ([], "no pieces"),
])
def test_bad_files_name_the_line_and_the_fault(tmp_path, rows, message):
    p = tmp_path / "bad.csv"
    p.write_text("\n".join([",".join(HEADER)] + [",".join(str(v) for v in r) for r in rows]) + "\n")
    with pytest.raises(TrajectoryError, match=message) as e:
        Trajectory().loadcsv(str(p))
    if rows:
        assert "bad.csv:2" in str(e.value)


def test_a_missing_file_says_so(tmp_path):
    with pytest.raises(TrajectoryError, match="cannot be read"):
        Trajectory().loadcsv(str(tmp_path / "none.csv"))


def test_save_and_load_round_trip(tmp_path):
    t = figure8()
    t.savecsv(str(tmp_path / "f.csv"))
    back = Trajectory().loadcsv(str(tmp_path / "f.csv"))
    for s in np.linspace(0, t.duration, 97):
        assert back.eval(s).pos == pytest.approx(t.eval(s).pos, abs=1e-7)


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_the_shipped_files_are_what_the_generator_writes(name, tmp_path):
    shipped = Trajectory().loadcsv(str(FILES / name))
    fresh = EXAMPLES[name]()
    assert shipped.n_pieces() == fresh.n_pieces()
    for s in np.linspace(0, fresh.duration, 201):
        assert shipped.eval(s).pos == pytest.approx(fresh.eval(s).pos, abs=1e-6)


def test_the_figure8_is_smooth_closed_and_at_crazyswarms_speeds():
    t = Trajectory().loadcsv(str(FILES / "figure8.csv"))
    ts = np.linspace(0, t.duration, 4001)
    states = [t.eval(s) for s in ts]
    pos = np.array([s.pos for s in states])
    speed = np.linalg.norm([s.vel for s in states], axis=1)
    assert pos[0] == pytest.approx([0, 0, 0]) and pos[-1] == pytest.approx([0, 0, 0], abs=1e-6)
    assert pos[:, 0].max() - pos[:, 0].min() == pytest.approx(2.0, abs=1e-3)
    assert pos[:, 1].max() - pos[:, 1].min() == pytest.approx(1.0, abs=1e-3)
    assert speed.mean() == pytest.approx(0.76, abs=0.01) and speed.max() == pytest.approx(1.48, abs=0.01)
    # continuous up to the jerk at every joint between pieces
    start = 0.0
    for a, b in zip(t.polynomials, t.polynomials[1:]):
        start += a.duration
        for _ in range(4):
            assert a.eval(a.duration).pos == pytest.approx(b.eval(0.0).pos, abs=1e-6)
            a, b = a.derivative(), b.derivative()
    assert len(pack_poly4d(t.pieces())) <= 4096            # fits the trajectory memory


def test_the_takeoff_rises_from_rest_to_rest():
    t = Trajectory().loadcsv(str(FILES / "takeoff.csv"))
    assert t.eval(0).pos == pytest.approx([0, 0, 0]) and t.eval(t.duration).pos == pytest.approx([0, 0, 1.0])
    for s in (0.0, t.duration):
        assert t.eval(s).vel == pytest.approx([0, 0, 0], abs=1e-9)
        assert t.eval(s).acc == pytest.approx([0, 0, 0], abs=1e-9)
    z = [t.eval(s).pos[2] for s in np.linspace(0, t.duration, 301)]
    assert all(b >= a - 1e-12 for a, b in zip(z, z[1:]))    # never sinks on the way up


def test_pieces_are_what_the_upload_takes():
    t = figure8()
    pieces = t.pieces()
    assert len(pieces) == t.n_pieces()
    mid = pieces[3].duration / 2
    assert evaluate(pieces[3], mid)[:3] == pytest.approx(t.polynomials[3].eval(mid).pos.tolist())
    assert not math.isnan(pieces[0].x[0])


def test_plot_writes_a_png(tmp_path):
    from uav_trajectory.plot import plot
    out = plot(takeoff(), str(tmp_path / "t.png"))
    assert pathlib.Path(out).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
