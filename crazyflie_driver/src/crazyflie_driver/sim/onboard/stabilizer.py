"""The firmware's flight controller for the legacy RPYT setpoint, all vehicles at once (numpy).

Follows docs/simulation.md, "The onboard attitude and rate controllers": commander semantics (thrust below 1 000 is
0, clamp at 60 000, thrust lock
until a zero-thrust setpoint, the yaw-rate negation, the legacy nose-up-positive pitch), the
setpoint watchdog (level out after 0.5 s, motors off after 2 s), emergency stop, tumble detection
(current firmware), attitude PID -> rate PID -> legacy X mixer with the clamping of each firmware
generation. Rows flown by the Mellinger controller (controller 2 with generic or high-level
setpoints) take their roll, pitch and yaw commands from its attitude law (``mellinger.moments``)
instead of the PIDs, and rows flown by onboard position control skip the RPYT commander's thrust
rules. Battery compensation is taken as ideal: a command means the same thrust at any
battery voltage (docs/simulation.md, "Battery"), so the battery only matters through its cut-off.

Sign conventions of the firmware estimate used here and in the logs: roll right-hand about body x,
pitch positive nose up (the negated standard pitch), yaw counter-clockwise seen from above; degrees.
"""
from __future__ import annotations

import math
from typing import Dict, Optional, Tuple

import numpy as np

from crazyflie_driver.crtp.firmware_limits import (
    MAX_THRUST,
    MIN_THRUST,
    SETPOINT_WATCHDOG_CUT_S,
    SETPOINT_WATCHDOG_LEVEL_S,
)
from crazyflie_driver.sim.onboard import mellinger as _mel
from crazyflie_driver.sim.onboard.body import BodyRows
from crazyflie_driver.sim.onboard.ticks import CONTROL_PERIOD_S, CONTROL_TICKS, FIRMWARE_TICK_S
from crazyflie_driver.sim.vehicle_rows import Rows, quadratic_form

GEN_CURRENT = "current"
GEN_2016 = "2016.02"
GENERATIONS = (GEN_CURRENT, GEN_2016)

PID_DT = CONTROL_PERIOD_S        # dt both generations use inside their PIDs (1/500 s)
RATE_OUTPUT_LIMIT = 32767.0
WATCHDOG_LEVEL_S = SETPOINT_WATCHDOG_LEVEL_S
WATCHDOG_SHUTDOWN_S = SETPOINT_WATCHDOG_CUT_S
WATCHDOG_MARGIN_S = 1.5 * FIRMWARE_TICK_S    # odd ticks recompute the motors this close to a watchdog cut
TUMBLE_TILT_COS = 0.5            # 60 degrees
TUMBLE_TILT_S = 1.0
TUMBLE_UPSIDE_DOWN_S = 0.1

# lock reasons (why the motors are held off until a reboot)
LOCK_NONE, LOCK_EMERGENCY, LOCK_WATCHDOG, LOCK_TUMBLE, LOCK_BATTERY, LOCK_ASSERT = 0, 1, 2, 3, 4, 5

# platforms (a vehicles entry's ``platform``): a brushed Crazyflie 2.x arms itself at boot; a Brushless one
# keeps its motors off until armed, then idles them (the firmware's arming documentation)
PLATFORM_CF2 = "cf2"
PLATFORM_BRUSHLESS = "brushless"
PLATFORMS = (PLATFORM_CF2, PLATFORM_BRUSHLESS)
#: Motor command (0..65535) a Brushless platform's motors idle at once armed: a simulation choice, low
#: enough to lift nothing (about 5 % of full scale)
BRUSHLESS_IDLE_MOTOR = 3000.0
LOCK_NAMES = {LOCK_NONE: "", LOCK_EMERGENCY: "emergency stop", LOCK_WATCHDOG: "setpoint watchdog",
              LOCK_TUMBLE: "tumbled", LOCK_BATTERY: "battery empty", LOCK_ASSERT: "firmware assert"}

AXES = ("roll", "pitch", "yaw")
TERMS = ("kp", "ki", "kd")

