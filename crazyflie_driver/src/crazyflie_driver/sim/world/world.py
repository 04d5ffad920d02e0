"""The simulated world: Crazyflies stepped together at 1 kHz with numpy, in real time or faster.

`World` owns one row per vehicle in each model's arrays (physics `BodyStates`, onboard controller,
sensors, battery) and advances all of them with a handful of numpy expressions per tick, so its
cost grows slowly with the number of vehicles. `Vehicle` is the per-Crazyflie handle the
simulated firmware talks to (see the Vehicle contract in docs/architecture.md); every method takes
the world lock, so it may be called from any thread while the world steps.
"""
from __future__ import annotations

import logging
import math
import threading
import time as _time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from crazyflie_driver.sim.world import battery as _battery
from crazyflie_driver.sim.world import sensors as _sensors
from crazyflie_driver.sim.world.stabilizer import GEN_CURRENT, LOCK_EMERGENCY, LOCK_NAMES, LOCK_NONE, LOCK_TUMBLE, OnboardController, \
    check_generation, default_params
from crazyflie_driver.sim.world.physics import BodyStates, RigidBodyBackend, VehicleParams, quat_to_matrix

_log = logging.getLogger(__name__)

TICK_S = 0.001
BATTERY_EVERY = 10                 # ticks between battery updates
MAX_LAG_S = 0.25                   # real-time thread: further behind than this, it stops catching up


class Vehicle:
    """One simulated Crazyflie as the firmware side sees it. Thread safe."""

    def __init__(self, world: "World", name: str, firmware: str, params: VehicleParams) -> None:
        self.name = name
        self.firmware = firmware
        self.params = params
        self._world = world
        self._row = -1
        self._cache: Dict[str, Dict[str, float]] = {}
        self._cache_tick = -1
        self.external_position: Optional[Tuple[float, float, float]] = None
        self.last_generic_setpoint: Optional[Tuple[int, bytes]] = None

    @property
    def removed(self) -> bool:
        return self._row < 0

    # --- the Vehicle contract ----------------------------------------------------------------
    def time(self) -> float:
        return self._world.time

    def read(self, name: str) -> float:
        """Current value of a firmware log variable; 0.0 for names the simulation does not model."""
        w = self._world
        with w._lock:
            if self._row < 0:
                return 0.0
            if self._cache_tick != w.ticks:
                self._cache.clear()
                self._cache_tick = w.ticks
            group = name.partition(".")[0]
            values = self._cache.get(group)
            if values is None:
                values = w._readings(self._row, group)
                self._cache[group] = values
            return float(values.get(name, 0.0))

    def param_defaults(self) -> Dict[str, float]:
        return default_params(self.firmware)

    def write_param(self, name: str, value: float) -> None:
        w = self._world
        with w._lock:
            if self._row >= 0:
                w.onboard.set_param(self._row, str(name), float(value))

    def set_rpyt(self, roll: float, pitch: float, yaw: float, thrust: int) -> None:
        w = self._world
        with w._lock:
            if self._row >= 0:
                w.onboard.set_rpyt(self._row, roll, pitch, yaw, thrust, w.time)

    def emergency_stop(self) -> None:
        w = self._world
        with w._lock:
            if self._row >= 0:
                w.onboard.lock(self._row, LOCK_EMERGENCY)

    def pose(self) -> Tuple[np.ndarray, np.ndarray]:
        w = self._world
        with w._lock:
            if self._row < 0:
                raise KeyError("vehicle %r was removed from the world" % self.name)
            return w.bodies.position[self._row].copy(), w.bodies.quaternion[self._row].copy()

    # --- optional hooks the simulated firmware uses ------------------------------------------
    def reboot(self) -> None:
        """Power cycle of the STM: controller back to boot (gains, thrust lock, locks cleared)."""
        w = self._world
        with w._lock:
            if self._row >= 0:
                yaw = w.onboard.s.attitude[self._row, 2]
                w.onboard.s.boot(self._row, self.firmware, w.time, float(yaw))

    def stop_motors(self) -> None:
        """Generic setpoint type 0 (stop): the same as a zero RPYT setpoint."""
        self.set_rpyt(0.0, 0.0, 0.0, 0)

    def set_external_position(self, x: float, y: float, z: float) -> None:
        with self._world._lock:
            self.external_position = (float(x), float(y), float(z))

    def set_generic_setpoint(self, kind: int, data: bytes) -> None:
        with self._world._lock:
            self.last_generic_setpoint = (int(kind), bytes(data))

    # --- inspection and test helpers ---------------------------------------------------------
    def state(self) -> Dict[str, object]:
        """True state and controller status (JSON-friendly)."""
        w = self._world
        with w._lock:
            i = self._row
            if i < 0:
                return {"name": self.name, "removed": True}
            b, o = w.bodies, w.onboard.s
            return {"name": self.name, "firmware": self.firmware, "time": w.time,
                    "position": b.position[i].tolist(), "velocity": b.velocity[i].tolist(),
                    "quaternion": b.quaternion[i].tolist(), "omega": b.omega[i].tolist(),
                    "on_ground": bool(b.on_ground[i]), "motors": o.motors[i].tolist(),
                    "thrust": float(o.thrust[i]), "thrust_locked": bool(o.thrust_locked[i]),
                    "locked": LOCK_NAMES[int(o.lock[i])], "vbat": float(w.battery.vbat[i]),
                    "mass": self.params.mass}

    def velocity(self) -> np.ndarray:
        with self._world._lock:
            return self._world.bodies.velocity[self._row].copy()

    def motors(self) -> np.ndarray:
        """Motor commands (4,) the firmware drives, 0..65535."""
        with self._world._lock:
            return self._world.onboard.s.motors[self._row].copy()

    @property
    def lock_reason(self) -> str:
        """Why the motors are held off until a reboot ('' when they are not)."""
        with self._world._lock:
            return LOCK_NAMES[int(self._world.onboard.s.lock[self._row])] if self._row >= 0 else ""

    def place(self, position: Sequence[float], yaw: float = 0.0) -> None:
        """Teleport (at rest) - for tests and scenario setup."""
        w = self._world
        with w._lock:
            i = self._row
            b = w.bodies
            b.position[i] = np.asarray(position, dtype=float)
            b.velocity[i] = 0.0
            b.omega[i] = 0.0
            b.quaternion[i] = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
            self._cache_tick = -1

    def __repr__(self) -> str:
        return "Vehicle(%r, firmware=%r)" % (self.name, self.firmware)


