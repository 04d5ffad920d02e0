"""``swarm.input.waitUntilButtonPressed()``: the operator's go-ahead between a script's phases.

Crazyswarm waits for a joystick button, or a key without a joystick. Here: Enter on the terminal,
or a line on a piped stdin (a supervising program's go-ahead). With no terminal and nothing more to
read (stdin closed or at its end) a simulation (``--sim`` or a running simulated world) goes on at
once, so simulated runs go through unattended; a real swarm refuses, because no one could press it.
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
        if sys.stdin is not None and not sys.stdin.closed and sys.stdin.readline():
            return
        if self.simulated:
            return
        raise CrazyflieError("waitUntilButtonPressed: no terminal to press Enter on (stdin is not a tty and had no "
                             "line to read) and this is not a simulation; run the script from a terminal, or "
                             "pipe it a line per go-ahead")

    def checkIfButtonIsPressed(self) -> bool:
        return False
