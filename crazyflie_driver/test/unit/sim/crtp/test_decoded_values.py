"""The simulated firmware's record of what it decoded: extremes per field, non-finite values counted."""
from __future__ import annotations

import math

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