class World:
    """All simulated vehicles, stepped together; optionally by a real-time background thread."""

    def __init__(self, speed: float = 1.0, seed: Optional[int] = None, physics=None,
                 ground_asl: float = 0.0) -> None:
        if not (speed >= 0 and math.isfinite(speed)):
            raise ValueError("world speed must be >= 0 (0 = as fast as possible), got %r" % (speed,))
        self.speed = float(speed)
        self.physics = physics if physics is not None else RigidBodyBackend()
        self.ground_asl = float(ground_asl)
        self.ticks = 0
        self.bodies = BodyStates()
        self.onboard = OnboardController()
        self.sensors = _sensors.SensorStates()
        self.battery = _battery.BatteryStates()
        self.rng = np.random.default_rng(seed)
        self._lock = threading.RLock()
        self._vehicles: Dict[str, Vehicle] = {}
        self._order: List[Vehicle] = []
        self._listeners: List[list] = []           # [fn, period, next_time]
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self.realtime_factor = 0.0                 # measured by the background thread
        self.overruns = 0                          # times the thread could not keep up and let go

    @property
    def time(self) -> float:
        return self.ticks * TICK_S

    # --- vehicles ----------------------------------------------------------------------------
    def add_vehicle(self, name: str, position=(0.0, 0.0, 0.0), yaw: float = 0.0, firmware: str = GEN_CURRENT,
                    mass: Optional[float] = None, params: Optional[VehicleParams] = None,
                    battery_charge: float = 1.0) -> Vehicle:
        """A Crazyflie at `position` (m) with `yaw` (rad), at rest on the floor when z <= 0."""
        name = str(name)
        check_generation(firmware)
        pos = np.asarray(position, dtype=float).reshape(-1)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ValueError("position of vehicle %r must be 3 finite numbers, got %r" % (name, position))
        pos[2] = max(pos[2], 0.0)
        if params is None:
            params = VehicleParams() if mass is None else VehicleParams(mass=float(mass))
        elif mass is not None:
            raise ValueError("give either mass or params for vehicle %r, not both" % name)
        with self._lock:
            if name in self._vehicles:
                raise ValueError("a vehicle called %r is already in the world" % name)
            v = Vehicle(self, name, firmware, params)
            v._row = self.bodies.add(params, pos, float(yaw))
            self.onboard.s.add(firmware, self.time, math.degrees(float(yaw)))
            self.sensors.add(self.rng)
            self.battery.add(battery_charge)
            self._vehicles[name] = v
            self._order.append(v)
            return v

    def remove_vehicle(self, name: str) -> None:
        with self._lock:
            v = self._vehicles.pop(name, None)
            if v is None:
                raise KeyError("no vehicle called %r in the world" % name)
            i = v._row
            for model in (self.bodies, self.onboard.s, self.sensors, self.battery):
                model.delete_row(i)
            self._order.pop(i)
            for k, other in enumerate(self._order):
                other._row = k
            v._row = -1

    def vehicle(self, name: str) -> Vehicle:
        with self._lock:
            try:
                return self._vehicles[name]
            except KeyError:
                raise KeyError("no vehicle called %r in the world" % name) from None

    def vehicles(self) -> List[Vehicle]:
        with self._lock:
            return list(self._order)

    def poses(self) -> Tuple[List[str], np.ndarray, np.ndarray]:
        """Names, positions (N,3) and quaternions (N,4, xyzw) of all vehicles at this instant."""
        with self._lock:
            return ([v.name for v in self._order], self.bodies.position.copy(), self.bodies.quaternion.copy())

    # --- stepping ----------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        """Advance `n` firmware ticks (1 ms each) for all vehicles; tick listeners run in between."""
        for _ in range(int(n)):
            with self._lock:
                self._tick()
                now = self.time
                due = [l for l in self._listeners if now >= l[2] - 1e-9]
                for l in due:
                    l[2] += l[1]
                    if l[2] <= now:
                        l[2] = now + l[1]
            for l in due:
                try:
                    l[0](now)
                except Exception:
                    _log.exception("world tick listener %r failed", l[0])

    def _tick(self) -> None:
        k = self.ticks
        if len(self._order):
            b = self.bodies
            hover = b.mass * b.gravity
            thrust_fraction = b.thrust.sum(axis=1) / hover
            gyro = _sensors.gyro_measured(self.sensors, b.omega, thrust_fraction, self.rng) if k % 2 == 0 \
                else None
            motors = self.onboard.update(k, self.time, b, gyro, self.battery.empty)
            self.physics.step(b, motors, TICK_S)
            if k % BATTERY_EVERY == 0:
                _battery.update(self.battery, TICK_S * BATTERY_EVERY, b.thrust)
        self.ticks = k + 1

    # --- readings ----------------------------------------------------------------------------
    def _readings(self, i: int, group: str) -> Dict[str, float]:
        """Log variables of one group for vehicle row `i` (called under the lock)."""
        b, o = self.bodies, self.onboard.s
        if group in ("acc", "gyro", "mag", "mag_raw"):
            r = quat_to_matrix(b.quaternion[i:i + 1])[0]
            fraction = float(b.thrust[i].sum() / (b.mass[i] * b.gravity[i]))
            return _sensors.imu_readings(self.sensors, i, b.specific_force[i], b.omega[i], r, fraction, self.rng)
        if group == "baro":
            return _sensors.baro_readings(self.sensors, i, float(b.position[i, 2]), self.ground_asl, self.rng)
        if group == "pm":
            return {"pm.vbat": float(self.battery.vbat[i]), "pm.state": float(self.battery.state[i]),
                    "pm.batteryLevel": float(_battery.battery_level(float(self.battery.charge[i])))}
        if group == "stabilizer":
            att = o.attitude[i]
            return {"stabilizer.roll": float(att[0]), "stabilizer.pitch": float(att[1]),
                    "stabilizer.yaw": float(att[2]), "stabilizer.thrust": float(o.thrust[i])}
        if group == "stateEstimate":
            att = o.attitude[i]
            p, v = b.position[i], b.velocity[i]
            return {"stateEstimate.x": float(p[0]), "stateEstimate.y": float(p[1]), "stateEstimate.z": float(p[2]),
                    "stateEstimate.vx": float(v[0]), "stateEstimate.vy": float(v[1]),
                    "stateEstimate.vz": float(v[2]), "stateEstimate.roll": float(att[0]),
                    "stateEstimate.pitch": float(att[1]), "stateEstimate.yaw": float(att[2])}
        if group == "motor":
            m = o.motors[i]
            return {"motor.m%d" % (k + 1): float(int(m[k])) for k in range(4)}
        if group == "sys":
            locked = int(o.lock[i])
            return {"sys.canfly": float(locked == LOCK_NONE), "sys.isFlying": float(o.thrust[i] > 0.0),
                    "sys.isTumbled": float(locked == LOCK_TUMBLE)}
        if group == "controller":
            d, r = o.attitude_desired[i], o.rate_desired[i]
            return {"controller.roll": float(d[0]), "controller.pitch": float(d[1]), "controller.yaw": float(d[2]),
                    "controller.rollRate": float(r[0]), "controller.pitchRate": float(r[1]),
                    "controller.yawRate": float(r[2])}
        return {}

    def add_tick_listener(self, fn: Callable[[float], None], period: float) -> None:
        """Call fn(world_time) every `period` seconds of world time (from the stepping thread)."""
        if not period > 0:
            raise ValueError("tick listener period must be > 0 s, got %r" % (period,))
        with self._lock:
            self._listeners.append([fn, float(period), self.time + float(period)])

    def remove_tick_listener(self, fn: Callable[[float], None]) -> None:
        with self._lock:
            self._listeners = [l for l in self._listeners if l[0] is not fn]

    # --- real time ---------------------------------------------------------------------------
    def start(self) -> None:
        """Step in a background thread at `speed` × real time (speed 0: as fast as possible)."""
        with self._lock:
            if self._thread is not None and self._thread.is_alive():
                return
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="sim-world", daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout)
        self._thread = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        wall0, world0 = _time.monotonic(), self.time
        meter_wall, meter_world = wall0, world0
        while not self._stop.is_set():
            now = _time.monotonic()
            if now - meter_wall >= 1.0:
                self.realtime_factor = (self.time - meter_world) / (now - meter_wall)
                meter_wall, meter_world = now, self.time
            if self.speed <= 0:
                self.step(10)
                continue
            due = int((world0 + (now - wall0) * self.speed - self.time) / TICK_S)
            if due <= 0:
                self._stop.wait(min(0.002, (1 - due) * TICK_S / self.speed))
                continue
            if due * TICK_S > MAX_LAG_S:
                self.overruns += 1
                wall0, world0 = now, self.time
                due = 1
            self.step(min(due, 20))