# (kp, ki, kd) per axis and the integral limits (docs/simulation.md, rates and gains table)
GAINS: Dict[str, Dict[str, Tuple[Tuple[float, float, float], ...]]] = {
    GEN_CURRENT: {"pid_attitude": ((6.0, 3.0, 0.0), (6.0, 3.0, 0.0), (6.0, 1.0, 0.35)),
                  "pid_rate": ((250.0, 500.0, 2.5), (250.0, 500.0, 2.5), (120.0, 16.7, 0.0))},
    GEN_2016: {"pid_attitude": ((3.5, 2.0, 0.0), (3.5, 2.0, 0.0), (10.0, 1.0, 0.35)),
               "pid_rate": ((70.0, 0.0, 0.0), (70.0, 0.0, 0.0), (70.0, 16.7, 0.0))},
}
ATTITUDE_ILIMIT = (20.0, 20.0, 360.0)
RATE_ILIMIT = (33.3, 33.3, 166.7)

# mixer rows: m_i = T + R·MIX_R[i] + P·MIX_P[i] + Y·MIX_Y[i]   (docs/simulation.md, mixing)
MIX_R = np.array([-0.5, -0.5, 0.5, 0.5])
MIX_P = np.array([0.5, -0.5, -0.5, 0.5])
MIX_Y = np.array([1.0, -1.0, 1.0, -1.0])


def check_generation(firmware: str) -> str:
    if firmware not in GENERATIONS:
        raise ValueError("unknown firmware generation %r (choose one of: %s)" % (firmware, ", ".join(GENERATIONS)))
    return firmware


def default_params(firmware: str) -> Dict[str, float]:
    """The controller's parameters with the firmware's names, e.g. ``pid_rate.roll_kp``."""
    out: Dict[str, float] = {}
    for group, per_axis in GAINS[check_generation(firmware)].items():
        for axis, gains in zip(AXES, per_axis):
            for term, value in zip(TERMS, gains):
                out["%s.%s_%s" % (group, axis, term)] = float(value)
    return out


def _finite_or_zero(value: float) -> float:
    """A setpoint field as the firmware's float: NaN and infinities become 0."""
    v = float(value)
    return v if math.isfinite(v) else 0.0


def wrap_deg(a: np.ndarray) -> np.ndarray:
    return (a + _HALF_TURN) % _TURN - _HALF_TURN


_HALF_TURN, _TURN = np.array(180.0), np.array(360.0)    # deg; 0-d arrays: cheaper in numpy calls than floats


