"""The firmware's PID position controller (``stabilizer.controller`` 1) for every vehicle (numpy rows).

Runs at the firmware's 100 Hz position rate on the onboard estimate: a position PID (absolute
axes only; x/y in the yaw-rotated body frame) gives a velocity setpoint, a velocity PID gives
roll/pitch (legacy signs: pitch = -vx output, roll = -vy output) and thrust
(1000·vz output + thrustBase, floored at thrustMin). Axes whose mode is disabled take roll,
pitch or thrust straight from the setpoint. The result feeds the attitude and rate controllers
of ``stabilizer.py`` through their setpoint row, so those stay exactly as they are. Facts and
gains: docs/simulation.md ("Onboard position control").
"""
from __future__ import annotations

from typing import Dict, Tuple

import numpy as np

from crazyflie_driver.sim.firmware.setpoint_decode import MODE_ABS, MODE_DISABLE, MODE_VELOCITY, Setpoint
from crazyflie_driver.sim.world import mellinger as _mel
from crazyflie_driver.sim.world.vehicle_rows import Rows

POSITION_EVERY = 10                 # ticks: the position controller runs at 100 Hz
DT = POSITION_EVERY * 1e-3          # s
THRUST_SCALE = 1000.0               # counts per unit of velocity-PID z output
INTEGRATION_LIMIT = 5000.0          # the firmware's default PID integral limit
LIMIT_OVERHEAD = 1.10               # output limits are the nominal limits × this
Z_VEL_MAX_FLOOR = 0.5               # m/s, the z position-PID limit is never below this (× overhead)
VZ_OUTPUT_LIMIT = 65535 / 2 / THRUST_SCALE
UINT16_MAX = 65535.0
M_X, M_Y, M_Z, M_ROLL, M_PITCH, M_YAW, M_QUAT = range(7)
PRIORITY_HIGH_LEVEL, PRIORITY_CRTP = 1, 2
CONTROLLER_PID, CONTROLLER_MELLINGER = 1, 2
TERMS = ("Kp", "Ki", "Kd")

# current firmware defaults: gains (kp, ki, kd, kff) per axis, then limits and thrust
POS_GAINS = ((2.0, 0.0, 0.0, 0.0), (2.0, 0.0, 0.0, 0.0), (2.0, 0.5, 0.0, 0.0))
VEL_GAINS = ((25.0, 1.0, 0.0, 0.0), (25.0, 1.0, 0.0, 0.0), (25.0, 15.0, 0.0, 0.0))
THRUST_BASE = 36000.0
THRUST_MIN = 20000.0
RP_LIMIT_DEG = 20.0
VEL_MAX = 1.0                       # m/s per axis


def default_params() -> Dict[str, float]:
    """``posCtlPid.*`` and ``velCtlPid.*`` with the firmware's names and defaults."""
    out: Dict[str, float] = {}
    for axis, gains in zip("xyz", POS_GAINS):
        for term, value in zip(TERMS + ("Kff",), gains):
            out["posCtlPid.%s%s" % (axis, term)] = value
    for axis, gains in zip(("vx", "vy", "vz"), VEL_GAINS):
        for term, value in zip(TERMS + ("KFF",), gains):
            out["velCtlPid.%s%s" % (axis, term)] = value
    out.update({"posCtlPid.thrustBase": THRUST_BASE, "posCtlPid.thrustMin": THRUST_MIN,
                "posCtlPid.rLimit": RP_LIMIT_DEG, "posCtlPid.pLimit": RP_LIMIT_DEG,
                "posCtlPid.xVelMax": VEL_MAX, "posCtlPid.yVelMax": VEL_MAX, "posCtlPid.zVelMax": VEL_MAX})
    out.update(_mel.DEFAULTS)
    return out


_PARAMS = default_params()


def _param_slot(name: str) -> Tuple[str, Tuple[int, ...]]:
    """Parameter name -> (field, index within the row) of ``PositionStates``."""
    group, _, field = name.partition(".")
    if group == "ctrlMel":
        return "mel_gains", (_mel.GAIN_ORDER.index(name),)
    if group == "posCtlPid":
        if field[:1] in "xyz" and field[1:] in ("Kp", "Ki", "Kd", "Kff"):
            return "pos_gains", ("xyz".index(field[0]), ("Kp", "Ki", "Kd", "Kff").index(field[1:]))
        simple = {"thrustBase": ("thrust_base", ()), "thrustMin": ("thrust_min", ()),
                  "rLimit": ("rp_limit", (0,)), "pLimit": ("rp_limit", (1,)),
                  "xVelMax": ("vel_max", (0,)), "yVelMax": ("vel_max", (1,)), "zVelMax": ("vel_max", (2,))}
        return simple[field]
    axis, term = field[:2], field[2:]
    return "vel_gains", (("vx", "vy", "vz").index(axis), ("Kp", "Ki", "Kd", "KFF").index(term))


