"""Onboard flight of every vehicle: the estimator and the position controller, hooked into the world tick.

One object so that the world needs a single call per tick (``step``) and a single place to ask for
the log variables of these stages (``readings``). It runs before the stabilizer's attitude and rate
controllers, whose setpoint row it writes for vehicles flown by generic setpoints.
"""
from __future__ import annotations

import math
from typing import Dict, List, Optional, Sequence

import numpy as np

from crazyflie_driver.crtp.quaternion import compress_quaternion
from crazyflie_driver.sim.onboard.body import BodyRows
from crazyflie_driver.sim.onboard.estimator import DEFAULTS as ESTIMATOR_DEFAULTS
from crazyflie_driver.sim.onboard.estimator import PREDICT_EVERY, Estimator, ImuSource
from crazyflie_driver.sim.onboard.high_level import DEFAULT_VELOCITY, EBUSY, HL_RATE_EVERY, HighLevelPlans
from crazyflie_driver.sim.onboard.mellinger import ATTITUDE_DEFAULTS as MELLINGER_ATTITUDE_DEFAULTS
from crazyflie_driver.sim.onboard.mellinger import MELLINGER_EVERY
from crazyflie_driver.sim.onboard.planner import IDLE, Evaluation, Piece, Plan
from crazyflie_driver.sim.onboard.position_control import (
    CONTROLLER_PID,
    M_X,
    M_Y,
    NULL_MODES,
    POSITION_EVERY,
    PRIORITY_CRTP,
    PRIORITY_HIGH_LEVEL,
    PositionControl,
)
from crazyflie_driver.sim.onboard.position_control import default_params as control_defaults
from crazyflie_driver.sim.onboard.setpoint import MODE_DISABLE, OnboardSetpoint
from crazyflie_driver.sim.onboard.stabilizer import firmware_attitude
from crazyflie_driver.sim.vehicle_rows import Vector

assert PREDICT_EVERY % MELLINGER_EVERY == 0 and HL_RATE_EVERY % MELLINGER_EVERY == 0   # see OnboardFlight.step
GROUPS = ("stateEstimate", "stateEstimateZ", "locSrv", "locSrvZ", "ctrltarget", "posCtl")


def default_params() -> Dict[str, float]:
    """Parameters of the onboard estimator and position controller with the firmware's defaults."""
    out = dict(ESTIMATOR_DEFAULTS)
    out.update(control_defaults())
    out.update(MELLINGER_ATTITUDE_DEFAULTS)          # kept in the stabilizer's rows, where the law runs
    out["hlCommander.groupmask"] = 0.0
    out["hlCommander.vtoff"] = DEFAULT_VELOCITY
    out["hlCommander.vland"] = DEFAULT_VELOCITY
    return out