class OnboardStates(Rows):
    FIELDS = {
        "gen2016": ((), bool),
        "att_gains": ((3, 3), float),       # [axis, term]
        "rate_gains": ((3, 3), float),
        "att_ilimit": ((3,), float),
        "rate_ilimit": ((3,), float),
        # last setpoint (raw wire values) and when it came
        "sp": ((4,), float),                # roll, pitch, yaw rate, thrust
        "sp_time": ((), float),
        "thrust_locked": ((), bool),        # waits for a zero-thrust setpoint
        "generic": ((), bool),              # the onboard position controller writes the setpoint row: the
                                            # RPYT commander's thrust rules (< 1000 -> 0, cap 60000) do not apply
        "lock": ((), np.int8),              # LOCK_*: motors off until reboot (LOCK_TUMBLE: until crash recovery)
        "lock_time": ((), float),           # world time the present lock was set [s]
        # controller state
        "yaw_sp": ((), float),
        "att_integ": ((3,), float),
        "att_prev": ((3,), float),
        "rate_integ": ((3,), float),
        "rate_prev": ((3,), float),
        "rate_desired": ((3,), float),
        "rate_out": ((3,), float),          # R, P, Y as the mixer takes them
        "attitude": ((3,), float),          # estimate, firmware convention, deg
        "attitude_desired": ((3,), float),
        "thrust": ((), float),              # collective thrust after commander rules
        "motors": ((4,), float),            # motor commands 0..65535
        "tilt_time": ((), float),
        "upside_time": ((), float),
        "motor_power_enable": ((), bool),
        "disarmed": ((), bool),             # not armed: motors off whatever the setpoint (Brushless at boot)
        "idle_motor": ((), float),          # motor command while armed with no thrust asked (Brushless)
        "motor_power": ((4,), float),
        # the Mellinger controller's attitude law (rows flown by controller 2 with generic setpoints)
        "moment_law": ((), bool),           # the roll, pitch, yaw commands come from the law, not the PIDs
        "mel_axes": ((3, 3), float),        # desired body axes (columns x, y, z) from its position part
        "mel_rate_sp": ((3,), float),       # the setpoint's body rates (deg/s)
        "mel_gains": ((len(_mel.ATTITUDE_GAIN_ORDER),), float),
        "mel_integ_m": ((3,), float),
        "mel_prev": ((4,), float),          # last roll, pitch rate and their setpoints (rad/s)
    }

    # The columns (one row per vehicle; shapes and dtypes in FIELDS), declared for the type checker.
    gen2016: np.ndarray
    att_gains: np.ndarray
    rate_gains: np.ndarray
    att_ilimit: np.ndarray
    rate_ilimit: np.ndarray
    sp: np.ndarray
    sp_time: np.ndarray
    thrust_locked: np.ndarray
    generic: np.ndarray
    lock: np.ndarray
    lock_time: np.ndarray
    yaw_sp: np.ndarray
    att_integ: np.ndarray
    att_prev: np.ndarray
    rate_integ: np.ndarray
    rate_prev: np.ndarray
    rate_desired: np.ndarray
    rate_out: np.ndarray
    attitude: np.ndarray
    attitude_desired: np.ndarray
    thrust: np.ndarray
    motors: np.ndarray
    tilt_time: np.ndarray
    upside_time: np.ndarray
    motor_power_enable: np.ndarray
    disarmed: np.ndarray
    idle_motor: np.ndarray
    motor_power: np.ndarray
    moment_law: np.ndarray
    mel_axes: np.ndarray
    mel_rate_sp: np.ndarray
    mel_gains: np.ndarray
    mel_integ_m: np.ndarray
    mel_prev: np.ndarray

    def reset_pids(self, rows, attitude: np.ndarray) -> None:
        """The firmware PID controller's re-initialisation on a change of setpoint modes: the attitude
        PIDs restart from ``attitude`` (n,3, deg, firmware convention; integrals 0, last measurement =
        it) and the rate PIDs from rest (integrals 0, last measurement 0); the yaw setpoint and the
        outputs of the last step are kept (unlike the motors-off reset)."""
        self.att_integ[rows] = 0.0
        self.att_prev[rows] = np.where(self.gen2016[rows, None], 0.0, -attitude)
        self.rate_integ[rows] = 0.0
        self.rate_prev[rows] = 0.0

    def add(self, firmware: str, now: float, yaw_deg: float = 0.0, platform: str = PLATFORM_CF2) -> int:
        i = self.append_row()
        self.boot(i, firmware, now, yaw_deg, platform)
        return i

    def boot(self, i: int, firmware: str, now: float, yaw_deg: float = 0.0, platform: str = PLATFORM_CF2) -> None:
        """Row ``i`` as after power-on: default gains, thrust locked, controller reset; a Brushless
        platform disarmed."""
        if platform not in PLATFORMS:
            raise ValueError("unknown platform %r (choose one of: %s)" % (platform, ", ".join(PLATFORMS)))
        for name in self.FIELDS:
            getattr(self, name)[i] = 0
        self.disarmed[i] = platform == PLATFORM_BRUSHLESS
        self.idle_motor[i] = BRUSHLESS_IDLE_MOTOR if platform == PLATFORM_BRUSHLESS else 0.0
        self.gen2016[i] = check_generation(firmware) == GEN_2016
        g = GAINS[firmware]
        self.att_gains[i] = g["pid_attitude"]
        self.rate_gains[i] = g["pid_rate"]
        self.att_ilimit[i] = ATTITUDE_ILIMIT
        self.rate_ilimit[i] = RATE_ILIMIT
        self.sp_time[i] = now
        self.thrust_locked[i] = True
        self.yaw_sp[i] = yaw_deg
        self.att_prev[i] = (0.0, 0.0, -yaw_deg)
        self.mel_gains[i] = [_mel.ATTITUDE_DEFAULTS[n] for n in _mel.ATTITUDE_GAIN_ORDER]
        self.mel_axes[i] = np.eye(3)


