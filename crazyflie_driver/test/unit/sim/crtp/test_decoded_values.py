"""The simulated firmware's record of what it decoded: extremes per field, non-finite values counted."""
from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from crazyflie_driver.protocol.trajectory import make_piece
from crazyflie_driver.sim.crtp.decoded_values import DecodedValues
from support.radio_rig import RadioRig


def test_extremes_and_non_finite_values_per_field():
    d = DecodedValues()
    d.observe("a", (1.0, [2.0, math.nan], {"k": -math.inf}, True, None, "text"))
    d.observe("a", (-3.0, [5.0, 1.0], {"k": 0.5}))
    s = d.summary()
    assert s["a.0"] == {"count": 2, "non_finite": 0, "min": -3.0, "max": 1.0}
    assert s["a.1.1"] == {"count": 2, "non_finite": 1, "min": 1.0, "max": 1.0}
    assert s["a.2.k"]["non_finite"] == 1 and s["a.2.k"]["min"] == 0.5
    assert set(s) == {"a.0", "a.1.0", "a.1.1", "a.2.k"}      # booleans, None and text are not numbers here


class _Pair(NamedTuple):
    x: float
    y: float


@dataclasses.dataclass
class _Piece:
    duration: float
    coefficients: np.ndarray
    label: str = "piece"


def test_numpy_numbers_named_tuples_arrays_and_dataclasses_are_walked_by_name():
    d = DecodedValues()
    d.observe("n", np.float32(2.5))
    d.observe("p", _Pair(1.0, np.inf))
    d.observe("piece", _Piece(1.5, np.array([[0.0, -1.0], [math.nan, 4.0]])))
    d.observe("piece", _Piece(0.5, np.zeros((2, 2))))
    s = d.summary()
    assert s["n"] == {"count": 1, "non_finite": 0, "min": 2.5, "max": 2.5}
    assert s["p.0"]["max"] == 1.0 and s["p.1"] == {"count": 1, "non_finite": 1, "min": None, "max": None}
    assert s["piece.duration"] == {"count": 2, "non_finite": 0, "min": 0.5, "max": 1.5}
    assert [s["piece.coefficients.%d" % i]["min"] for i in range(4)] == [0.0, -1.0, 0.0, 0.0]
    assert s["piece.coefficients.2"]["non_finite"] == 1
    assert not any(name.startswith("piece.label") for name in s)       # text is no number


def test_tuples_counted_later_are_recorded_as_walking_every_value_as_it_came():
    """Tuples wait to be counted a column at a time (``PENDING_TUPLES``, or a summary); the record is the
    one of walking every value as it came: NaN, infinities, nested values, bools, other lengths."""
    values = [("rpyt", (1.0, -2.0, 3.0, 40000)), ("rpyt", (1.5, math.nan, -math.inf, 0)),
              ("rpyt", (0.5, (7.0, 8.0), True, 2)), ("rpyt", (9.0, 1.0)), ("rpyt", (2.0, -9.0, 1e308, 60000)),
              ("rpyt", (-0.5, 3.0, 1e308, -7)), ("mixed", ([1.0], 2.0)), ("mixed", (3.0, 4.0)),
              ("mixed", (5.0, [6.0])), ("mixed", ()), ("mixed", 2.5)]
    values += [("rpyt", (float(i), -float(i), 0.25 * i, i)) for i in range(3 * DecodedValues.PENDING_TUPLES)]
    later, walked = DecodedValues(), DecodedValues()
    for k, (name, value) in enumerate(values):
        later.observe(name, value)
        walked._walk(name, value)
        if k in (3, 200):
            assert later.summary() == walked.summary()
    assert later.summary() == walked.summary()
    assert later.summary()["rpyt.3"] == {"count": 5 + 3 * DecodedValues.PENDING_TUPLES, "non_finite": 0,
                                         "min": -7.0, "max": 60000.0}
    assert later.summary()["rpyt.2"]["non_finite"] == 1 and later.summary()["rpyt.2"]["max"] == 1e308


def test_a_value_changed_after_it_was_observed_is_recorded_as_it_was():
    d = DecodedValues()
    inner = [1.0]
    d.observe("x", (inner, 2.0))
    inner[0] = 50.0
    assert d.summary()["x.0.0"] == {"count": 1, "non_finite": 0, "min": 1.0, "max": 1.0}


def test_the_snapshot_shows_what_reached_the_vehicle():
    rig = RadioRig()
    cf = rig.connect()
    cf.send_setpoint(10.0, -20.0, 30.0, 40000)
    cf.send_setpoint(1.0, 2.0, 3.0, 1000)
    cf.high_level.upload_trajectory(1, [make_piece(1.5, [0.0] * 8, [1.0] * 8, [0.0] * 8, [0.0] * 8)])
    snap = rig.firmware.snapshot()
    assert snap["decoded"]["set_rpyt.0"] == {"count": 2, "non_finite": 0, "min": 1.0, "max": 10.0}
    assert snap["decoded"]["set_rpyt.3"]["max"] == 40000
    traj = snap["trajectories"]
    assert traj, "the uploaded trajectory's pieces as the firmware reads them"
    assert all(v["non_finite"] == 0 for v in traj.values())
    assert max(v["max"] for v in traj.values()) == 1.5       # the duration


def test_one_byte_high_level_requests_are_answered_and_matched():
    """stop and set_group_mask carry one byte after the command; the reply echoes two (the second as
    the firmware's buffer holds it): the host matches the bytes its request has."""
    rig = RadioRig()
    cf = rig.connect()
    cf.high_level.set_group_mask(3)
    cf.high_level.stop(0)
    decoded = rig.firmware.snapshot()["decoded"]
    assert decoded["high_level.set_group_mask.mask"]["max"] == 3
    assert decoded["high_level.stop.mask"]["count"] == 1
