"""Hover-thrust fit over a stretch of flight (hover_thrust) and the thrust gain of the lift-off fit."""
import math
import random

import pytest

from crazyflie_controller.hover_thrust import HoverThrustFit
from crazyflie_controller.liftoff import LiftoffEstimator

GAIN = 3.5e-4      # m/s² per count, ≈ a 32 g Crazyflie near hover
HOVER = 40900.0
LAG = 0.07


def flown_fit(noise: float, seconds: float = 1.5, seed: int = 3) -> HoverThrustFit:
    """z'' = G·(u(t − lag) − H), u a 50 Hz command wandering ±300 counts around a value 150 counts
    below hover (the vehicle starts sinking), heights sampled at 100 Hz with ``noise`` m of noise."""
    rng = random.Random(seed)
    fit = HoverThrustFit(start=0.0, gain=GAIN, lag=LAG)
    commands = [(k * 0.02, HOVER - 150.0 + 300.0 * math.sin(2.0 * math.pi * 0.7 * k * 0.02) + rng.gauss(0, 200))
                for k in range(int(seconds / 0.02) + 1)]
    for t, u in commands:
        fit.record_command(t, u)

    def command(t):   # what the fit assumes: the command lag earlier, interpolated between ticks
        t -= LAG
        if t <= 0:
            return commands[0][1]
        k = min(int(t / 0.02), len(commands) - 2)
        (t1, u1), (t2, u2) = commands[k], commands[k + 1]
        return u1 + (u2 - u1) * (t - t1) / (t2 - t1)

    z, v, dt = 0.5, 0.03, 0.001
    for i in range(int(seconds / dt) + 1):
        t = i * dt
        if i % 10 == 0:
            fit.record_height(t, z + rng.gauss(0, noise))
        v += GAIN * (command(t) - HOVER) * dt
        z += v * dt
    return fit


def test_fit_recovers_the_hover_thrust_from_a_wandering_flight():
    assert flown_fit(noise=0.0).estimate() == pytest.approx(HOVER, abs=3)
    assert flown_fit(noise=0.0005).estimate() == pytest.approx(HOVER, abs=30)   # mocap noise 0.5 mm


def test_fit_needs_samples_and_commands_covering_the_window():
    fit = HoverThrustFit(start=0.0, gain=GAIN, lag=LAG)
    assert fit.estimate() is None
    for k in range(10):
        fit.record_height(0.1 + k * 0.01, 0.5)
    fit.record_command(0.0, HOVER)
    assert fit.estimate() is None                 # 10 heights: too few
    late = HoverThrustFit(start=0.0, gain=GAIN, lag=LAG)
    late.record_command(1.0, HOVER)               # no command for the first heights
    for k in range(50):
        late.record_height(0.1 + k * 0.01, 0.5)
    assert late.estimate() is None
    with pytest.raises(ValueError, match="thrust gain"):
        HoverThrustFit(start=0.0, gain=0.0, lag=LAG)


def test_thrust_gain_from_the_lift_off_climb():
    est = LiftoffEstimator(min_climb=0.005)
    rate, t0 = 10000.0, 4.1
    assert est.thrust_gain(rate) is None
    for k in range(0, 460):                       # climb = G·rate·(t − t0)³ / 6 under the ramp
        t = k * 0.01
        est.record_climb(t, GAIN * rate * (t - t0) ** 3 / 6 if t > t0 else 0.0)
    assert est.thrust_gain(rate) == pytest.approx(GAIN, rel=0.02)