class OnboardFlight:
    """Estimator + position controller rows, one per vehicle (called under the world lock)."""

    def __init__(self) -> None:
        self.estimator = Estimator()
        self.control = PositionControl()
        self.hl = HighLevelPlans()

    @property
    def models(self):
        """The row containers the world adds to and deletes from."""
        return self.estimator.models + (self.control.s, self.hl)

    def carried(self, i: int) -> None:
        """Row ``i`` was put somewhere by hand (a teleport of the room): its IMU filter reads the new
        rest state from the next sample instead of ringing from a jump no sensor could see."""
        self.estimator.s.acc_settled[i] = False

    def add(self, rng: np.random.Generator, position: Vector, now: float) -> None:
        self.estimator.add(rng, position, now)
        self.control.add()
        self.hl.append_row()

    def boot(self, i: int, truth: Sequence[float], now: float) -> None:
        self.estimator.boot(i, truth, now)
        self.control.boot(i)
        self.hl.boot(i)

    def set_param(self, i: int, name: str, value: float, truth: Sequence[float], now: float) -> bool:
        if name == "hlCommander.groupmask":
            self.hl.group_mask[i] = int(value) & 0xFF
            return True
        if name in ("hlCommander.vtoff", "hlCommander.vland"):
            velocities = self.hl.takeoff_velocity if name.endswith("vtoff") else self.hl.landing_velocity
            velocities[i] = float(value)
            return True
        return self.estimator.set_param(i, name, value, truth, now) or self.control.set_param(i, name, value)

    # --- inputs from the radio -------------------------------------------------------------------
    def setpoint(self, i: int, sp: OnboardSetpoint) -> None:
        """A low-level (CRTP) setpoint: it takes the priority and stops the high-level planner."""
        self.control.set_setpoint(i, sp)
        self.control.s.priority[i] = PRIORITY_CRTP
        self.hl.preempt(i)

    def release(self, i: int) -> None:
        """The legacy RPYT path drives this vehicle (also a low-level setpoint)."""
        self.control.release(i)
        self.control.s.priority[i] = PRIORITY_CRTP
        self.hl.preempt(i)

    def notify_stop(self, i: int, stab, now: float) -> None:
        """Notify-setpoints-stop: the high-level commander gets the priority back. At its next tick
        (100 Hz) it sends its plan's setpoint, or, idle, the null setpoint that stops the motors, or,
        disabled, nothing (the low-level setpoint left then ages into the watchdog)."""
        self.control.s.priority[i] = PRIORITY_HIGH_LEVEL
        self.hl.relax(i)

    def _null_setpoint(self, i: int, stab, now: float) -> None:
        self.control.release(i, NULL_MODES)
        stab.sp[i] = 0.0
        stab.sp_time[i] = now

    # --- the high-level commander ------------------------------------------------------------------
    def start_state(self, i: int, bodies: BodyRows, stab, ground_asl: float, now: float) -> Evaluation:
        """Where a new plan starts: the running plan now, else the state estimate at rest."""
        current = self.hl.current(i, now)
        if current is not None:
            return current
        pos = self.estimator.position(i, bodies.position[i], ground_asl)       # idle or disabled: the estimate
        vel = self.estimator.velocity(i, bodies.velocity[i])
        return Evaluation(np.asarray(pos, dtype=float), np.asarray(vel, dtype=float), np.zeros(3),
                          math.radians(float(stab.attitude[i, 2])), 0.0)

    def high_level(self, i: int, command: str, args: Dict, bodies: BodyRows, stab, ground_asl: float,
                   now: float) -> int:
        """One port-8 command for row i; returns the firmware's result code."""
        hl = self.hl
        if command == "set_group_mask":
            hl.group_mask[i] = int(args["mask"]) & 0xFF
            return 0
        if not hl.in_group(i, int(args.get("mask", 0))):
            return 0
        if command == "stop":
            hl.stop(i)
            return 0
        if stab.lock[i] != 0:
            return EBUSY
        start = self.start_state(i, bodies, stab, ground_asl, now)
        yaw = start.yaw if args.get("use_current_yaw") else float(args.get("yaw", 0.0))
        duration = float(args.get("duration", 0.0))
        if command in ("takeoff", "land"):
            return self._vertical(i, command, args, start, yaw, duration, now)
        if command == "go_to":
            return hl.go_to(i, start, args["goal"], float(args["yaw"]), duration, bool(args.get("relative")),
                            bool(args.get("linear")), now)
        if command == "spiral":
            return hl.spiral(i, start, bool(args["sideways"]), bool(args["clockwise"]), float(args["angle"]),
                             float(args["r0"]), float(args["rf"]), float(args["ascent"]), duration, now)
        if command == "start_trajectory":
            pieces = [Piece(float(d), np.asarray(c, dtype=float)) for d, c in args["pieces"]]
            return hl.start_trajectory(i, start, pieces, float(args.get("timescale", 1.0)),
                                       bool(args.get("reversed")), bool(args.get("relative")),
                                       bool(args.get("relative_yaw")), now)
        raise ValueError("unknown high-level command %r" % (command,))

    def _vertical(self, i: int, command: str, args: Dict, start: Evaluation, yaw: float, duration: float,
                  now: float) -> int:
        """Takeoff or land (v1 or v2): the goal height, relative to the start where asked; a velocity
        (v2 with velocity, <= 0: the parameter's default) gives the duration instead."""
        hl = self.hl
        takeoff = command == "takeoff"
        height = float(args["height"])
        if args.get("relative"):
            height = start.pos[2] + height if takeoff else start.pos[2] - height
        velocity = args.get("velocity")
        if velocity is not None:
            default = hl.takeoff_velocity[i] if takeoff else hl.landing_velocity[i]
            v = float(velocity) if float(velocity) > 0 else default
            with np.errstate(divide="ignore", invalid="ignore"):
                duration = float(np.float64(abs(height - start.pos[2])) / v)
        fn = hl.takeoff if takeoff else hl.land
        return fn(i, start, height, yaw, duration, now)

    def _high_level_tick(self, now: float, stab) -> bool:
        """The planners' 100 Hz tick: each evaluates its plan (also while a low-level setpoint holds the
        priority: a landing still ends, a NaN plan still disables it); its setpoint counts only with
        the priority. True when it wrote a setpoint."""
        rows: List[int] = self.hl.due()
        if not rows:
            return False
        hl, priority = self.hl, self.control.s.priority
        wrote = False
        for i in rows:
            if stab.lock[i] != 0:           # the supervisor cannot fly: the plan is stopped
                hl.plans[i] = Plan()
                hl.null_due[i] = False
                continue
            sp = hl.setpoint(i, now)
            if priority[i] != PRIORITY_HIGH_LEVEL:
                continue                    # rejected: a low-level setpoint holds the priority
            if sp is not None:
                self.control.set_setpoint(i, sp)
                stab.sp_time[i] = now
                wrote = True
            elif hl.plans[i].state == IDLE:
                self._null_setpoint(i, stab, now)
                wrote = True
        return wrote

    def measure(self, i: int, position: Sequence[float], quaternion: Optional[Sequence[float]],
                bodies: BodyRows, now: float) -> bool:
        return self.estimator.measure(i, position, quaternion, bodies.position[i].copy(), now)

    # --- the tick ------------------------------------------------------------------------------------
    def step(self, tick: int, now: float, bodies: BodyRows, stab, ground_asl: float,
             imu: Optional[ImuSource] = None) -> bool:
        """Before the stabilizer's tick: estimator loop (``imu`` gives its readings), then (100 Hz) the
        position controller.

        Returns True when it wrote new setpoints into the stabilizer's rows."""
        wrote = False
        if tick % MELLINGER_EVERY == 0:     # every stage here runs on even ticks only, but the mode check
            self.estimator.update(tick, now, stab.thrust, bodies, MELLINGER_EVERY, imu)
            wrote = self._high_level_tick(now, stab) if tick % HL_RATE_EVERY == 0 else False
        if self.control.pending:            # every tick, before the controllers, as the firmware's
            wrote = self._new_setpoints(tick, bodies, stab, ground_asl) or wrote
        if tick % MELLINGER_EVERY:
            return wrote
        est = self.estimator

        def row_inputs(i: int):
            q0, q1, q2, q3 = bodies.quaternion[i].tolist()
            body_z = (2.0 * (q0 * q2 + q3 * q1), 2.0 * (q1 * q2 - q3 * q0), 1.0 - 2.0 * (q0 * q0 + q1 * q1))
            yaw = math.degrees(math.atan2(2.0 * (q3 * q2 + q0 * q1), 1.0 - 2.0 * (q1 * q1 + q2 * q2)))
            pos, vel = est.row_estimate(i, bodies.position[i].tolist(), bodies.velocity[i].tolist(), ground_asl)
            return pos, vel, yaw, bool(stab.thrust[i] > 0.0), body_z

        def all_inputs():
            q = bodies.quaternion
            body_z = np.stack([2.0 * (q[:, 0] * q[:, 2] + q[:, 3] * q[:, 1]),
                               2.0 * (q[:, 1] * q[:, 2] - q[:, 3] * q[:, 0]),
                               1.0 - 2.0 * (q[:, 0] ** 2 + q[:, 1] ** 2)], axis=1)
            yaw = np.degrees(np.arctan2(2.0 * (q[:, 3] * q[:, 2] + q[:, 0] * q[:, 1]),
                                        1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2)))
            return (est.positions(bodies.position, ground_asl), est.velocities(bodies.velocity),
                    yaw, stab.thrust > 0.0, body_z)

        # the yaw is the current one (the stabilizer's attitude row is from its last step)
        rows = self.control.update(tick, row_inputs, all_inputs, stab.sp, stab.yaw_sp, stab.mel_axes,
                                   stab.mel_rate_sp)
        if not rows:
            return wrote
        pid, mel = self.control.rows()
        if mel:
            stab.moment_law[mel] = True     # the Mellinger attitude law flies these rows
        if pid and tick % POSITION_EVERY == 0:
            stab.moment_law[pid] = False
        if len(rows) > 1:
            stab.thrust_locked[rows] = False
            stab.generic[rows] = True
        else:
            stab.thrust_locked[rows[0]] = False
            stab.generic[rows[0]] = True
        return True

    def _new_setpoints(self, tick: int, bodies: BodyRows, stab, ground_asl: float) -> bool:
        """Setpoints that came since the last tick, for the rows the PID controller flies. When the
        setpoint's modes differ from the last tick's it re-initialises all its PIDs (position and
        velocity here, attitude and rate in the stabilizer's rows) and its desired roll and pitch become
        the current attitude until its position controller's next step (when x and y are not
        disabled). Between position steps, the parts it takes at 500 Hz (yaw; roll, pitch and thrust
        of disabled axes) are written at once. True when it changed a stabilizer row."""
        control = self.control
        pending, changed = control.take_pending()
        s = control.s
        wrote = False
        if tick % POSITION_EVERY:
            for i in pending:
                if s.active[i] and s.controller[i] == CONTROLLER_PID:
                    control.write_direct(i, stab.sp, stab.yaw_sp)
                    stab.thrust_locked[i] = False
                    stab.generic[i] = True
                    wrote = True
        rows = [i for i in changed if s.controller[i] == CONTROLLER_PID]
        if not rows:
            return wrote
        attitude = firmware_attitude(bodies.quaternion[rows])
        est = self.estimator
        positions = np.array([est.row_estimate(i, bodies.position[i].tolist(), bodies.velocity[i].tolist(),
                                               ground_asl)[0] for i in rows], dtype=float)
        control.reset_pids(rows, positions)
        stab.reset_pids(rows, attitude)
        for k, i in enumerate(rows):
            modes = s.modes[i]
            if s.active[i] and modes[M_X] != MODE_DISABLE and modes[M_Y] != MODE_DISABLE:
                stab.sp[i, 0:2] = attitude[k, 0:2]
        return True

    # --- log variables ---------------------------------------------------------------------------------
    def readings(self, i: int, group: str, bodies: BodyRows, attitude_deg: np.ndarray,
                 ground_asl: float) -> Dict[str, float]:
        est = self.estimator
        if group in ("stateEstimate", "stateEstimateZ"):
            p = est.position(i, bodies.position[i], ground_asl)
            v = est.velocity(i, bodies.velocity[i])
            q = bodies.quaternion[i]
            if group == "stateEstimateZ":
                out = {"stateEstimateZ.%s" % n: float(int(round(val * 1000.0)))
                       for n, val in zip(("x", "y", "z", "vx", "vy", "vz"), list(p) + list(v))}
                out["stateEstimateZ.quat"] = float(compress_quaternion(q))     # the compressed attitude
                return out
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
