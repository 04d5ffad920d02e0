"""Which pyusb backend a process's Crazyradios use: real libusb, or a fake dongle in the simulated world.

Only entry points (nodes, tools, tests, benchmarks) call this; ``radio/`` takes the backend it is given.

* default: ``None``, i.e. pyusb picks libusb1 (real hardware);
* ``CRAZYFLIE_BACKEND=sim``: one shared ``FakeUsbBackend`` attached to the world server at
  ``CRAZYFLIE_SIM_ADDRESS`` (default 127.0.0.1:19840), so nodes and tools fly simulated Crazyflies
  without a code change; its dongles time their transfers in world time (the world's speed comes
  with every radio reply);
* ``use_backend(b)``: an explicit backend for this process (tests inject an in-process fake),
  usable as a plain call or as a context manager that restores the previous choice.
"""
from __future__ import annotations

import os
import threading
from typing import Optional

from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.radio.crazyradio import Crazyradio
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.radio.usb_crazyflie import UsbCrazyflie

ENV_BACKEND = "CRAZYFLIE_BACKEND"
ENV_SIM_ADDRESS = "CRAZYFLIE_SIM_ADDRESS"
DEFAULT_SIM_ADDRESS = "127.0.0.1:19840"

_lock = threading.Lock()
_override = None
_sim_backends: dict = {}
_manager: Optional[RadioManager] = None


def get_backend():
    """The backend to pass to pyusb: None (libusb1), the injected one, or the simulator's fake."""
    if _override is not None:
        return _override
    name = os.environ.get(ENV_BACKEND, "").strip().lower()
    if name in ("", "libusb", "libusb1", "usb", "hw", "hardware"):
        return None
    if name == "sim":
        return _sim_backend(os.environ.get(ENV_SIM_ADDRESS, DEFAULT_SIM_ADDRESS))
    raise CrazyflieError("%s=%r is not understood: leave it unset for real Crazyradios or set it to 'sim'"
                         % (ENV_BACKEND, name))


def _sim_backend(address: str):
    # Imported here: a process flying real hardware never loads the simulator.
    from crazyflie_driver.sim.air.dongle_timing import DongleClock
    from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
    from crazyflie_driver.sim.air.medium import RemoteMedium, parse_address
    try:
        host, port = parse_address(address)
    except ValueError as exc:
        raise CrazyflieError("%s=%r is not a loopback host:port (e.g. %s): %s"
                             % (ENV_SIM_ADDRESS, address, DEFAULT_SIM_ADDRESS, exc)) from None
    with _lock:
        backend = _sim_backends.get((host, port))
        if backend is None:
            medium = RemoteMedium(host, port)
            backend = FakeUsbBackend(medium, dongles=max(1, medium.dongle_count()), model=medium.dongle_model(),
                                     usb_crazyflies=medium.usb_count(),
                                     clock=DongleClock.world_paced(medium))
            _sim_backends[(host, port)] = backend
        return backend


class use_backend:
    """Make ``get_backend()`` return ``backend`` (None = back to the environment's choice).

    ``use_backend(fake)`` takes effect at once; ``with use_backend(fake): ...`` also restores the
    previous backend on exit.
    """

    def __init__(self, backend) -> None:
        global _override
        self._previous = _override
        self.backend = backend
        _override = backend

    def __enter__(self):
        return self.backend

    def __exit__(self, *exc) -> None:
        global _override
        _override = self._previous


def current_override() -> Optional[object]:
    """The backend set by ``use_backend``, if any."""
    return _override


def open_radio(index: int) -> Crazyradio:
    """Crazyradio ``index`` on the backend chosen now (the simulated world is looked up only here)."""
    return Crazyradio(index, backend=get_backend())


def open_usb_crazyflie(index: int):
    """Crazyflie ``usb://index`` on the backend chosen now (a ``usb_crazyflie.UsbCrazyflie``)."""
    return UsbCrazyflie(index, backend=get_backend())


def radio_manager() -> RadioManager:
    """The process-wide ``RadioManager`` of an entry point: every Crazyflie of the process shares
    its dongles, each opened through ``open_radio`` when a link first needs it (a simulated world
    that is still starting is then retried by the caller, as a dongle not plugged in yet)."""
    global _manager
    with _lock:
        if _manager is None:
            _manager = RadioManager(radio_factory=open_radio, usb_factory=open_usb_crazyflie)
        return _manager