class OnboardController:
    """Runs the commander, supervisor and PID cascade of every vehicle, one 1 kHz tick per call."""

    def __init__(self) -> None:
        self.s = OnboardStates()
        self.dirty = True            # something changed the motors' inputs since the last update
        self._cut_soon = False       # a setpoint watchdog cut is due within the next ticks
        self.time = 0.0              # world time of the latest tick [s]: stamps a lock set between ticks

    # --- commands (called under the world lock) ----------------------------------------------
    def set_rpyt(self, i: int, roll: float, pitch: float, yaw: float, thrust: float, now: float) -> None:
        vals = [_finite_or_zero(roll), _finite_or_zero(pitch), _finite_or_zero(yaw), _finite_or_zero(thrust)]
        vals[3] = min(max(vals[3], 0.0), 65535.0)
        s = self.s
        s.sp[i] = vals
        s.sp_time[i] = now
        if vals[3] == 0.0:
            s.thrust_locked[i] = False
        s.generic[i] = False
        s.moment_law[i] = False
        self.dirty = True

    def lock(self, i: int, reason: int, now: Optional[float] = None) -> None:
        """Motors off until reboot; a lock replaces a crash (the firmware's Crashed state can still lock).
        ``now``: world time [s] (default: the latest tick's)."""
        if self.s.lock[i] == LOCK_NONE or (self.s.lock[i] == LOCK_TUMBLE and reason != LOCK_TUMBLE):
            self.s.lock[i] = reason
            self.s.lock_time[i] = self.time if now is None else now
        self.dirty = True

    def set_param(self, i: int, name: str, value: float) -> bool:
        """Apply a firmware parameter; False when the controller does not use it."""
        group, _, field = name.partition(".")
        s = self.s
        self.dirty = True
        if group in ("pid_attitude", "pid_rate"):
            axis, _, term = field.partition("_")
            if axis in AXES and term in TERMS:
                target = s.att_gains if group == "pid_attitude" else s.rate_gains
                target[i, AXES.index(axis), TERMS.index(term)] = float(value)
                return True
        elif group == "motorPowerSet":
            if field == "enable":
                s.motor_power_enable[i] = bool(value)
                return True
            if field in ("m1", "m2", "m3", "m4"):
                s.motor_power[i, int(field[1]) - 1] = min(max(float(value), 0.0), 65535.0)
                return True
        elif name in _mel.ATTITUDE_DEFAULTS:
            s.mel_gains[i, _mel.ATTITUDE_GAIN_ORDER.index(name)] = float(value)
            return True
        elif name == "stabilizer.stop":
            if value:                       # an emergency stop: the supervisor locks until reboot
                self.lock(i, LOCK_EMERGENCY)
            return True
        return False

    def params(self, i: int) -> Dict[str, float]:
        s = self.s
        out: Dict[str, float] = {}
        for group, gains in (("pid_attitude", s.att_gains[i]), ("pid_rate", s.rate_gains[i])):
            for a, axis in enumerate(AXES):
                for t, term in enumerate(TERMS):
                    out["%s.%s_%s" % (group, axis, term)] = float(gains[a, t])
        return out

    # --- the tick ----------------------------------------------------------------------------
    def update(self, tick: int, now: float, body: BodyRows, gyro_deg, battery_empty: np.ndarray) -> np.ndarray:
        """One 1 kHz firmware tick for all vehicles; returns the motor commands (N,4).

        ``tick`` counts world ticks (decides which loops run: the attitude and rate loops every 2nd
        tick), ``gyro_deg`` is the measured body rate (N,3, deg/s, standard signs; needed on even
        ticks only), ``battery_empty`` (N,) forces the motors off and locks.

        Between two runs of the PIDs the motors change only when a setpoint, a lock, a parameter or
        the setpoint watchdog changes the thrust: ``motors_may_change`` says whether an odd tick has
        anything to compute; when it says no, ``motors`` holds what this call would return.
        """
        s = self.s
        self.dirty = False
        self.time = now
        if len(s) == 0:
            return s.motors
        level = self._supervise(now, battery_empty)
        thrust = self._thrust()
        if tick % CONTROL_TICKS == 0:
            self._control(tick, body, gyro_deg, thrust, level)
        m = self._mix(thrust)
        s.thrust = thrust
        s.motors = m
        return m

    def _supervise(self, now: float, battery_empty: np.ndarray) -> Optional[np.ndarray]:
        """The supervisor's part of a tick: the setpoint watchdog (levels out after 0.5 s, cuts and
        locks after 2 s) and the empty battery's lock. The rows to level out, or None for none."""
        s = self.s
        age = now - s.sp_time
        watched = age > WATCHDOG_LEVEL_S
        level: Optional[np.ndarray] = watched
        self._cut_soon = False
        if np.count_nonzero(watched):
            flying = s.sp[:, 3] > 0.0
            cut = (age > WATCHDOG_SHUTDOWN_S) & flying
            if np.count_nonzero(cut):
                # 2016.02: thrust 0 and relock; current: supervisor locked until reboot
                s.thrust_locked |= cut
                s.sp[:, 3] = np.where(cut, 0.0, s.sp[:, 3])
                self._lock_rows(cut & ~s.gen2016, LOCK_WATCHDOG)
            self._cut_soon = bool(np.count_nonzero((age > WATCHDOG_SHUTDOWN_S - WATCHDOG_MARGIN_S) & flying))
        else:
            level = None
        if np.count_nonzero(battery_empty):
            self._lock_rows(battery_empty, LOCK_BATTERY)
        return level

    def _thrust(self) -> np.ndarray:
        """The base thrust per row [counts]: the setpoint's, clamped as the firmware does for RPYT
        (the position controller's goes as it is), 0 while locked or disarmed."""
        s = self.s
        raw = s.sp[:, 3]
        thrust = np.minimum(raw, MAX_THRUST) * (raw >= MIN_THRUST)
        if np.count_nonzero(s.generic):     # the position controller's thrust goes to the mixer as it is
            thrust = np.where(s.generic, raw, thrust)
        off = s.thrust_locked | (s.lock != LOCK_NONE) | s.disarmed
        if np.count_nonzero(off):
            thrust[off] = 0.0
        return thrust

    def _control(self, tick: int, body: BodyRows, gyro_deg, thrust: np.ndarray, level: Optional[np.ndarray]) -> None:
        """The control ticks (500 Hz): tumble check, attitude and rate loops (or the moment law),
        integrators reset where the thrust is 0. Zeroes ``thrust`` of rows that locked now."""
        s = self.s
        terms = _attitude_terms(body.quaternion)
        if self._tumble(terms[:, 2], thrust):
            thrust[s.lock != LOCK_NONE] = 0.0
        s.attitude = _attitude_from_terms(terms)
        # attitude loop: 500 Hz (current), 250 Hz (2016.02, still with dt = 1/500 in its PIDs)
        due = None if tick % (2 * CONTROL_TICKS) == 0 or not np.count_nonzero(s.gen2016) else ~s.gen2016
        self._attitude_loop(due, level)
        self._rate_loop(gyro_deg)
        if np.count_nonzero(s.moment_law):
            self._moment_law(body.quaternion, gyro_deg, level)
        idle = thrust <= 0.0
        if np.count_nonzero(idle):
            self._reset(idle)

    def _mix(self, thrust: np.ndarray) -> np.ndarray:
        """The motor commands (N,4) [counts]: the rate loops' output through the mixer on the thrust,
        saturated as the firmware does; motor tests and a Brushless idle override it."""
        s = self.s
        m = s.rate_out @ MIX
        m += thrust[:, None]
        if m.max() > 65535.0:
            excess = np.maximum(m.max(axis=1) - 65535.0, 0.0) * ~s.gen2016      # current: keep the torques
            m -= excess[:, None]
        np.fmax(m, 0.0, out=m)                 # NaN (a NaN setpoint) -> 0, as the MCU converts it
        np.minimum(m, 65535.0, out=m)
        m *= (thrust > 0.0)[:, None]
        if np.count_nonzero(s.motor_power_enable):
            m = np.where((s.motor_power_enable & (s.lock == LOCK_NONE) & ~s.disarmed)[:, None], s.motor_power, m)
        if np.count_nonzero(s.idle_motor):      # armed Brushless rows idle their motors
            idling = (s.idle_motor > 0.0) & ~s.disarmed & (s.lock == LOCK_NONE)
            m = np.where(idling[:, None], np.maximum(m, s.idle_motor[:, None]), m)
        return m

    def set_armed(self, i: int, armed: bool) -> None:
        """The supervisor armed (or disarmed) row ``i``."""
        self.s.disarmed[i] = not armed
        self.dirty = True

    def recover(self, i: int, tilt_cos: float) -> bool:
        """Crash recovery: a crash (tumble) lock is cleared unless the body is still tilted over 60°.
        True when row ``i`` is not crashed afterwards."""
        s = self.s
        if s.lock[i] != LOCK_TUMBLE:
            return True
        if tilt_cos < TUMBLE_TILT_COS:
            return False
        s.lock[i] = LOCK_NONE
        s.tilt_time[i] = s.upside_time[i] = 0.0
        self.dirty = True
        return True

    @property
    def motors_may_change(self) -> bool:
        """Whether a tick without the PIDs could give other motor commands than the last call returned."""
        return self.dirty or self._cut_soon

    def _lock_rows(self, rows: np.ndarray, reason: int) -> None:
        s = self.s
        free = (s.lock == LOCK_NONE) | ((s.lock == LOCK_TUMBLE) & (reason != LOCK_TUMBLE))
        s.lock_time = np.where(rows & free, self.time, s.lock_time)
        s.lock = np.where(rows & free, reason, s.lock).astype(np.int8)

    def _tumble(self, tilt_cos: np.ndarray, thrust: np.ndarray) -> bool:
        """Current firmware: tilted over 60° for 1 s or upside down for 0.1 s while flying -> crashed
        (motors off until a crash recovery or a reboot).

        ``tilt_cos``: cosine of each body's tilt (its z axis against the world's). True when a vehicle
        was locked by this call.
        """
        s = self.s
        if tilt_cos.min() >= TUMBLE_TILT_COS and not np.count_nonzero(s.tilt_time):
            return False                    # nobody tilted, no tilt being timed
        flying = thrust > 0.0
        tilted = flying & (tilt_cos < TUMBLE_TILT_COS)
        if not (np.count_nonzero(tilted) or np.count_nonzero(s.tilt_time)):
            return False
        dt = CONTROL_PERIOD_S
        s.tilt_time = np.where(tilted, s.tilt_time + dt, 0.0)
        s.upside_time = np.where(flying & (tilt_cos < 0.0), s.upside_time + dt, 0.0)
        tumbled = ~s.gen2016 & ((s.tilt_time > TUMBLE_TILT_S) | (s.upside_time > TUMBLE_UPSIDE_DOWN_S))
        if np.count_nonzero(tumbled):
            self._lock_rows(tumbled, LOCK_TUMBLE)
            return True
        return False

    def _attitude_loop(self, due, level) -> None:
        s = self.s
        old = np.count_nonzero(s.gen2016)
        dt_yaw = np.where(s.gen2016, 2 * PID_DT, PID_DT) if old else PID_DT
        sp = s.sp[:, :3] if level is None else np.where(level[:, None], 0.0, s.sp[:, :3])
        yaw_sp = wrap_deg(s.yaw_sp - sp[:, 2] * dt_yaw)           # the firmware negates the yaw rate
        desired = sp.copy()
        desired[:, 2] = yaw_sp
        err = desired - s.attitude
        err[:, 2] = wrap_deg(err[:, 2])
        integ = np.minimum(np.maximum(s.att_integ + err * PID_DT, -s.att_ilimit), s.att_ilimit)
        src = np.where(s.gen2016[:, None], err, -s.attitude) if old else -s.attitude   # 2016: D on error
        deriv = wrap_deg(src - s.att_prev) * (1.0 / PID_DT)
        g = s.att_gains
        out = g[:, :, 0] * err + g[:, :, 1] * integ + g[:, :, 2] * deriv
        if due is None:
            s.yaw_sp, s.attitude_desired, s.att_integ, s.att_prev, s.rate_desired = yaw_sp, desired, integ, src, out
        else:
            d2 = due[:, None]
            s.yaw_sp = np.where(due, yaw_sp, s.yaw_sp)
            s.attitude_desired = np.where(d2, desired, s.attitude_desired)
            s.att_integ = np.where(d2, integ, s.att_integ)
            s.att_prev = np.where(d2, src, s.att_prev)
            s.rate_desired = np.where(d2, out, s.rate_desired)

    def _rate_loop(self, gyro_deg: np.ndarray) -> None:
        s = self.s
        meas = gyro_deg * _LEGACY_RATE_SIGNS                      # legacy pitch: −gyro_y
        err = s.rate_desired - meas
        integ = np.minimum(np.maximum(s.rate_integ + err * PID_DT, -s.rate_ilimit), s.rate_ilimit)
        src = np.where(s.gen2016[:, None], err, -meas) if np.count_nonzero(s.gen2016) else -meas
        deriv = (src - s.rate_prev) * (1.0 / PID_DT)
        g = s.rate_gains
        out = g[:, :, 0] * err + g[:, :, 1] * integ + g[:, :, 2] * deriv
        out = np.minimum(np.maximum(out, -RATE_OUTPUT_LIMIT), RATE_OUTPUT_LIMIT)
        out[:, 2] *= -1.0                                         # yaw output sign-flipped for the mixer
        s.rate_integ, s.rate_prev, s.rate_out = integ, src, out

    def _moment_law(self, quaternion: np.ndarray, gyro_deg: np.ndarray, level) -> None:
        """Rows flown by the Mellinger controller: its attitude law replaces the attitude and rate PIDs.
        While the supervisor levels out (stale setpoints) the desired axes are level at the current
        yaw, as the firmware's controller takes the level-out setpoint."""
        s = self.s
        rows = np.flatnonzero(s.moment_law)
        axes = s.mel_axes[rows]
        if level is not None and np.count_nonzero(level[rows]):
            flat = level[rows]
            yaw = np.radians(s.attitude[rows, 2])
            up = np.zeros((len(rows), 3))
            up[:, 2] = 1.0
            axes = np.where(flat[:, None, None], _mel._axes_towards(up, yaw), axes)
        s.rate_out[rows], s.mel_integ_m[rows], s.mel_prev[rows] = _mel.moments(
            s.mel_gains[rows], s.mel_integ_m[rows], s.mel_prev[rows], quaternion[rows], axes, s.mel_rate_sp[rows],
            gyro_deg[rows])

    def _reset(self, rows: np.ndarray) -> None:
        """Motors off: PID states cleared, yaw set-point re-seeded with the current yaw."""
        s = self.s
        s.mel_integ_m[rows] = 0.0
        s.att_integ[rows] = 0.0
        s.rate_integ[rows] = 0.0
        s.rate_prev[rows] = 0.0
        s.rate_desired[rows] = 0.0
        s.rate_out[rows] = 0.0
        s.yaw_sp[rows] = s.attitude[rows, 2]
        s.att_prev[rows] = np.where(s.gen2016[rows, None], 0.0, -s.attitude[rows])


