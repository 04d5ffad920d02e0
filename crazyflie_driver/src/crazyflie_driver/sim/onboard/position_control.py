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

import math
from typing import Callable, Dict, List, Sequence, Set, Tuple

import numpy as np

from crazyflie_driver.sim.onboard import mellinger as _mel
from crazyflie_driver.sim.onboard.scalar import clamp, maximum, safe_cos, safe_sin
from crazyflie_driver.sim.onboard.setpoint import MODE_ABS, MODE_DISABLE, MODE_VELOCITY, OnboardSetpoint
from crazyflie_driver.sim.vehicle_rows import Rows

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
# the modes of a legacy RPYT setpoint (x, y, z off; roll, pitch angles; yaw rate) and of the null setpoint
RPYT_MODES = (MODE_DISABLE, MODE_DISABLE, MODE_DISABLE, MODE_ABS, MODE_ABS, MODE_VELOCITY, MODE_DISABLE)
NULL_MODES = (MODE_DISABLE,) * 7
CONTROLLER_PID, CONTROLLER_MELLINGER = 1, 2
TERMS = ("Kp", "Ki", "Kd")
SCALAR_ROWS = 3                     # up to this many rows of a controller: Python floats, row by row (faster
                                    # than numpy's per-call cost); more: one numpy pass over all of them

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
# one row's estimated position and velocity (m, m/s), yaw (deg), motors running, body z axis
RowInputs = Tuple[Sequence[float], Sequence[float], float, bool, Sequence[float]]
# the same for all rows: (N,3), (N,3), (N,), (N,) bool, (N,3)
AllInputs = Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


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
        "prev_modes": ((7,), np.int8),    # the modes at the last tick (a change resets every PID)
        "pos": ((3,), float),
        "vel": ((3,), float),
        "acc": ((3,), float),
        "att": ((3,), float),             # roll, pitch, yaw (deg)
        "rate": ((3,), float),            # roll, pitch, yaw rate (deg/s, yaw counter-clockwise)
        "quat": ((4,), float),
        "quat_yaw": ((), float),          # yaw of the setpoint's quaternion (deg)
        "thrust_sp": ((), float),
        "vbody": ((), bool),
        "pos_gains": ((3, 4), float),
        "vel_gains": ((3, 4), float),
        "thrust_base": ((), float),
        "thrust_min": ((), float),
        "rp_limit": ((2,), float),
        "vel_max": ((3,), float),
        "pos_integ": ((3,), float),
        "pos_prev": ((3,), float),        # previous measurement (the derivative is on the measurement)
        "vel_integ": ((3,), float),
        "vel_prev": ((3,), float),
        "vel_target": ((3,), float),      # velocity setpoint of the velocity PID (body x, y; world z)
        "out": ((3,), float),             # roll, pitch (deg), thrust (counts)
        "controller": ((), np.int8),      # stabilizer.controller as it runs: 1 PID, 2 Mellinger
        "mel_gains": ((len(_mel.GAIN_ORDER),), float),
        "mel_integ": ((3,), float),
    }

    # The columns (one row per vehicle; shapes and dtypes in FIELDS), declared for the type checker.
    active: np.ndarray
    priority: np.ndarray
    kind: np.ndarray
    modes: np.ndarray
    prev_modes: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    att: np.ndarray
    rate: np.ndarray
    quat: np.ndarray
    quat_yaw: np.ndarray
    thrust_sp: np.ndarray
    vbody: np.ndarray
    pos_gains: np.ndarray
    vel_gains: np.ndarray
    thrust_base: np.ndarray
    thrust_min: np.ndarray
    rp_limit: np.ndarray
    vel_max: np.ndarray
    pos_integ: np.ndarray
    pos_prev: np.ndarray
    vel_integ: np.ndarray
    vel_prev: np.ndarray
    vel_target: np.ndarray
    out: np.ndarray
    controller: np.ndarray
    mel_gains: np.ndarray
    mel_integ: np.ndarray

    def __init__(self) -> None:
        super().__init__()
        self.version = 0                  # changes whenever the set of rows or their roles may have changed

    def append_row(self, **values) -> int:
        self.version += 1
        return super().append_row(**values)

    def delete_row(self, index: int) -> None:
        self.version += 1
        super().delete_row(index)


