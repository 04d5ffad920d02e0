"""The simulated world: Crazyflies stepped together at 1 kHz with numpy, in real time or faster.

``World`` owns one row per vehicle in each model's arrays (physics ``BodyStates``, onboard controller,
sensors, battery) and advances all of them with a handful of numpy expressions per tick, so its
cost grows slowly with the number of vehicles. ``Vehicle`` is the per-Crazyflie handle the
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

from crazyflie_driver.sim.onboard import flight as _flight
from crazyflie_driver.sim.onboard.stabilizer import (
    GEN_CURRENT,
    LOCK_ASSERT,
    LOCK_EMERGENCY,
    LOCK_NAMES,
    LOCK_NONE,
    LOCK_TUMBLE,
    PLATFORM_BRUSHLESS,
    PLATFORM_CF2,
    PLATFORMS,
    TUMBLE_TILT_COS,
    OnboardController,
    check_generation,
    default_params,
)
from crazyflie_driver.sim.onboard.ticks import CONTROL_PERIOD_S, CONTROL_TICKS, FIRMWARE_TICK_S
from crazyflie_driver.sim.room import battery as _battery
from crazyflie_driver.sim.room import sensors as _sensors
from crazyflie_driver.sim.room.physics import BodyStates, Drive, RigidBodyBackend, VehicleParams, quat_to_matrix

_log = logging.getLogger(__name__)

BATTERY_EVERY = 10                 # ticks between battery updates
MAX_LAG_S = 0.25                   # real-time thread: further behind than this [world s], it stops catching up
WAKE_PERIOD_S = CONTROL_TICKS * FIRMWARE_TICK_S   # real-time thread: world time stepped per wake-up
MAX_CHUNK_TICKS = 20               # real-time thread: most ticks stepped in one go when catching up
FAST_CHUNK_TICKS = 10              # speed 0: ticks per loop
METER_PERIOD_S = 1.0               # wall time over which the real-time factor is measured
BEHIND_FACTOR = 0.95               # below this fraction of its speed the world counts as behind
BEHIND_WARNING_PERIOD_S = 10.0     # at most one "behind real time" warning this often
_ONES4 = np.ones(4)


class Vehicle:
    """One simulated Crazyflie as the firmware side sees it. Thread safe."""

    def __init__(self, world: World, name: str, firmware: str, params: VehicleParams,
                 platform: str = PLATFORM_CF2) -> None:
        self.name = name
        self.firmware = firmware
        self.platform = platform
        self.params = params
        self._world = world
        self._row = -1
        self._cache: Dict[str, Dict[str, float]] = {}
        self._cache_tick = -1

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
        out = default_params(self.firmware)
        if self.firmware == GEN_CURRENT:          # the 2016.02 firmware had no onboard position control
            out.update(_flight.default_params())
        return out

    def write_param(self, name: str, value: float) -> None:
        w = self._world
        with w._lock:
            i = self._row
            if i >= 0 and not w.onboard.set_param(i, str(name), float(value)):
                w.flight.set_param(i, str(name), float(value), w.bodies.position[i].copy(), w.time)

    def set_rpyt(self, roll: float, pitch: float, yaw: float, thrust: int) -> None:
        w = self._world
        with w._lock:
            if self._row >= 0:
                w.flight.release(self._row)
                w.onboard.set_rpyt(self._row, roll, pitch, yaw, thrust, w.time)

    def emergency_stop(self) -> None:
        w = self._world
        with w._lock:
            if self._row >= 0:
                w.onboard.lock(self._row, LOCK_EMERGENCY, w.time)

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
                w.onboard.s.boot(self._row, self.firmware, w.time, float(yaw), self.platform)
                w.onboard.dirty = True
                w.flight.boot(self._row, w.bodies.position[self._row].copy(), w.time)

    @property
    def auto_arm(self) -> bool:
        """Whether its firmware arms itself at boot (not a Brushless platform)."""
        return self.platform != PLATFORM_BRUSHLESS

    def set_armed(self, armed: bool) -> None:
        """The supervisor armed or disarmed it: a Brushless platform's motors run only armed."""
        w = self._world
        with w._lock:
            if self._row >= 0:
                w.onboard.set_armed(self._row, armed)

    def stop_motors(self) -> None:
        """Generic setpoint type 0 (stop): the same as a zero RPYT setpoint."""
        self.set_rpyt(0.0, 0.0, 0.0, 0)

    def set_setpoint(self, setpoint) -> None:
        """A decoded generic setpoint (``onboard.setpoint.OnboardSetpoint``) at the CRTP priority."""
        if setpoint.is_stop:
            self.stop_motors()
            return
        w = self._world
        with w._lock:
            i = self._row
            if i >= 0:
                w.flight.setpoint(i, setpoint)
                w.onboard.s.sp_time[i] = w.time
                w.onboard.dirty = True

    def notify_setpoint_stop(self) -> None:
        """Streaming setpoints end: the high-level commander takes over (idle, it stops the motors)."""
        w = self._world
        with w._lock:
            if self._row >= 0:
                w.flight.notify_stop(self._row, w.onboard.s, w.time)
                w.onboard.dirty = True

    def high_level(self, command: str, **args) -> int:
        """A high-level commander command (port 8); returns the firmware's result code."""
        w = self._world
        with w._lock:
            if self._row < 0:
                return 0
            w.onboard.dirty = True
            return w.flight.high_level(self._row, command, args, w.bodies, w.onboard.s, w.ground_asl, w.time)

    def external_measurement(self, position, quaternion=None) -> bool:
        """External position (m) and optional quaternion (x, y, z, w) for the onboard estimator."""
        w = self._world
        with w._lock:
            i = self._row
            return i >= 0 and w.flight.measure(i, position, quaternion, w.bodies, w.time)

    def battery(self) -> Dict[str, float]:
        """The cell now: state of charge 0..1, voltage under load (V), current (A), power state."""
        w = self._world
        with w._lock:
            b, i = w.battery, self._row
            return {"charge": float(b.charge[i]), "vbat": float(b.vbat[i]), "current": float(b.current[i]),
                    "state": int(b.state[i])}

    def set_battery_charge(self, charge: float) -> None:
        """Drain or charge the cell to ``charge`` (0..1) at once (fault injection)."""
        w = self._world
        with w._lock:
            _battery.set_charge(w.battery, self._row, charge)
            w.onboard.dirty = True

    def halt(self) -> None:
        """The STM32 stopped on an assert: motors off until a reboot."""
        w = self._world
        with w._lock:
            if self._row >= 0:
                w.flight.release(self._row)
                w.onboard.lock(self._row, LOCK_ASSERT, w.time)

    def supervisor_flags(self) -> Dict[str, bool]:
        """What the supervisor reports beyond the firmware's own records: locked (until reboot),
        crashed (a tumble while flying, until crash recovery), tumbled now, flying, and the
        high-level commander's flying / finished / disabled states."""
        w = self._world
        with w._lock:
            i = self._row
            if i < 0:
                return {}
            o = w.onboard.s
            lock = int(o.lock[i])
            q = w.bodies.quaternion[i]
            active, finished, disabled = w.flight.hl.status(i, w.time)
            return {"locked": lock not in (LOCK_NONE, LOCK_TUMBLE), "crashed": lock == LOCK_TUMBLE,
                    "tumbled": _tilt_cos(q) < TUMBLE_TILT_COS, "flying": bool(o.thrust[i] > 0.0),
                    "hl_active": active, "hl_finished": finished, "hl_disabled": disabled}

    def recover_crash(self) -> bool:
        """Crash recovery; True when the vehicle is not crashed afterwards (refused while tumbled)."""
        w = self._world
        with w._lock:
            i = self._row
            return i >= 0 and w.onboard.recover(i, _tilt_cos(w.bodies.quaternion[i]))

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
                    # world time the supervisor locked it (None: not locked): when the motors were cut
                    "locked_at": float(o.lock_time[i]) if o.lock[i] != LOCK_NONE else None,
                    "mass": self.params.mass,
                    # world time the high-level commander's current plan began (takeoff, go_to, trajectory...)
                    "plan_begin": float(w.flight.hl.plans[i].t_begin)}

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
            b.acceleration[i] = 0.0
            b.specific_force[i] = (0.0, 0.0, b.gravity[i] if b.position[i, 2] <= 0.0 else 0.0)
            w.flight.carried(i)
            self._cache_tick = -1

    def __repr__(self) -> str:
        return "Vehicle(%r, firmware=%r)" % (self.name, self.firmware)


