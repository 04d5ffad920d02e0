"""What the chapter's joystick buttons do: 0 land, 1 emergency, 2 takeoff, 4 headlight toggle.

Actions fire on the press (rising edge) only, so holding a button does not repeat it.
"""
from __future__ import annotations

from typing import List, Optional, Sequence

LAND = 0
EMERGENCY = 1
TAKEOFF = 2
HEADLIGHT = 4

ACTIONS = {LAND: "land", EMERGENCY: "emergency", TAKEOFF: "takeoff", HEADLIGHT: "headlight"}


class ButtonEdges:
    """Turns successive Joy button arrays into the list of buttons just pressed."""

    def __init__(self) -> None:
        self._last: Optional[List[int]] = None

    def pressed(self, buttons: Sequence[int]) -> List[int]:
        last = self._last or [0] * len(buttons)
        if len(last) < len(buttons):
            last = list(last) + [0] * (len(buttons) - len(last))
        out = [i for i, b in enumerate(buttons) if b and not last[i]]
        self._last = list(buttons)
        return out


def actions_for(pressed: Sequence[int]) -> List[str]:
    """Names of the actions for the pressed buttons, in button order (emergency first if present)."""
    names = [ACTIONS[i] for i in pressed if i in ACTIONS]
    if "emergency" in names:  # nothing else matters once emergency is asked for
        return ["emergency"]
    return names
