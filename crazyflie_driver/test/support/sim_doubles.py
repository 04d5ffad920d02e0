"""Small stand-ins for the world and its vehicles, for tests of the simulated firmware and server."""
from __future__ import annotations

import threading
from typing import Callable, Dict, List, Tuple


class FakeVehicle:
    """Records what the firmware asks of it; readings come from a dict (default 0)."""

    def __init__(self, name: str = "cf1", readings: Dict[str, float] = None,
                 defaults: Dict[str, float] = None) -> None:
        self.name = name
        self.t = 0.0
        self.readings = dict(readings or {})
        self.defaults = dict(defaults or {})
        self.written: List[Tuple[str, float]] = []
        self.setpoints: List[Tuple[float, float, float, int]] = []
        self.estops = 0
        self.reboots = 0

    def time(self) -> float:
        return self.t

    def read(self, name: str) -> float:
        return self.readings.get(name, 0.0)

    def param_defaults(self) -> Dict[str, float]:
        return dict(self.defaults)

    def write_param(self, name: str, value: float) -> None:
        self.written.append((name, value))

    def set_rpyt(self, roll: float, pitch: float, yaw: float, thrust: int) -> None:
        self.setpoints.append((roll, pitch, yaw, thrust))

    def emergency_stop(self) -> None:
        self.estops += 1

    def reboot(self) -> None:
        self.reboots += 1


class FakeWorld:
    """World contract without physics: ``advance(dt)`` moves time and fires tick listeners."""

    def __init__(self) -> None:
        self.time = 0.0
        self.speed = 1.0            # world seconds per wall second, as its radio replies report it
        self._vehicles: Dict[str, FakeVehicle] = {}
        self._listeners: List[Tuple[Callable[[float], None], float, List[float]]] = []
        self._lock = threading.Lock()
        self.started = self.stopped = False

    def add_vehicle(self, name, position=(0.0, 0.0, 0.0), yaw=0.0, firmware="current", mass=None):
        v = FakeVehicle(name)
        v.position = tuple(position)
        v.firmware = firmware
        self._vehicles[name] = v
        return v

    def remove_vehicle(self, name):
        del self._vehicles[name]

    def vehicle(self, name):
        return self._vehicles[name]

    def vehicles(self):
        return list(self._vehicles.values())

    def add_tick_listener(self, fn, period):
        self._listeners.append((fn, period, [0.0]))

    def advance(self, dt: float, step: float = 0.001) -> None:
        n = int(round(dt / step))
        for _ in range(n):
            with self._lock:
                self.time += step
                for v in self._vehicles.values():
                    v.t = self.time
                for fn, period, last in self._listeners:
                    if self.time - last[0] >= period - 1e-9:
                        last[0] = self.time
                        fn(self.time)

    def start(self):
        self.started = True

    def stop(self):
        self.stopped = True


def drain(cf) -> List[bytes]:
    """Every packet a simulated Crazyflie has queued for the host, oldest first (the queue is left empty)."""
    return list(iter(cf.pop_outgoing, None))
