"""The simulated onboard controllers driven open loop by scripted states, as the firmware's are in a
reference run: a perfect estimate, one vehicle, one step per 1 kHz tick."""
from __future__ import annotations

import math
import types
from typing import Any, Callable, Dict, Optional, Sequence, Tuple

import numpy as np

from crazyflie_driver.sim.onboard import estimator
from crazyflie_driver.sim.onboard.flight import OnboardFlight
from crazyflie_driver.sim.onboard.stabilizer import OnboardController

#: states(t) -> (roll, pitch, yaw [deg]; position [m]; velocity [m/s]; gyro [deg/s]) at time t [s]
States = Callable[[float], Tuple[Sequence[float], Sequence[float], Sequence[float], Sequence[float]]]


def quaternion(roll: float, pitch: float, yaw: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of standard roll, pitch, yaw in degrees (z-y-x)."""
    r, p, y = (math.radians(a) / 2 for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def fly_open_loop(states: States, setpoint_at: Callable[[int], Optional[Any]], ticks: int, controller: int = 1,
                  read: Callable[[Any], Tuple[float, ...]] = lambda s: tuple(s.rate_out[0])) -> Dict[int, Tuple]:
    """``read(stabilizer state)`` after each tick, by tick; ``setpoint_at(tick)`` is sent when not None."""
    flight, stab = OnboardFlight(), OnboardController()
    rpy, pos, _, _ = states(0.0)
    stab.s.add("current", 0.0, rpy[2])
    flight.add(np.random.default_rng(0), pos, 0.0)
    if controller != 1:
        flight.set_param(0, "stabilizer.controller", controller, np.array(pos), 0.0)
    est = flight.estimator.s                       # a perfect estimate
    est.kind[0], est.exact[0] = estimator.KALMAN, True
    bodies = types.SimpleNamespace(position=np.zeros((1, 3)), velocity=np.zeros((1, 3)),
                                   quaternion=np.zeros((1, 4)))
    out = {}
    for k in range(ticks):
        t = k / 1000.0
        rpy, pos, vel, gyro = states(t)
        bodies.position[0], bodies.velocity[0], bodies.quaternion[0] = pos, vel, quaternion(*rpy)
        sp = setpoint_at(k)
        if sp is not None:
            flight.setpoint(0, sp)
        stab.s.sp_time[0] = t                      # a stream: no watchdog
        flight.step(k, t, bodies, stab.s, 0.0)
        stab.update(k, t, bodies, np.array([gyro]), np.zeros(1, bool))
        out[k] = read(stab.s)
    return out