def _euler_terms(q: np.ndarray) -> np.ndarray:
    """The arguments of euler_from_quat's arctan2/arcsin, each a quadratic form of a unit quaternion."""
    x, y, z, w = q
    return np.array([2 * (w * x + y * z), 2 * (w * z + x * y),            # roll, yaw numerators
                     w * w + z * z - x * x - y * y, w * w + x * x - y * y - z * z,   # = 1 - 2(x²+y²), 1 - 2(y²+z²)
                     2 * (w * y - z * x)])                             # sin pitch


_EULER_TERMS = quadratic_form(_euler_terms, 4)       # (16, 5)


def firmware_attitude(q: np.ndarray) -> np.ndarray:
    """(N,4) unit quaternions -> (N,3) roll, pitch, yaw in degrees, firmware convention (pitch nose-up positive).

    The same as degrees(euler_from_quat(q)) with pitch negated, in a fixed number of numpy calls.
    """
    return _attitude_from_terms(_attitude_terms(q))


def _attitude_terms(q: np.ndarray) -> np.ndarray:
    """(N,5) arguments of the Euler angles' arctan2/arcsin; column 2 is the cosine of the tilt."""
    return (q[:, :, None] * q[:, None, :]).reshape(-1, 16) @ _EULER_TERMS


def _attitude_from_terms(t: np.ndarray) -> np.ndarray:
    out = np.empty((len(t), 3))
    out[:, 0::2] = np.arctan2(t[:, 0:2], t[:, 2:4])
    out[:, 1] = np.arcsin(np.minimum(np.maximum(t[:, 4], -1.0), 1.0))
    out *= _FIRMWARE_ATTITUDE_DEGREES
    return out


_FIRMWARE_ATTITUDE_DEGREES = np.array([180.0 / np.pi, -180.0 / np.pi, 180.0 / np.pi])
_LEGACY_RATE_SIGNS = np.array([1.0, -1.0, 1.0])
MIX = np.stack([MIX_R, MIX_P, MIX_Y])       # (3,4): [R, P, Y] @ MIX
