"""The high-level commander of every vehicle: plans from commands, setpoints from plans (100 Hz).

The commands come from port 8 (decoded by ``sim/crtp/high_level_port.py``); the result codes are
the firmware's (0 success, 1 refused by the planner, ENOEXEC, EBUSY). Its setpoints have the
high-level priority: a low-level (port 3 or 7) setpoint takes over and stops the planner (IDLE),
commands are still planned but their setpoints lose against the low-level priority until
notify-setpoints-stop hands control back. While idle with the control, it stops the motors; a plan
that evaluates to a NaN position disables the planner (DISABLED: no setpoint at all, the
supervisor's "high-level disabled" bit). docs/protocol.md, "The commander's priority".
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from crazyflie_driver.sim.onboard.planner import (
    AXES,
    DISABLED,
    FLYING,
    IDLE,
    LANDING,
    N_COEFFS,
    Evaluation,
    Piece,
    Plan,
    normalize_radians,
    online_piece,
    poly7_nojerk,
    yaw_turn,
)
from crazyflie_driver.sim.onboard.setpoint import MODE_ABS, OnboardSetpoint

HL_RATE_EVERY = 10                 # ticks: the high-level commander runs at 100 Hz
HL_SETPOINT_KIND = 100             # not a port-7 type: marks setpoints of the high-level commander
ENOEXEC, EBUSY = 8, 16
REFUSED = 1                        # what the planner returns for a command it does not take now
DEFAULT_VELOCITY = 0.5             # m/s, the defaults of hlCommander.vtoff and hlCommander.vland
MAX_SPIRAL_ANGLE = 2.0 * math.pi   # rad: the planner saturates a spiral's angle here


class HighLevelPlans:
    """One ``Plan`` (and group mask) per vehicle row; rows follow the world's other models."""

    def __init__(self) -> None:
        self.plans: List[Plan] = []
        self.group_mask: List[int] = []
        self.takeoff_velocity: List[float] = []       # hlCommander.vtoff, m/s
        self.landing_velocity: List[float] = []       # hlCommander.vland, m/s
        self.null_due: List[bool] = []                # an idle planner with the priority: null setpoint next tick
        self.finish_time: List[float] = []            # world time at which the last plan ends

    def __len__(self) -> int:
        return len(self.plans)

    def append_row(self) -> int:
        self.plans.append(Plan())
        self.group_mask.append(0)
        self.takeoff_velocity.append(DEFAULT_VELOCITY)
        self.landing_velocity.append(DEFAULT_VELOCITY)
        self.null_due.append(False)
        self.finish_time.append(-math.inf)
        return len(self.plans) - 1

    def delete_row(self, index: int) -> None:
        del self.plans[index]
        del self.group_mask[index]
        del self.takeoff_velocity[index]
        del self.landing_velocity[index]
        del self.null_due[index]
        del self.finish_time[index]

    def boot(self, i: int) -> None:
        self.plans[i] = Plan()
        self.group_mask[i] = 0
        self.takeoff_velocity[i] = DEFAULT_VELOCITY
        self.landing_velocity[i] = DEFAULT_VELOCITY
        self.null_due[i] = False
        self.finish_time[i] = -math.inf

    def _begin(self, i: int, plan: Plan) -> int:
        self.plans[i] = plan
        self.finish_time[i] = plan.t_begin + plan.duration
        return 0

    def preempt(self, i: int) -> None:
        """A low-level setpoint took the priority: the planner is stopped (IDLE) and forgets its plan."""
        self.plans[i] = Plan()

    def relax(self, i: int) -> None:
        """Notify-setpoints-stop gave the priority back: an idle planner sends its null setpoint at its next tick."""
        self.null_due[i] = True

    def status(self, i: int, now: float) -> Tuple[bool, bool, bool]:
        """(flying a plan, the last plan has ended, disabled): supervisor.info bits 8, 9 and 10."""
        state = self.plans[i].state
        return (state in (FLYING, LANDING), now >= self.finish_time[i], state == DISABLED)

    def in_group(self, i: int, mask: int) -> bool:
        return mask == 0 or bool(mask & self.group_mask[i])

    def due(self) -> List[int]:
        """Rows whose planner has something to say at this tick: a plan to fly, or its null setpoint."""
        null_due = self.null_due
        return [i for i, p in enumerate(self.plans) if p.state == FLYING or p.state == LANDING or null_due[i]]

    # --- commands (world time ``now``; ``start`` is the last setpoint or the estimate) ----------------
    def takeoff(self, i: int, start: Evaluation, height: float, yaw: float, duration: float, now: float) -> int:
        plan = self.plans[i]
        if plan.state != IDLE:
            return REFUSED
        goal = np.array([start.pos[0], start.pos[1], height])
        rest = Evaluation(start.pos, np.zeros(3), np.zeros(3), start.yaw, 0.0)
        return self._begin(i, Plan(FLYING, [online_piece(duration, rest, goal, yaw)], now))

    def land(self, i: int, start: Evaluation, height: float, yaw: float, duration: float, now: float) -> int:
        if self.plans[i].state == LANDING:
            return REFUSED
        goal = np.array([start.pos[0], start.pos[1], height])
        rest = Evaluation(start.pos, np.zeros(3), np.zeros(3), start.yaw, 0.0)
        return self._begin(i, Plan(LANDING, [online_piece(duration, rest, goal, yaw)], now))

    def go_to(self, i: int, start: Evaluation, goal: Sequence[float], yaw: float, duration: float, relative: bool,
              linear: bool, now: float) -> int:
        target = np.asarray(goal, dtype=float)
        if relative:
            target = target + start.pos
            yaw = yaw + start.yaw
        if linear and duration > 0:
            # constant velocity and yaw rate at both ends; the yaw turns the short way
            v = (target - start.pos) / duration
            yaw_rate = yaw_turn(start.yaw, yaw)[1] / duration
            begin = Evaluation(start.pos, v, np.zeros(3), start.yaw, yaw_rate)
            piece = online_piece(duration, begin, target, yaw, v, yaw_rate)
        else:
            piece = online_piece(duration, start, target, yaw)
        return self._begin(i, Plan(FLYING, [piece], now))

    def start_trajectory(self, i: int, start: Evaluation, pieces: List[Piece], timescale: float, reversed_: bool,
                         relative_position: bool, relative_yaw: bool, now: float) -> int:
        if not pieces:
            return ENOEXEC
        plan = Plan(FLYING, list(pieces), now, timescale if timescale > 0 else 1.0, bool(reversed_))
        if relative_position:
            plan.shifted_to(start, relative_yaw)
        return self._begin(i, plan)

    def spiral(self, i: int, start: Evaluation, sideways: bool, clockwise: bool, angle: float, r0: float, rf: float,
               ascent: float, duration: float, now: float) -> int:
        """A spiral segment from ``start`` as the firmware plans it: one degree-7 piece per axis whose ends
        lie on the spiral (position, velocity and acceleration); the yaw turns by the angle. The angle is
        saturated at +-2 pi and negative radii count as 0. Around a centre to the left (counter-clockwise)
        or right (clockwise) of the heading, or ahead of/behind it when ``sideways``."""
        angle = min(max(angle, -MAX_SPIRAL_ANGLE), MAX_SPIRAL_ANGLE) if not math.isnan(angle) else angle
        r0 = 0.0 if r0 < 0 else r0
        rf = 0.0 if rf < 0 else rf
        sense = 1.0 if clockwise else -1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            omega = np.float64(-sense * angle) / duration
            climb = np.float64(ascent) / duration
            dr = np.float64(rf - r0) / duration
        phi0 = normalize_radians(start.yaw)
        phi_f = phi0 - sense * angle

        def point(phi: float, r: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
            """Offset from the centre, velocity and acceleration at heading ``phi`` and radius ``r``."""
            c, s_ = math.cos(phi), math.sin(phi)
            if sideways:
                offset = np.array([-c, -s_]) * sense * r
                vel = sense * np.array([r * s_ * omega - dr * c, -r * c * omega - dr * s_])
                acc = sense * np.array([r * c * omega ** 2 + 2 * dr * s_ * omega,
                                        r * s_ * omega ** 2 - 2 * dr * c * omega])
            else:
                offset = np.array([-s_, c]) * sense * r
                vel = np.array([-sense * (r * c * omega + dr * s_), sense * (-r * s_ * omega + dr * c)])
                acc = sense * np.array([r * s_ * omega ** 2 - 2 * dr * c * omega,
                                        -r * c * omega ** 2 - 2 * dr * s_ * omega])
            return offset, vel, acc

        with np.errstate(invalid="ignore", over="ignore"):
            off0, vel0, acc0 = point(phi0, r0)
            off_f, vel_f, acc_f = point(phi_f, rf)
            centre = start.pos[:2] - off0
            end = centre + off_f
            coeffs = np.zeros((AXES, N_COEFFS))
            for k in range(2):
                coeffs[k] = poly7_nojerk(duration, (start.pos[k], vel0[k], acc0[k]), (end[k], vel_f[k], acc_f[k]))
            coeffs[2] = poly7_nojerk(duration, (start.pos[2], climb, 0.0), (start.pos[2] + ascent, climb, 0.0))
            coeffs[3] = poly7_nojerk(duration, (phi0, omega, 0.0), (phi_f, omega, 0.0))
        return self._begin(i, Plan(FLYING, [Piece(duration if duration > 0 else 0.0, coeffs)], now))

    def stop(self, i: int) -> None:
        """IDLE: with the priority, the planner's null setpoint stops the motors at its next tick."""
        self.plans[i] = Plan()
        self.null_due[i] = True

    # --- the tick ---------------------------------------------------------------------------------
    def setpoint(self, i: int, now: float) -> Optional[OnboardSetpoint]:
        """The setpoint of row i's plan now. None when there is none: the planner is IDLE (its null
        setpoint, e.g. a landing just ended) or DISABLED (nothing; a plan whose position evaluates to
        NaN disables it, as the firmware's planner does)."""
        self.null_due[i] = False
        plan = self.plans[i]
        if plan.state != FLYING and plan.state != LANDING:
            return None
        if plan.state == LANDING and plan.finished(now):
            self.plans[i] = Plan()
            return None
        ev = plan.evaluate(now)
        if ev is None or not (ev.pos[0] == ev.pos[0] and ev.pos[1] == ev.pos[1] and ev.pos[2] == ev.pos[2]):
            self.plans[i] = Plan(DISABLED, plan.pieces, plan.t_begin, plan.timescale, plan.reversed, plan.shift,
                                 plan.rotation)
            return None
        return OnboardSetpoint(HL_SETPOINT_KIND, MODE_ABS, MODE_ABS, MODE_ABS, mode_yaw=MODE_ABS,
                        position=tuple(ev.pos), velocity=tuple(ev.vel), acceleration=tuple(ev.acc),
                        attitude=(0.0, 0.0, math.degrees(ev.yaw)),
                        attitude_rate=(math.degrees(ev.omega_xy[0]), math.degrees(ev.omega_xy[1]),
                                       math.degrees(ev.yaw_rate)))

    def current(self, i: int, now: float) -> Optional[Evaluation]:
        plan = self.plans[i]
        return plan.evaluate(now) if plan.state in (FLYING, LANDING) else None