class PositionStates(Rows):
    FIELDS = {
        "active": ((), bool),             # a generic (or high-level) setpoint drives this vehicle
        "priority": ((), np.int8),        # commander priority: 1 high-level, 2 low-level (CRTP)
        "kind": ((), np.int8),            # setpoint type that set the modes
        "modes": ((7,), np.int8),         # x, y, z, roll, pitch, yaw, quat
        "prev_modes": ((7,), np.int8),
        "pos": ((3,), float),
        "vel": ((3,), float),
        "acc": ((3,), float),
        "att": ((3,), float),             # roll, pitch, yaw (deg)
        "rate": ((3,), float),            # roll, pitch, yaw rate (deg/s, yaw counter-clockwise)
        "quat": ((4,), float),
        "thrust_sp": ((), float),
        "vbody": ((), bool),
        "pos_gains": ((3, 4), float),
        "vel_gains": ((3, 4), float),
        "thrust_base": ((), float),
        "thrust_min": ((), float),
        "rp_limit": ((2,), float),
        "vel_max": ((3,), float),
        "pos_integ": ((3,), float),
        "pos_prev": ((3,), float),
        "vel_integ": ((3,), float),
        "vel_prev": ((3,), float),
        "vel_target": ((3,), float),      # velocity setpoint of the velocity PID (body x, y; world z)
        "out": ((3,), float),             # roll, pitch (deg), thrust (counts)
        "controller": ((), np.int8),      # stabilizer.controller as it runs: 1 PID, 2 Mellinger
        "mel_gains": ((len(_mel.GAIN_ORDER),), float),
        "mel_integ": ((3,), float),
    }


