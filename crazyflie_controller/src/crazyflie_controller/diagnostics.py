"""The controller's entry on ``/diagnostics``: its state, the pose's age and how often the thrust is
at a limit. Pure; the node publishes. Levels and reasons: docs/diagnostics.md, "The controller"."""
from __future__ import annotations

from collections import deque
from typing import Deque, Optional, Tuple

from .position_controller import Safety, State

OK, WARN, ERROR = 0, 1, 2        # diagnostic_msgs/DiagnosticStatus levels
SATURATION_WINDOW_S = 2.0        # s of control steps the saturation share is counted over
SATURATION_WARN = 0.2            # share of those steps (in the air) with the thrust at a limit: WARN

# what the controller's pose handling means for the vehicle
SAFETY_LEVELS = {
    Safety.OK: OK,
    Safety.NO_POSE: WARN,          # idle and no fresh pose: take-off refused
    Safety.HOLDING: WARN,          # airborne on a stale pose: holding level
    Safety.BLIND_DESCENT: ERROR,   # pose lost: descending blind
    Safety.LANDED_BLIND: ERROR,    # the blind descent stopped the motors
    Safety.EMERGENCY: ERROR,
}
AIRBORNE = (State.TAKING_OFF, State.AUTOMATIC, State.LANDING)


def thrust_saturated(state: State, thrust: float, min_output: float, max_output: float) -> bool:
    """True when a closed-loop thrust command sits at the Z loop's output limit."""
    return state in (State.AUTOMATIC, State.LANDING) and (thrust >= max_output or thrust <= min_output)


class SaturationWindow:
    """Which share of the control steps of the last ``window_s`` s had the thrust at a limit."""

    def __init__(self, window_s: float = SATURATION_WINDOW_S) -> None:
        self.window_s = window_s
        self._steps: Deque[Tuple[float, bool]] = deque()
        self._saturated = 0

    def record(self, now: float, saturated: bool) -> None:
        self._steps.append((now, saturated))
        self._saturated += saturated
        while self._steps and now - self._steps[0][0] > self.window_s + 1e-9:
            self._saturated -= self._steps.popleft()[1]

    def share(self) -> Optional[float]:
        return self._saturated / len(self._steps) if self._steps else None

    @property
    def steps(self) -> int:
        return len(self._steps)


Values = Tuple[Tuple[str, str], ...]


def controller_entry(state: State, safety: Safety, pose_age_s: Optional[float], pose_timeout_s: float,
                     thrust: float, saturation: Optional[float], steps: int) -> Tuple[int, str, Values]:
    """(level, message, values) of the controller's entry."""
    level = SAFETY_LEVELS.get(safety, WARN)
    message = "%s: %s" % (state.value, safety.value)
    if state in AIRBORNE and saturation is not None and saturation > SATURATION_WARN:
        level = max(level, WARN)
        message += "; thrust at its limit in %.0f %% of the last %.0f s (too heavy, battery low, or gains)" % (
            saturation * 100, SATURATION_WINDOW_S)
    values = (("state", state.value), ("safety", safety.value),
              ("pose age [s]", "%.3f" % pose_age_s if pose_age_s is not None else "never"),
              ("pose timeout [s]", "%.3f" % pose_timeout_s), ("thrust", "%.0f" % thrust),
              ("thrust saturated share", "%.2f" % saturation if saturation is not None else "n/a"),
              ("control steps in window", str(steps)))
    return level, message, values
