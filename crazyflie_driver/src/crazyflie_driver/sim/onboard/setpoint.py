"""The setpoint the simulated Crazyflie's flight code follows: the firmware's setpoint_t and its axis modes.

The radio side (``sim.crtp.setpoint_decode``) and the high-level commander fill it in; the
controllers read it. It lives with the flight code so that the flight code needs nothing of the
radio side.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Tuple

# modes of one setpoint axis (the firmware's stab_mode_t)
MODE_DISABLE, MODE_ABS, MODE_VELOCITY = 0, 1, 2


@dataclass
class OnboardSetpoint:
    """The firmware's setpoint_t, reduced to what the simulated controllers use.

    Units as the firmware keeps them: m, m/s, m/s², attitude and rates in degrees (and deg/s),
    yaw rate counter-clockwise positive (the decoders apply the legacy negation), thrust in
    motor counts. Quaternion (x, y, z, w).
    """

    kind: int = 0                      # generic-setpoint type it came from (0: stop)
    mode_x: int = MODE_DISABLE
    mode_y: int = MODE_DISABLE
    mode_z: int = MODE_DISABLE
    mode_roll: int = MODE_DISABLE
    mode_pitch: int = MODE_DISABLE
    mode_yaw: int = MODE_DISABLE
    mode_quat: int = MODE_DISABLE
    position: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    acceleration: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    attitude: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    attitude_rate: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    quaternion: Tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    thrust: float = 0.0
    velocity_body: bool = False
    extra: Dict[str, float] = field(default_factory=dict)

    @property
    def is_stop(self) -> bool:
        """All modes disabled and no thrust: the motors stop."""
        return (self.thrust == 0.0 and self.mode_x == self.mode_y == self.mode_z == MODE_DISABLE
                and self.mode_roll == self.mode_pitch == MODE_DISABLE)

