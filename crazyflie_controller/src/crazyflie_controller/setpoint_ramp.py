"""A setpoint that travels to the goal with bounded speed and acceleration.

Used at the hand-over from take-off to closed loop (and for landing): instead of asking the PIDs
to close a 0.45 m step at once, the setpoint starts where the vehicle is, moving as fast as it
moves, and glides to the goal, braking so that it stops there. Its velocity is continuous, so it
can be fed to the D terms without a kick.
"""
from __future__ import annotations

import math
from typing import Sequence, Tuple

Vec3 = Tuple[float, float, float]
BRAKING_MARGIN = 0.8   # plan braking with 80 % of max_accel so discrete steps can follow the profile


def _norm(v: Sequence[float]) -> float:
    return math.sqrt(sum(c * c for c in v))


class SetpointRamp:
    """Position/velocity of a moving setpoint; :meth:`step` advances it toward a goal."""

    def __init__(self, position: Sequence[float], velocity: Sequence[float], max_speed: float,
                 max_accel: float) -> None:
        if not (max_speed > 0 and max_accel > 0):
            raise ValueError("setpoint ramp needs positive max_speed and max_accel, got %r and %r"
                             % (max_speed, max_accel))
        self.position: Vec3 = (float(position[0]), float(position[1]), float(position[2]))
        speed = _norm(velocity)
        scale = max_speed / speed if speed > max_speed else 1.0   # a noisy velocity never exceeds the limit
        self.velocity: Vec3 = (float(velocity[0]) * scale, float(velocity[1]) * scale, float(velocity[2]) * scale)
        self.max_speed = float(max_speed)
        self.max_accel = float(max_accel)
        self.arrived = False

    def step(self, goal: Sequence[float], dt: float) -> None:
        """Moves the setpoint for ``dt`` seconds; sets :attr:`arrived` once it rests on the goal.

        The velocity changes by at most max_accel·dt per step, except the last step onto the goal
        (at most 2·max_accel·dt).
        """
        if dt <= 0:
            return
        p, v = self.position, self.velocity
        to_goal = [goal[i] - p[i] for i in range(3)]
        distance = _norm(to_goal)
        speed = _norm(v)
        if distance < 1e-4 and speed < self.max_accel * dt:
            self.position, self.velocity, self.arrived = (goal[0], goal[1], goal[2]), (0.0, 0.0, 0.0), True
            return
        self.arrived = False
        # Desired velocity: toward the goal, slow enough to brake to rest exactly there.
        braking_speed = math.sqrt(2.0 * BRAKING_MARGIN * self.max_accel * distance) if distance > 0 else 0.0
        desired_speed = min(self.max_speed, braking_speed)
        desired = [c / distance * desired_speed if distance > 0 else 0.0 for c in to_goal]
        change = [desired[i] - v[i] for i in range(3)]
        change_norm = _norm(change)
        limit = self.max_accel * dt
        if change_norm > limit:
            change = [c * limit / change_norm for c in change]
        new_v = [v[i] + change[i] for i in range(3)]
        new_p = [p[i] + 0.5 * (v[i] + new_v[i]) * dt for i in range(3)]
        # Settle on the goal when this step would cross it at a crawl (no velocity jump worth a kick).
        if _norm([new_p[i] - p[i] for i in range(3)]) >= distance and speed <= 2.0 * limit:
            new_p, new_v = list(goal[:3]), [0.0, 0.0, 0.0]
            self.arrived = True
        self.position = (new_p[0], new_p[1], new_p[2])
        self.velocity = (new_v[0], new_v[1], new_v[2])
