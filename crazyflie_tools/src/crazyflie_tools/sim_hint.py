"""When no Crazyradio is plugged in but a simulated world is running, say how to reach it.

A reader who starts the simulator and then types a tool's command as for hardware gets "no
Crazyradio found"; the tools only use the world's fake dongle with ``CRAZYFLIE_BACKEND=sim``.
"""
from __future__ import annotations

import os
from typing import Optional

from crazyflie_driver import usb_choice

PROBE_TIMEOUT_S = 0.5   # a local world answers in milliseconds; nothing listening fails at once


def sim_world_address() -> str:
    """The address the tools would use with CRAZYFLIE_BACKEND=sim."""
    return os.environ.get(usb_choice.ENV_SIM_ADDRESS, "").strip() or usb_choice.DEFAULT_SIM_ADDRESS


def world_listening(address: str, timeout: float = PROBE_TIMEOUT_S) -> bool:
    """True when a simulated world answers at ``address`` (host:port)."""
    from crazyflie_driver.errors import CrazyflieError
    from crazyflie_driver.sim.air.medium import RemoteMedium  # lazily: hardware runs never load the sim
    try:
        medium = RemoteMedium(address, timeout=timeout)
    except CrazyflieError:
        return False
    try:
        medium.ping()
        return True
    except (CrazyflieError, OSError, ValueError):
        return False
    finally:
        medium.close()


def sim_hint(prog: str) -> Optional[str]:
    """The sentence to add to "no Crazyradio found", or None (already on the simulator, or none running)."""
    if usb_choice.current_override() is not None:
        return None
    if os.environ.get(usb_choice.ENV_BACKEND, "").strip().lower() == "sim":
        return None
    address = sim_world_address()
    if not world_listening(address):
        return None
    return ("a simulated world is listening at %s: to use its fake Crazyradio, run "
            "CRAZYFLIE_BACKEND=sim rosrun crazyflie_tools %s" % (address, prog))
