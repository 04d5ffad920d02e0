"""``swarm.input.waitUntilButtonPressed()``: the operator's go-ahead between a script's phases.

Crazyswarm waits for a joystick button, or a key without a joystick. Here: Enter on the terminal.
In a simulation without a terminal (a test, a batch run; ``--sim`` or a running simulated world) it
returns at once, so simulated runs go through unattended; without a terminal on a real swarm it
refuses, because no one could press it.
"""
from __future__ import annotations

import sys

from crazyflie_driver.errors import CrazyflieError


class Input:
    def __init__(self, time_helper, simulated: bool) -> None:
        self.timeHelper = time_helper
        self.simulated = simulated

    def waitUntilButtonPressed(self) -> None:
        if sys.stdin is not None and sys.stdin.isatty():
            input("pycrazyswarm: press Enter to continue ")
            return
        if self.simulated:
            return
        raise CrazyflieError("waitUntilButtonPressed: no terminal to press Enter on (stdin is not a tty) and this is "
                             "not a simulation; run the script from a terminal")

    def checkIfButtonIsPressed(self) -> bool:
        return False