class PositionControl:
    """Generic setpoints of all vehicles and the PID position controller they drive."""

    def __init__(self) -> None:
        self.s = PositionStates()

    def add(self) -> int:
        i = self.s.append_row()
        self.boot(i)
        return i

    def boot(self, i: int) -> None:
        s = self.s
        for name in s.FIELDS:
            getattr(s, name)[i] = 0
        s.quat[i] = (0.0, 0.0, 0.0, 1.0)
        s.priority[i] = PRIORITY_HIGH_LEVEL      # at boot the high-level commander owns the setpoint
        s.pos_gains[i] = POS_GAINS
        s.vel_gains[i] = VEL_GAINS
        s.thrust_base[i] = THRUST_BASE
        s.thrust_min[i] = THRUST_MIN
        s.rp_limit[i] = RP_LIMIT_DEG
        s.vel_max[i] = VEL_MAX
        s.controller[i] = CONTROLLER_PID
        s.mel_gains[i] = [_mel.DEFAULTS[n] for n in _mel.GAIN_ORDER]

    def set_param(self, i: int, name: str, value: float) -> bool:
        if name == "stabilizer.controller":       # 0 (auto) and the controllers not simulated run PID
            self.s.controller[i] = CONTROLLER_MELLINGER if int(value) == CONTROLLER_MELLINGER else CONTROLLER_PID
            return True
        if name not in _PARAMS:
            return False
        field, index = _param_slot(name)
        getattr(self.s, field)[(i,) + index] = float(value)
        return True

    # --- setpoints (under the world lock) ---------------------------------------------------------
    def set_setpoint(self, i: int, sp: Setpoint) -> None:
        s = self.s
        s.active[i] = True
        s.kind[i] = sp.kind
        s.modes[i] = (sp.mode_x, sp.mode_y, sp.mode_z, sp.mode_roll, sp.mode_pitch, sp.mode_yaw, sp.mode_quat)
        s.pos[i], s.vel[i], s.acc[i] = sp.position, sp.velocity, sp.acceleration
        s.att[i], s.rate[i], s.quat[i] = sp.attitude, sp.attitude_rate, sp.quaternion
        s.thrust_sp[i] = sp.thrust
        s.vbody[i] = sp.velocity_body

    def release(self, i: int) -> None:
        """The legacy path (RPYT) drives this vehicle again."""
        self.s.active[i] = False

    # --- the tick -----------------------------------------------------------------------------------
    def update(self, tick: int, est_pos: np.ndarray, est_vel: np.ndarray, yaw_deg: np.ndarray,
               stab_sp: np.ndarray, stab_yaw_sp: np.ndarray, thrust_on: np.ndarray, body_z: np.ndarray) -> bool:
        """New roll, pitch, yaw and thrust setpoints for the active rows of the stabilizer: PID rows at
        100 Hz, Mellinger rows at 500 Hz. Returns whether it wrote anything.

        ``stab_sp`` (N,4: roll, pitch, yaw rate as the wire has it, thrust) and ``stab_yaw_sp`` (N,)
        are the stabilizer's own setpoint arrays, written in place. ``thrust_on`` (N,) is False
        where the motors were off at the last tick (the firmware then resets the PIDs); ``body_z``
        (N,3) the current body z axes.
        """
        s = self.s
        if tick % _mel.MELLINGER_EVERY or not s.active.any():
            return False
        wrote = False
        mel = s.active & (s.controller == CONTROLLER_MELLINGER)
        if mel.any():
            rows = np.flatnonzero(mel)
            s.mel_integ[rows[~thrust_on[rows]]] = 0.0
            modes = s.modes[rows]
            yaw_des = np.radians(self._yaw_target(rows, yaw_deg[rows], _mel.DT))
            roll, pitch, thrust, s.mel_integ[rows] = _mel.force_and_attitude(
                s.mel_gains[rows], s.mel_integ[rows], est_pos[rows], est_vel[rows], s.pos[rows], s.vel[rows],
                s.acc[rows], s.att[rows], modes[:, M_X] == MODE_ABS, modes[:, M_Z] == MODE_ABS, yaw_des, body_z[rows])
            self._write(rows, roll, pitch, thrust, stab_sp, stab_yaw_sp)
            wrote = True
        if tick % POSITION_EVERY == 0:
            pid = s.active & (s.controller != CONTROLLER_MELLINGER)
            if pid.any():
                self._update_pid(np.flatnonzero(pid), est_pos, est_vel, yaw_deg, stab_sp, stab_yaw_sp, thrust_on)
                wrote = True
        return wrote

    def _yaw_target(self, rows: np.ndarray, yaw_now_deg: np.ndarray, dt: float) -> np.ndarray:
        """Desired yaw (deg): the setpoint's angle, its quaternion's yaw, or now + rate·dt."""
        s = self.s
        modes = s.modes[rows]
        q = s.quat[rows]
        quat_yaw = np.degrees(np.arctan2(2.0 * (q[:, 3] * q[:, 2] + q[:, 0] * q[:, 1]),
                                         1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2)))
        target = np.where(modes[:, M_QUAT] == MODE_ABS, quat_yaw, yaw_now_deg + s.rate[rows, 2] * dt)
        return np.where(modes[:, M_YAW] == MODE_ABS, s.att[rows, 2], target)

    def _update_pid(self, rows: np.ndarray, est_pos: np.ndarray, est_vel: np.ndarray, yaw_deg: np.ndarray,
                    stab_sp: np.ndarray, stab_yaw_sp: np.ndarray, thrust_on: np.ndarray) -> None:
        s = self.s
        modes = s.modes[rows]
        changed = (modes != s.prev_modes[rows]).any(axis=1) | ~thrust_on[rows]
        if changed.any():
            reset = rows[changed]
            s.pos_integ[reset] = 0.0
            s.pos_prev[reset] = 0.0
            s.vel_integ[reset] = 0.0
            s.vel_prev[reset] = 0.0
        s.prev_modes[rows] = modes

        yaw = np.radians(yaw_deg[rows])
        c, sn = np.cos(yaw), np.sin(yaw)
        p, v = est_pos[rows], est_vel[rows]
        sp_p, sp_v = s.pos[rows], s.vel[rows]
        absolute = modes[:, :3] == MODE_ABS
        # position PID (absolute axes), x/y in the yaw-rotated frame
        desired = np.stack([sp_p[:, 0] * c + sp_p[:, 1] * sn, -sp_p[:, 0] * sn + sp_p[:, 1] * c, sp_p[:, 2]], axis=1)
        measured = np.stack([p[:, 0] * c + p[:, 1] * sn, -p[:, 0] * sn + p[:, 1] * c, p[:, 2]], axis=1)
        vel_limit = s.vel_max[rows].copy()
        vel_limit[:, 2] = np.maximum(vel_limit[:, 2], Z_VEL_MAX_FLOOR)
        pos_out = self._pid(rows, desired, measured, s.pos_gains[rows], "pos", vel_limit * LIMIT_OVERHEAD, absolute)
        # velocity setpoint: the position PID output, or the setpoint's own velocity
        world_v = np.stack([sp_v[:, 0] * c + sp_v[:, 1] * sn, sp_v[:, 1] * c - sp_v[:, 0] * sn, sp_v[:, 2]], axis=1)
        vel_sp = np.where(s.vbody[rows, None], sp_v, world_v)
        vel_sp = np.where(absolute, pos_out, vel_sp)
        body_v = np.stack([v[:, 0] * c + v[:, 1] * sn, -v[:, 0] * sn + v[:, 1] * c, v[:, 2]], axis=1)
        limits = np.empty((len(rows), 3))
        limits[:, 0] = s.rp_limit[rows, 1] * LIMIT_OVERHEAD
        limits[:, 1] = s.rp_limit[rows, 0] * LIMIT_OVERHEAD
        limits[:, 2] = VZ_OUTPUT_LIMIT
        vel_out = self._pid(rows, vel_sp, body_v, s.vel_gains[rows], "vel", limits, np.ones_like(absolute))
        s.vel_target[rows] = vel_sp

        pitch = np.minimum(np.maximum(-vel_out[:, 0], -s.rp_limit[rows, 1]), s.rp_limit[rows, 1])
        roll = np.minimum(np.maximum(-vel_out[:, 1], -s.rp_limit[rows, 0]), s.rp_limit[rows, 0])
        thrust = np.minimum(np.maximum(np.maximum(vel_out[:, 2] * THRUST_SCALE + s.thrust_base[rows],
                                                s.thrust_min[rows]), 0.0), UINT16_MAX)
        # disabled axes: attitude and thrust straight from the setpoint
        xy_off = (modes[:, M_X] == MODE_DISABLE) | (modes[:, M_Y] == MODE_DISABLE)
        roll = np.where(xy_off, s.att[rows, 0], roll)
        pitch = np.where(xy_off, s.att[rows, 1], pitch)
        thrust = np.where(modes[:, M_Z] == MODE_DISABLE, s.thrust_sp[rows], thrust)
        self._write(rows, roll, pitch, thrust, stab_sp, stab_yaw_sp)

    def _write(self, rows: np.ndarray, roll: np.ndarray, pitch: np.ndarray, thrust: np.ndarray,
               stab_sp: np.ndarray, stab_yaw_sp: np.ndarray) -> None:
        """Roll, pitch (deg), thrust and the yaw setpoint of ``rows`` into the stabilizer's setpoint row."""
        s = self.s
        modes = s.modes[rows]
        s.out[rows, 0], s.out[rows, 1], s.out[rows, 2] = roll, pitch, thrust
        stab_sp[rows, 0] = roll
        stab_sp[rows, 1] = pitch
        stab_sp[rows, 3] = thrust
        # yaw: integrated rate (the stabilizer integrates -sp[2]), absolute angle, or the quaternion's yaw
        yaw_mode = modes[:, M_YAW]
        stab_sp[rows, 2] = np.where(yaw_mode == MODE_VELOCITY, -s.rate[rows, 2], 0.0)
        target = np.where(yaw_mode == MODE_ABS, s.att[rows, 2], np.nan)
        q = s.quat[rows]
        quat_yaw = np.degrees(np.arctan2(2.0 * (q[:, 3] * q[:, 2] + q[:, 0] * q[:, 1]),
                                         1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2)))
        target = np.where((yaw_mode != MODE_ABS) & (modes[:, M_QUAT] == MODE_ABS), quat_yaw, target)
        fixed = ~np.isnan(target)
        if fixed.any():
            stab_yaw_sp[rows[fixed]] = (target[fixed] + 180.0) % 360.0 - 180.0

    def _pid(self, rows: np.ndarray, desired: np.ndarray, measured: np.ndarray, gains: np.ndarray, which: str,
             limit: np.ndarray, run: np.ndarray) -> np.ndarray:
        """The firmware's PID update (D on error, integral limit, output limit) where ``run`` is True."""
        s = self.s
        integ_name, prev_name = which + "_integ", which + "_prev"
        integ_all, prev_all = getattr(s, integ_name), getattr(s, prev_name)
        err = desired - measured
        integ = np.minimum(np.maximum(integ_all[rows] + err * DT, -INTEGRATION_LIMIT), INTEGRATION_LIMIT)
        deriv = (err - prev_all[rows]) / DT
        out = gains[:, :, 0] * err + gains[:, :, 1] * integ + gains[:, :, 2] * deriv + gains[:, :, 3] * desired
        out = np.minimum(np.maximum(out, -limit), limit)
        integ_all[rows] = np.where(run, integ, integ_all[rows])
        prev_all[rows] = np.where(run, err, prev_all[rows])
        return out

    def targets(self, i: int) -> Dict[str, float]:
        """``ctrltarget.*`` log variables of row ``i``."""
        s = self.s
        names = ("x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az")
        values = list(s.pos[i]) + list(s.vel[i]) + list(s.acc[i])
        return {"ctrltarget." + n: float(val) for n, val in zip(names, values)}
