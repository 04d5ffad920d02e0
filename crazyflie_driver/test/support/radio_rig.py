"""One simulated Crazyflie reachable through the whole radio stack, in one process, stepped by the caller.

The path is the real one: ``Crazyflie`` facade -> ``RadioLink`` -> ``Crazyradio`` -> ``FakeUsbBackend``
-> ``LocalMedium`` -> ``SimulatedCrazyflie`` -> ``World`` vehicle, with a ``MocapModel`` watching the
world. The fake dongle costs no time (``DongleTiming.instant()``) and the world runs at speed 0 with
nobody stepping it but the caller, so a flight is deterministic for a given seed and runs as fast
as the machine allows: a closed loop sends a setpoint, calls ``advance``, reads ``mocap``, and so on.
Used by the closed-loop tests and the hover benchmark.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Sequence, Tuple

import numpy as np

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from crazyflie_driver.sim.onboard.ticks import FIRMWARE_TICK_S
from crazyflie_driver.sim.room.mocap import MocapModel
from crazyflie_driver.sim.room.world import World

DEFAULT_URI = "radio://0/80/2M/E7E7E7E701"



class RadioRig:
    """A world, one vehicle with its simulated firmware on a fake Crazyradio, and motion capture."""

    def __init__(self, uri: str = DEFAULT_URI, firmware: str = "current", mass: float = 0.030,
                 position: Sequence[float] = (0.0, 0.0, 0.0), yaw: float = 0.0, seed: int = 1,
                 mocap: Optional[Dict[str, Any]] = None, name: str = "cf1") -> None:
        """``mocap``: keyword arguments for ``MocapModel`` (default: its own noise, rate and latency)."""
        self.uri = parse_uri(uri)
        self.world = World(speed=0.0, seed=seed)
        self.vehicle = self.world.add_vehicle(name, position=position, yaw=yaw, firmware=firmware, mass=mass)
        self.firmware = SimulatedCrazyflie(self.uri.address, self.vehicle, firmware=firmware)
        self.world.add_tick_listener(self.firmware.tick, FIRMWARE_TICK_S)
        options = dict(seed=seed + 1)
        options.update(mocap or {})
        self.mocap = MocapModel(self.world, **options).attach()
        self.medium = LocalMedium(dongles=1, seed=seed + 2)
        self.medium.add_crazyflie(self.firmware, self.uri.channel, self.uri.datarate)
        self.backend = FakeUsbBackend(self.medium, dongles=1, timing=DongleTiming.instant())
        self.manager = RadioManager(backend=self.backend)

    def connect(self, cache_dir: Optional[str] = None, timeout: float = 1.0) -> Crazyflie:
        """A connected ``Crazyflie`` facade for this rig's URI (over the fake dongle)."""
        cf = Crazyflie(self.uri, radio_manager=self.manager, cache_dir=cache_dir, timeout=timeout)
        cf.connect()
        return cf

    def advance(self, seconds: float) -> None:
        """Step the world (and so the firmware timers and the motion capture) by ``seconds``."""
        ticks = int(round(seconds / FIRMWARE_TICK_S))
        if ticks < 0:
            raise ValueError("cannot advance the world by a negative time (%r s)" % (seconds,))
        self.world.step(ticks)

    @property
    def time(self) -> float:
        return self.world.time

    def mocap_pose(self) -> Optional[Tuple[np.ndarray, np.ndarray, float]]:
        """Newest delivered motion-capture pose of the vehicle: position, quaternion xyzw, capture stamp."""
        return self.mocap.latest_pose(self.vehicle.name)

    def true_position(self) -> np.ndarray:
        return self.vehicle.pose()[0]