class PositionControl:
    """Generic setpoints of all vehicles and the PID position controller they drive."""

    def __init__(self) -> None:
        self.s = PositionStates()
        self._rows_version = -1
        self._rows: Tuple[List[int], List[int]] = ([], [])
        self._row_arrays: Tuple[np.ndarray, np.ndarray] = (np.zeros(0, int), np.zeros(0, int))
        self.pending: Set[int] = set()    # rows given a setpoint (and so modes) since the last tick

    def rows(self) -> Tuple[List[int], List[int]]:
        """(PID rows, Mellinger rows) among the active ones; recomputed only after a change."""
        s = self.s
        if self._rows_version != s.version:
            mel = s.controller == CONTROLLER_MELLINGER
            self._row_arrays = (np.flatnonzero(s.active & ~mel), np.flatnonzero(s.active & mel))
            self._rows = (self._row_arrays[0].tolist(), self._row_arrays[1].tolist())
            self._rows_version = s.version
        return self._rows

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
        s.version += 1

    def set_param(self, i: int, name: str, value: float) -> bool:
        if name == "stabilizer.controller":       # 0 (auto) and the controllers not simulated run PID
            self.s.controller[i] = CONTROLLER_MELLINGER if int(value) == CONTROLLER_MELLINGER else CONTROLLER_PID
            self.s.version += 1
            return True
        if name not in _PARAMS:
            return False
        field, index = _param_slot(name)
        getattr(self.s, field)[(i,) + index] = float(value)
        return True

    # --- setpoints (under the world lock) ---------------------------------------------------------
    def set_setpoint(self, i: int, sp: OnboardSetpoint) -> None:
        s = self.s
        if not s.active[i]:
            s.active[i] = True
            s.version += 1
        s.kind[i] = sp.kind
        s.modes[i] = (sp.mode_x, sp.mode_y, sp.mode_z, sp.mode_roll, sp.mode_pitch, sp.mode_yaw, sp.mode_quat)
        self.pending.add(i)
        s.pos[i], s.vel[i], s.acc[i] = sp.position, sp.velocity, sp.acceleration
        s.att[i], s.rate[i], s.quat[i] = sp.attitude, sp.attitude_rate, sp.quaternion
        x, y, z, w = sp.quaternion
        s.quat_yaw[i] = math.degrees(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))
        s.thrust_sp[i] = sp.thrust
        s.vbody[i] = sp.velocity_body

    def release(self, i: int, modes: Sequence[int] = RPYT_MODES) -> None:
        """The legacy path (RPYT, or the null setpoint with ``NULL_MODES``) drives this vehicle again;
        its setpoint modes count for the reset on a mode change."""
        s = self.s
        if s.active[i]:
            s.active[i] = False
            s.version += 1
        s.modes[i] = modes
        self.pending.add(i)

    def take_pending(self) -> Tuple[List[int], List[int]]:
        """(rows given a setpoint since the last tick, those of them whose modes differ from the last
        tick's: the firmware's PID controller then re-initialises every PID, position, velocity,
        attitude and rate). The modes are remembered for the next tick."""
        s, rows, changed = self.s, [], []
        for i in self.pending:
            if i >= len(s):
                continue
            rows.append(i)
            if s.modes[i].tolist() != s.prev_modes[i].tolist():
                s.prev_modes[i] = s.modes[i]
                changed.append(i)
        self.pending.clear()
        return rows, changed

    def write_direct(self, i: int, stab_sp: np.ndarray, stab_yaw_sp: np.ndarray) -> None:
        """What the firmware's PID controller takes from a new setpoint at its next attitude step
        (500 Hz), before its position controller's next step (100 Hz): the yaw rate or yaw angle, and
        for disabled axes roll and pitch, or thrust, straight from the setpoint."""
        s = self.s
        modes = s.modes[i].tolist()
        att = s.att[i].tolist()
        if modes[M_X] == MODE_DISABLE or modes[M_Y] == MODE_DISABLE:
            stab_sp[i, 0], stab_sp[i, 1] = att[0], att[1]
        if modes[M_Z] == MODE_DISABLE:
            stab_sp[i, 3] = s.thrust_sp[i]
        yaw_mode = modes[M_YAW]
        stab_sp[i, 2] = -s.rate[i, 2] if yaw_mode == MODE_VELOCITY else 0.0
        if yaw_mode == MODE_ABS:
            target = att[2]
        elif modes[M_QUAT] == MODE_ABS:
            target = float(s.quat_yaw[i])
        else:
            return
        if target == target:
            stab_yaw_sp[i] = (target + 180.0) % 360.0 - 180.0

    def reset_pids(self, rows: Sequence[int], positions: np.ndarray) -> None:
        """The position and velocity PIDs of ``rows`` as the firmware resets them: integrals 0, the
        position PIDs' last measurement = the estimated world position (N,3) (though they measure in
        the yaw-rotated frame), the velocity PIDs' = 0."""
        s = self.s
        s.pos_integ[rows] = 0.0
        s.pos_prev[rows] = positions
        s.vel_integ[rows] = 0.0
        s.vel_prev[rows] = 0.0

    # --- the tick -----------------------------------------------------------------------------------
    def update(self, tick: int, row_inputs: Callable[[int], RowInputs], all_inputs: Callable[[], AllInputs],
               stab_sp: np.ndarray, stab_yaw_sp: np.ndarray, mel_axes: np.ndarray,
               mel_rate_sp: np.ndarray) -> List[int]:
        """New roll, pitch, yaw and thrust setpoints for the active rows of the stabilizer: PID rows at
        100 Hz, Mellinger rows at 500 Hz. Returns the rows it wrote.

        ``stab_sp`` (N,4: roll, pitch, yaw rate as the wire has it, thrust) and ``stab_yaw_sp`` (N,)
        are the stabilizer's own setpoint arrays, written in place; so are ``mel_axes`` (N,3,3) and
        ``mel_rate_sp`` (N,3), the desired body axes and body rates the Mellinger rows hand to the
        attitude law in the stabilizer. ``row_inputs(i)`` gives one row's
        estimated position and velocity, yaw (deg), whether its motors ran at the last tick (the
        firmware resets the PIDs when they did not) and its body z axis; ``all_inputs()`` the same
        as arrays over all rows, for the numpy pass (more than ``SCALAR_ROWS`` rows of a controller).
        """
        if tick % _mel.MELLINGER_EVERY:
            return []
        pid, mel = self.rows()
        if tick % POSITION_EVERY:
            pid = []
        if not pid and not mel:
            return []
        arrays = all_inputs() if mel or len(pid) > SCALAR_ROWS else None
        if mel:
            assert arrays is not None
            self._update_mellinger(self._row_arrays[1], arrays, stab_sp, stab_yaw_sp, mel_axes, mel_rate_sp)
        if len(pid) > SCALAR_ROWS:
            assert arrays is not None
            est_pos, est_vel, yaw_deg, thrust_on, _ = arrays
            self._update_pid(self._row_arrays[0], est_pos, est_vel, yaw_deg, stab_sp, stab_yaw_sp, thrust_on)
        else:
            for i in pid:
                self._pid_row(i, row_inputs(i), stab_sp, stab_yaw_sp)
        return pid + mel if pid and mel else (pid or mel)

    def _update_mellinger(self, rows: np.ndarray, arrays: AllInputs, stab_sp: np.ndarray, stab_yaw_sp: np.ndarray,
                          mel_axes: np.ndarray, mel_rate_sp: np.ndarray) -> None:
        """The Mellinger controller's position part for ``rows`` (its attitude law runs in the stabilizer)."""
        s = self.s
        est_pos, est_vel, yaw_deg, thrust_on, body_z = arrays
        s.mel_integ[rows[~thrust_on[rows]]] = 0.0
        modes = s.modes[rows]
        yaw_now = yaw_deg[rows]
        yaw_des = np.radians(self._yaw_target(rows, yaw_now, _mel.DT))
        z_off = modes[:, M_Z] == MODE_DISABLE
        manual = (modes[:, M_ROLL] == MODE_ABS) & (modes[:, M_PITCH] == MODE_ABS) & z_off
        axes, thrust, s.mel_integ[rows] = _mel.desired_axes(
            s.mel_gains[rows], s.mel_integ[rows], est_pos[rows], est_vel[rows], s.pos[rows], s.vel[rows],
            s.acc[rows], s.att[rows], s.thrust_sp[rows], modes[:, M_X] == MODE_ABS, manual, z_off, yaw_des,
            np.radians(yaw_now), body_z[rows])
        mel_axes[rows] = axes
        mel_rate_sp[rows] = s.rate[rows]
        # the desired roll and (legacy) pitch of those axes, for the record
        roll = np.degrees(np.arctan2(axes[:, 2, 1], axes[:, 2, 2]))
        pitch = np.degrees(np.arcsin(np.minimum(np.maximum(axes[:, 2, 0], -1.0), 1.0)))
        self._write(rows, roll, pitch, thrust, stab_sp, stab_yaw_sp)

    # --- one row in Python floats (the numpy pass below, for one vehicle) -----------------------------
    def _pid_row(self, i: int, inputs: RowInputs, stab_sp: np.ndarray, stab_yaw_sp: np.ndarray) -> None:
        s = self.s
        (px, py, pz), (vx, vy, vz), yaw_deg, thrust_on, _ = inputs
        modes = s.modes[i].tolist()
        if not thrust_on:
            self.reset_pids([i], np.array([[px, py, pz]]))
        yaw = math.radians(yaw_deg)
        c, sn = safe_cos(yaw), safe_sin(yaw)
        (sx, sy, sz), (svx, svy, svz) = s.pos[i].tolist(), s.vel[i].tolist()
        absolute = (modes[M_X] == MODE_ABS, modes[M_Y] == MODE_ABS, modes[M_Z] == MODE_ABS)
        # position PID (absolute axes), x/y in the yaw-rotated frame
        desired = (sx * c + sy * sn, -sx * sn + sy * c, sz)
        measured = (px * c + py * sn, -px * sn + py * c, pz)
        vmax = s.vel_max[i].tolist()
        limits = (vmax[0] * LIMIT_OVERHEAD, vmax[1] * LIMIT_OVERHEAD,
                  maximum(vmax[2], Z_VEL_MAX_FLOOR) * LIMIT_OVERHEAD)
        pos_out = _pid_step_row(desired, measured, s.pos_gains[i].tolist(), s.pos_integ, s.pos_prev, i, limits,
                                absolute)
        # velocity setpoint: the position PID output, or the setpoint's own velocity
        vel_sp = (svx, svy, svz) if s.vbody[i] else (svx * c + svy * sn, svy * c - svx * sn, svz)
        vel_sp = (pos_out[0] if absolute[0] else vel_sp[0], pos_out[1] if absolute[1] else vel_sp[1],
                  pos_out[2] if absolute[2] else vel_sp[2])
        body_v = (vx * c + vy * sn, -vx * sn + vy * c, vz)
        rp = s.rp_limit[i].tolist()
        limits = (rp[1] * LIMIT_OVERHEAD, rp[0] * LIMIT_OVERHEAD, VZ_OUTPUT_LIMIT)
        vel_out = _pid_step_row(vel_sp, body_v, s.vel_gains[i].tolist(), s.vel_integ, s.vel_prev, i, limits,
                           (True, True, True))
        s.vel_target[i] = vel_sp
        pitch = clamp(-vel_out[0], -rp[1], rp[1])
        roll = clamp(-vel_out[1], -rp[0], rp[0])
        thrust = clamp(maximum(vel_out[2] * THRUST_SCALE + float(s.thrust_base[i]), float(s.thrust_min[i])),
                       0.0, UINT16_MAX)
        # disabled axes: attitude and thrust straight from the setpoint
        att = s.att[i].tolist()
        if modes[M_X] == MODE_DISABLE or modes[M_Y] == MODE_DISABLE:
            roll, pitch = att[0], att[1]
        if modes[M_Z] == MODE_DISABLE:
            thrust = float(s.thrust_sp[i])
        self._write_row(i, modes, att, s.rate[i].tolist(), roll, pitch, thrust, stab_sp, stab_yaw_sp)

    def _write_row(self, i: int, modes: List[int], att: List[float], rate: List[float], roll: float, pitch: float,
                   thrust: float, stab_sp: np.ndarray, stab_yaw_sp: np.ndarray) -> None:
        """``_write`` for one row."""
        self.s.out[i] = (roll, pitch, thrust)
        yaw_mode = modes[M_YAW]
        stab_sp[i] = (roll, pitch, -rate[2] if yaw_mode == MODE_VELOCITY else 0.0, thrust)
        if yaw_mode == MODE_ABS:
            target = att[2]
        elif modes[M_QUAT] == MODE_ABS:
            target = float(self.s.quat_yaw[i])
        else:
            return
        if target == target:
            stab_yaw_sp[i] = (target + 180.0) % 360.0 - 180.0

    def _yaw_target(self, rows: np.ndarray, yaw_now_deg: np.ndarray, dt: float) -> np.ndarray:
        """Desired yaw (deg): the setpoint's angle, its quaternion's yaw, or now + rate·dt."""
        s = self.s
        modes = s.modes[rows]
        target = np.where(modes[:, M_QUAT] == MODE_ABS, s.quat_yaw[rows], yaw_now_deg + s.rate[rows, 2] * dt)
        return np.where(modes[:, M_YAW] == MODE_ABS, s.att[rows, 2], target)

    def _update_pid(self, rows: np.ndarray, est_pos: np.ndarray, est_vel: np.ndarray, yaw_deg: np.ndarray,
                    stab_sp: np.ndarray, stab_yaw_sp: np.ndarray, thrust_on: np.ndarray) -> None:
        s = self.s
        modes = s.modes[rows]
        off = ~thrust_on[rows]
        if off.any():
            self.reset_pids(rows[off], est_pos[rows[off]])

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
        target = np.where((yaw_mode != MODE_ABS) & (modes[:, M_QUAT] == MODE_ABS), s.quat_yaw[rows], target)
        fixed = ~np.isnan(target)
        if fixed.any():
            stab_yaw_sp[rows[fixed]] = (target[fixed] + 180.0) % 360.0 - 180.0

    def _pid(self, rows: np.ndarray, desired: np.ndarray, measured: np.ndarray, gains: np.ndarray, which: str,
             limit: np.ndarray, run: np.ndarray) -> np.ndarray:
        """The firmware's PID update (derivative on the measurement, integral limit, output limit) where
        ``run`` is True."""
        s = self.s
        integ_name, prev_name = which + "_integ", which + "_prev"
        integ_all, prev_all = getattr(s, integ_name), getattr(s, prev_name)
        err = desired - measured
        integ = np.minimum(np.maximum(integ_all[rows] + err * DT, -INTEGRATION_LIMIT), INTEGRATION_LIMIT)
        deriv = (prev_all[rows] - measured) / DT
        out = gains[:, :, 0] * err + gains[:, :, 1] * integ + gains[:, :, 2] * deriv + gains[:, :, 3] * desired
        out = np.minimum(np.maximum(out, -limit), limit)
        integ_all[rows] = np.where(run, integ, integ_all[rows])
        prev_all[rows] = np.where(run, measured, prev_all[rows])
        return out

    def targets(self, i: int) -> Dict[str, float]:
        """``ctrltarget.*`` log variables of row ``i``."""
        s = self.s
        names = ("x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az")
        values = list(s.pos[i]) + list(s.vel[i]) + list(s.acc[i])
        return {"ctrltarget." + n: float(val) for n, val in zip(names, values)}


def _pid_step_row(desired: Sequence[float], measured: Sequence[float], gains: List[List[float]], integ_all: np.ndarray,
             prev_all: np.ndarray, i: int, limit: Sequence[float], run: Sequence[bool]) -> List[float]:
    """``PositionControl._pid`` for one row ``i`` in Python floats (its state arrays updated in place)."""
    integ, prev = integ_all[i].tolist(), prev_all[i].tolist()
    out = []
    for k in range(3):
        err = desired[k] - measured[k]
        new_integ = clamp(integ[k] + err * DT, -INTEGRATION_LIMIT, INTEGRATION_LIMIT)
        deriv = (prev[k] - measured[k]) / DT
        g = gains[k]
        out.append(clamp(g[0] * err + g[1] * new_integ + g[2] * deriv + g[3] * desired[k], -limit[k], limit[k]))
        if run[k]:
            integ[k], prev[k] = new_integ, measured[k]
    integ_all[i], prev_all[i] = integ, prev
    return out
