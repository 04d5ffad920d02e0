"""The world's per-vehicle float twins (physics substep, PID position controller) give the numbers of
its numpy passes: the same flights (a PID and a Mellinger vehicle) with the twins forced off end in the
same state."""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from crazyflie_driver.crtp.quaternion import compress_quaternion
from crazyflie_driver.sim.crtp.setpoint_decode import decode_setpoint
from crazyflie_driver.sim.onboard import position_control
from crazyflie_driver.sim.onboard.scalar import clamp, maximum
from crazyflie_driver.sim.room import physics
from crazyflie_driver.sim.room.world import World


def fly():
    """A PID and a Mellinger vehicle: takeoff, go_to, four kinds of streamed setpoints, landing.
    Returns their states at each phase's end."""
    w = World(speed=0, seed=5)
    vehicles = [w.add_vehicle("cf%d" % k, position=(0.5 * k, 0.0, 0.0)) for k in range(2)]
    stream = {}

    def traffic(now):
        for v in vehicles:
            p, q = v.pose()
            v.external_measurement(p + 0.001 * math.sin(37.0 * now), q)
            if v.name in stream:
                v.set_setpoint(stream[v.name])

    for k, v in enumerate(vehicles):
        v.write_param("stabilizer.estimator", 2)
        v.write_param("stabilizer.controller", 1 + k)
        v.write_param("kalman.initialX", 0.5 * k)
        v.write_param("kalman.resetEstimation", 1)
    w.add_tick_listener(traffic, 0.01)
    q = (0.0, 0.0, math.sin(0.2), math.cos(0.2))
    phases = [
        lambda v, k: v.high_level("takeoff", height=0.6, duration=1.0, yaw=0.3),
        lambda v, k: v.high_level("go_to", goal=(0.3, 0.2, 0.2), yaw=-0.5, duration=1.0, relative=True),
        lambda v, k: stream.__setitem__(v.name, decode_setpoint(bytes([7]) + struct.pack("<ffff", k, 0.3, 0.7, 20.0))),
        lambda v, k: stream.__setitem__(v.name, decode_setpoint(bytes([6]) + struct.pack(
            "<hhhhhhhhhIhhh", 500 * k, -200, 800, 100, 0, 0, 0, 0, 0, compress_quaternion(q), 0, 0, 100))),
        lambda v, k: stream.__setitem__(v.name, decode_setpoint(bytes([10]) + struct.pack("<ffff", 0.2, -0.1, 15.0,
                                                                                          0.6))),
        lambda v, k: (stream.pop(v.name), v.notify_setpoint_stop(), v.high_level("land", height=0.0, duration=1.0,
                                                                                yaw=0.0)),
    ]
    states = []
    for phase in phases:
        for k, v in enumerate(vehicles):
            phase(v, k)
        w.step(1200)
        states.append([np.concatenate([v.pose()[0], v.pose()[1], v.velocity(), v.motors()]) for v in vehicles])
    return np.array(states)


def test_float_twins_fly_as_the_numpy_passes(monkeypatch):
    twins = fly()
    assert twins[1, :, 2].min() > 0.5 and twins[-1, :, 2].max() < 0.05        # flew, and landed
    monkeypatch.setattr(physics, "SCALAR_ROWS", 0)
    monkeypatch.setattr(position_control, "SCALAR_ROWS", 0)
    numpy_only = fly()
    assert np.abs(twins[:, :, :13] - numpy_only[:, :, :13]).max() < 1e-9         # state: float noise only
    assert np.abs(twins[:, :, 13:] - numpy_only[:, :, 13:]).max() < 1e-3         # motor commands (0..65535)


@pytest.mark.parametrize("x, lo, hi", [(0.5, 0.0, 1.0), (-2.0, 0.0, 1.0), (3.0, 0.0, 1.0), (math.nan, 0.0, 1.0),
                                       (0.5, math.nan, 1.0), (0.5, 0.0, math.nan), (0.5, 1.0, -1.0),
                                       (math.inf, 0.0, 1.0), (-math.inf, -math.inf, 1.0)])
def test_clamp_and_maximum_behave_as_numpy(x, lo, hi):
    expected = float(np.minimum(np.maximum(x, lo), hi))
    got = clamp(x, lo, hi)
    assert got == expected or (math.isnan(got) and math.isnan(expected))
    expected = float(np.maximum(x, lo))
    got = maximum(x, lo)
    assert got == expected or (math.isnan(got) and math.isnan(expected))
