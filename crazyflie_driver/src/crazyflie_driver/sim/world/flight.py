"""Onboard flight of every vehicle: the estimator and the position controller, hooked into the world tick.

One object so that the world needs a single call per tick (``step``) and a single place to ask for
the log variables of these stages (``readings``). It runs before the stabilizer's attitude and rate
controllers, whose setpoint row it writes for vehicles flown by generic setpoints.
"""
from __future__ import annotations

from typing import Dict, Optional, Sequence

import numpy as np

from crazyflie_driver.sim.firmware.setpoint_decode import Setpoint
from crazyflie_driver.sim.world.estimator import DEFAULTS as ESTIMATOR_DEFAULTS, Estimator
from crazyflie_driver.sim.world.physics import BodyStates
from crazyflie_driver.sim.world.position_control import POSITION_EVERY, PositionControl
from crazyflie_driver.sim.world.position_control import default_params as control_defaults

GROUPS = ("stateEstimate", "stateEstimateZ", "locSrv", "locSrvZ", "ctrltarget", "posCtl")


def default_params() -> Dict[str, float]:
    """Parameters of the onboard estimator and position controller with the firmware's defaults."""
    out = dict(ESTIMATOR_DEFAULTS)
    out.update(control_defaults())
    return out


class OnboardFlight:
    """Estimator + position controller rows, one per vehicle (called under the world lock)."""

    def __init__(self) -> None:
        self.estimator = Estimator()
        self.control = PositionControl()

    @property
    def models(self):
        """The row containers the world adds to and deletes from."""
        return (self.estimator.s, self.control.s)

    def add(self, rng: np.random.Generator, position: Sequence[float], now: float) -> None:
        self.estimator.add(rng, position, now)
        self.control.add()

    def boot(self, i: int, truth: Sequence[float], now: float) -> None:
        self.estimator.boot(i, truth, now)
        self.control.boot(i)

    def set_param(self, i: int, name: str, value: float, truth: Sequence[float], now: float) -> bool:
        return self.estimator.set_param(i, name, value, truth, now) or self.control.set_param(i, name, value)

    # --- inputs from the radio -------------------------------------------------------------------
    def setpoint(self, i: int, sp: Setpoint) -> None:
        self.control.set_setpoint(i, sp)

    def release(self, i: int) -> None:
        self.control.release(i)

    def measure(self, i: int, position: Sequence[float], quaternion: Optional[Sequence[float]],
                bodies: BodyStates, now: float) -> bool:
        return self.estimator.measure(i, position, quaternion, bodies.position[i].copy(), now)

    # --- the tick ------------------------------------------------------------------------------------
    def step(self, tick: int, now: float, bodies: BodyStates, stab, ground_asl: float) -> bool:
        """Before the stabilizer's tick: estimator prediction, then (100 Hz) the position controller.

        Returns True when it wrote new setpoints into the stabilizer's rows."""
        self.estimator.update(tick, now, stab.thrust > 0.0, bodies.position)
        active = self.control.s.active
        if tick % POSITION_EVERY or not active.any():
            return False
        est_pos = self.estimator.positions(bodies.position, ground_asl)
        est_vel = self.estimator.velocities(bodies.velocity)
        self.control.update(tick, est_pos, est_vel, stab.attitude[:, 2], stab.sp, stab.yaw_sp, stab.thrust > 0.0)
        stab.thrust_locked[active] = False
        return True

    # --- log variables ---------------------------------------------------------------------------------
    def readings(self, i: int, group: str, bodies: BodyStates, attitude_deg: np.ndarray,
                 ground_asl: float) -> Dict[str, float]:
        est = self.estimator
        if group in ("stateEstimate", "stateEstimateZ"):
            p = est.position(i, bodies.position[i], ground_asl)
            v = est.velocity(i, bodies.velocity[i])
            if group == "stateEstimateZ":
                return {"stateEstimateZ.%s" % n: float(int(round(val * 1000.0)))
                        for n, val in zip(("x", "y", "z", "vx", "vy", "vz"), list(p) + list(v))}
            q = bodies.quaternion[i]
            out = {"stateEstimate.%s" % n: float(val) for n, val in zip(("x", "y", "z", "vx", "vy", "vz"),
                                                                        list(p) + list(v))}
            out.update({"stateEstimate.roll": float(attitude_deg[0]), "stateEstimate.pitch": float(attitude_deg[1]),
                        "stateEstimate.yaw": float(attitude_deg[2]),
                        "stateEstimate.qx": float(q[0]), "stateEstimate.qy": float(q[1]),
                        "stateEstimate.qz": float(q[2]), "stateEstimate.qw": float(q[3])})
            return out
        if group == "locSrv":
            p, q = est.s.ext_pos[i], est.s.ext_quat[i]
            return {"locSrv.x": float(p[0]), "locSrv.y": float(p[1]), "locSrv.z": float(p[2]),
                    "locSrv.qx": float(q[0]), "locSrv.qy": float(q[1]), "locSrv.qz": float(q[2]),
                    "locSrv.qw": float(q[3])}
        if group == "locSrvZ":
            return {"locSrvZ.tick": float(int(est.s.ext_tick[i]) & 0xFFFF)}
        if group == "ctrltarget":
            return self.control.targets(i)
        if group == "posCtl":
            vt = self.control.s.vel_target[i]
            return {"posCtl.targetVX": float(vt[0]), "posCtl.targetVY": float(vt[1]), "posCtl.targetVZ": float(vt[2])}
        return {}