def _tilt_cos(q: np.ndarray) -> float:
    """Cosine of the angle between the body's z axis and the world's (quaternion x, y, z, w)."""
    return float(1.0 - 2.0 * (q[0] * q[0] + q[1] * q[1]))


class _Imu:
    """The vehicles' IMU as the onboard estimator reads it (``estimator.ImuSource``)."""

    def __init__(self, sensors: _sensors.SensorStates, bodies: BodyStates, rng: np.random.Generator) -> None:
        self._sensors, self._bodies, self._rng = sensors, bodies, rng

    def acc_raw(self, samples: int) -> np.ndarray:
        b = self._bodies
        fraction = (b.thrust @ _ONES4) * b.inv_mass[:, 0] / b.gravity
        return _sensors.acc_raw(self._sensors, b.specific_force, fraction, samples, self._rng)

    def gyro_means(self, rows: np.ndarray, omega: np.ndarray, window_s: float) -> np.ndarray:
        b = self._bodies
        fraction = (b.thrust[rows] @ _ONES4) * b.inv_mass[rows, 0] / b.gravity[rows]
        return _sensors.gyro_means(self._sensors, rows, omega, fraction, window_s, self._rng)


class World:
    """All simulated vehicles, stepped together; optionally by a real-time background thread."""

    def __init__(self, speed: float = 1.0, seed: Optional[int] = None, physics=None,
                 ground_asl: float = 0.0) -> None:
        if not (speed >= 0 and math.isfinite(speed)):
            raise ValueError("world speed must be >= 0 (0 = as fast as possible), got %r" % (speed,))
        self.speed = float(speed)
        self.physics = physics if physics is not None else RigidBodyBackend(tick=CONTROL_PERIOD_S)
        self.ground_asl = float(ground_asl)
        self.ticks = 0
        self.bodies = BodyStates()
        self.onboard = OnboardController()
        self.sensors = _sensors.SensorStates()
        self.battery = _battery.BatteryStates()
        self.flight = _flight.OnboardFlight()
        self.rng = np.random.default_rng(seed)
        self._imu = _Imu(self.sensors, self.bodies, self.rng)
        self._lock = threading.RLock()
        self._vehicles: Dict[str, Vehicle] = {}
        self._order: List[Vehicle] = []
        self._listeners: List[list] = []           # [fn, period, next_time]
        self._listeners_due = math.inf             # earliest next_time of the listeners
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self._drive: Optional[Drive] = None        # physics drive of the current motor commands
        self.realtime_factor = 0.0                 # measured by the background thread
        self.overruns = 0                          # times the thread could not keep up and let go
        self.max_lag_s = MAX_LAG_S                 # world s the thread may trail its schedule and still catch up
        # the thread's schedule: (host time.time(), world time, speed), replaced whole, never in parts
        self._anchor: Optional[Tuple[float, float, float]] = None
        self.ticks_behind = 0                      # how far world time trails wall time × speed, in ticks
        self._last_behind_warning = -math.inf
        self._speed_changed = threading.Event()    # set_speed: the thread starts a new schedule from now

    @property
    def time(self) -> float:
        return self.ticks * FIRMWARE_TICK_S

    # --- vehicles ----------------------------------------------------------------------------
    def add_vehicle(self, name: str, position=(0.0, 0.0, 0.0), yaw: float = 0.0, firmware: str = GEN_CURRENT,
                    mass: Optional[float] = None, params: Optional[VehicleParams] = None,
                    battery_charge: float = 1.0, platform: str = PLATFORM_CF2) -> Vehicle:
        """A Crazyflie at ``position`` (m) with ``yaw`` (rad), at rest on the floor when z <= 0; ``platform``
        'brushless' must be armed before its motors spin."""
        if platform not in PLATFORMS:
            raise ValueError("unknown platform %r for vehicle %r (choose one of: %s)"
                             % (platform, name, ", ".join(PLATFORMS)))
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
            v = Vehicle(self, name, firmware, params, platform)
            v._row = self.bodies.add(params, pos, float(yaw))
            self.onboard.s.add(firmware, self.time, math.degrees(float(yaw)), platform)
            self.sensors.add(self.rng)
            self.battery.add(battery_charge)
            self.flight.add(self.rng, pos, self.time)
            self._vehicles[name] = v
            self._order.append(v)
            self._drive = None
            self.onboard.dirty = True
            return v

    def remove_vehicle(self, name: str) -> None:
        with self._lock:
            v = self._vehicles.pop(name, None)
            if v is None:
                raise KeyError("no vehicle called %r in the world" % name)
            i = v._row
            for model in (self.bodies, self.onboard.s, self.sensors, self.battery) + self.flight.models:
                model.delete_row(i)
            self._order.pop(i)
            for k, other in enumerate(self._order):
                other._row = k
            v._row = -1
            self._drive = None
            self.onboard.dirty = True

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
        """Advance ``n`` firmware ticks (1 ms each) for all vehicles; tick listeners run in between."""
        for _ in range(int(n)):
            with self._lock:
                self._tick()
                now = self.time
                if now < self._listeners_due - 1e-9:
                    continue
                due = [entry for entry in self._listeners if now >= entry[2] - 1e-9]
                for entry in due:
                    entry[2] += entry[1]
                    if entry[2] <= now:
                        entry[2] = now + entry[1]
                self._listeners_due = min((entry[2] for entry in self._listeners), default=math.inf)
            for entry in due:
                try:
                    entry[0](now)
                except Exception:
                    _log.exception("world tick listener %r failed", entry[0])

    def _tick(self) -> None:
        """One firmware tick of every vehicle: a fixed pipeline of whole-fleet numpy stages.

        First tick of a control period: gyro -> onboard controller (PIDs) -> motors. Other ticks:
        the motors are recomputed only when a setpoint, lock or parameter changed them. Last tick
        of a control period: the bodies are integrated over the period (the state a reader sees
        on the ticks in between is the one at the period's start). Battery every BATTERY_EVERY
        ticks. A stage that concerns some vehicles only works on all rows with a mask, never with
        a Python loop over vehicles.
        """
        k = self.ticks
        if len(self._order):
            b = self.bodies
            onboard = self.onboard
            if self.flight.step(k, self.time, b, onboard.s, self.ground_asl, self._imu):
                onboard.dirty = True
            if k % CONTROL_TICKS == 0:
                thrust_fraction = (b.thrust @ _ONES4) * b.inv_mass[:, 0] / b.gravity
                gyro = _sensors.gyro_measured(self.sensors, b.omega, thrust_fraction, self.rng)
                motors = onboard.update(k, self.time, b, gyro, self.battery.empty)
            elif onboard.motors_may_change:
                motors = onboard.update(k, self.time, b, None, self.battery.empty)
            else:
                motors = onboard.s.motors
            if (k + 1) % CONTROL_TICKS == 0:
                drive = self._drive
                if drive is None or drive.commands is not motors:
                    drive = self._drive = self.physics.drive(b, motors, CONTROL_PERIOD_S)
                self.physics.step(b, motors, CONTROL_PERIOD_S, drive)
            if k % BATTERY_EVERY == 0:
                _battery.update(self.battery, FIRMWARE_TICK_S * BATTERY_EVERY, b.thrust)
                if np.count_nonzero(self.battery.empty):
                    onboard.dirty = True
        self.ticks = k + 1

    # --- readings ----------------------------------------------------------------------------
    def _readings(self, i: int, group: str) -> Dict[str, float]:
        """Log variables of one group for vehicle row ``i`` (called under the lock)."""
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
        if group in _flight.GROUPS:
            return self.flight.readings(i, group, b, o.attitude[i], self.ground_asl)
        if group == "motor":
            m = o.motors[i]
            return {"motor.m%d" % (k + 1): float(int(m[k])) for k in range(4)}
        if group == "sys":
            locked = int(o.lock[i])
            return {"sys.canfly": float(locked == LOCK_NONE), "sys.isFlying": float(o.thrust[i] > 0.0),
                    "sys.isTumbled": float(_tilt_cos(b.quaternion[i]) < TUMBLE_TILT_COS)}
        if group == "controller":
            d, r = o.attitude_desired[i], o.rate_desired[i]
            return {"controller.roll": float(d[0]), "controller.pitch": float(d[1]), "controller.yaw": float(d[2]),
                    "controller.rollRate": float(r[0]), "controller.pitchRate": float(r[1]),
                    "controller.yawRate": float(r[2])}
        return {}

    def add_tick_listener(self, fn: Callable[[float], None], period: float, first: Optional[float] = None) -> None:
        """Call fn(world_time) every ``period`` seconds of world time (from the stepping thread).

        The first call is at world time ``first`` (default: one period from now), on the first tick
        at or after it.
        """
        if not period > 0:
            raise ValueError("tick listener period must be > 0 s, got %r" % (period,))
        with self._lock:
            start = self.time + float(period) if first is None else float(first)
            self._listeners.append([fn, float(period), start])
            self._listeners_due = min(self._listeners_due, start)

    def remove_tick_listener(self, fn: Callable[[float], None]) -> None:
        with self._lock:
            self._listeners = [entry for entry in self._listeners if entry[0] is not fn]

    # --- real time ---------------------------------------------------------------------------
    def start(self) -> None:
        """Step in a background thread at ``speed`` × real time (speed 0: as fast as possible)."""
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
        self._anchor = None

    def wall_time_of(self, world_t: float) -> Optional[float]:
        """The host time (``time.time()``) at which the real-time thread's schedule puts world time ``world_t``;
        None when no thread steps in real time. A world running behind steps a tick later than
        this; one that let go of its lag (``overruns``) starts a new schedule."""
        anchor = self._anchor
        if anchor is None or anchor[2] <= 0:
            return None
        return anchor[0] + (world_t - anchor[1]) / anchor[2]

    def set_speed(self, speed: float) -> None:
        """Run at ``speed`` × real time from now on (0: as fast as possible); world time goes on from
        where it is, without a jump (the real-time thread starts a new schedule)."""
        if not (speed >= 0 and math.isfinite(speed)):
            raise ValueError("world speed must be >= 0 (0 = as fast as possible), got %r" % (speed,))
        self.speed = float(speed)
        self._speed_changed.set()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        """Real-time stepping: wake every WAKE_PERIOD_S of wall time (per ``speed``), step what is due."""
        wall0, world0 = _time.monotonic(), self.time
        self._anchor = (_time.time(), world0, self.speed)
        meter_wall, meter_world = wall0, world0
        wake_ticks = max(1, int(round(WAKE_PERIOD_S / FIRMWARE_TICK_S)))
        while not self._stop.is_set():
            now = _time.monotonic()
            if self._speed_changed.is_set():
                self._speed_changed.clear()
                wall0, world0 = now, self.time
                self._anchor = (_time.time(), world0, self.speed)
            if now - meter_wall >= METER_PERIOD_S:
                self._meter((self.time - meter_world) / (now - meter_wall), world0 + (now - wall0) * self.speed)
                meter_wall, meter_world = now, self.time
            if self.speed <= 0:
                self.step(FAST_CHUNK_TICKS)
                continue
            due = int((world0 + (now - wall0) * self.speed - self.time) / FIRMWARE_TICK_S)
            if due < wake_ticks:
                self._stop.wait((wake_ticks - due) * FIRMWARE_TICK_S / self.speed)
                continue
            if due * FIRMWARE_TICK_S > self.max_lag_s:
                self.overruns += 1
                wall0, world0 = now, self.time
                self._anchor = (_time.time(), world0, self.speed)
                due = wake_ticks
            self.step(min(due, MAX_CHUNK_TICKS))

    def _meter(self, factor: float, wanted_time: float) -> None:
        """Record the measured real-time factor; warn (throttled) when the world falls behind its speed."""
        self.realtime_factor = factor
        self.ticks_behind = max(0, int((wanted_time - self.time) / FIRMWARE_TICK_S)) if self.speed > 0 else 0
        if self.speed <= 0 or factor >= self.speed * BEHIND_FACTOR:
            return
        now = _time.monotonic()
        if now - self._last_behind_warning >= BEHIND_WARNING_PERIOD_S:
            self._last_behind_warning = now
            _log.warning("the simulated world runs behind real time: %.2fx instead of %.2fx with %d vehicle(s) "
                         "(%d overrun(s)); rates that follow the firmware's clock are %.0f %% low "
                         "(the machine is busy, or the world has too many vehicles for it)",
                         factor, self.speed, len(self._order), self.overruns, 100.0 * (1.0 - factor / self.speed))
