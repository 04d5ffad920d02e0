"""1S LiPo battery of each vehicle: charge drawn by the motors, voltage sag, firmware power states.

EST model (docs/simulation.md, "Battery", gives the anchors): 240 mAh cell; current = idle + k·Σ F_i^1.5 (rotor
power grows with thrust^1.5), k set so a 27 g hover draws ≈ 2.1 A (≈ 7 min of hover);
open-circuit voltage from a typical LiPo discharge curve; 0.15 Ω internal resistance (≈ 0.3 V sag at
hover). Firmware power states as ``pm.state``: 0 battery, 3 low power (below 3.2 V for 5 s),
4 shut down (below 3.0 V for 5 s: the motors stop).
"""
from __future__ import annotations

import numpy as np

from crazyflie_driver.sim.vehicle_rows import Rows

CAPACITY_MAH = 240.0
IDLE_CURRENT_A = 0.08
CURRENT_PER_THRUST = 29.7            # A per Σ F^1.5 [N^1.5]
INTERNAL_RESISTANCE = 0.15           # ohm
LOW_VOLTAGE = 3.2
CRITICAL_VOLTAGE = 3.0
PERSIST_S = 5.0

# state of charge -> open-circuit voltage (typical 1S LiPo curve, EST)
SOC_POINTS = np.array([0.0, 0.03, 0.05, 0.1, 0.2, 0.4, 0.6, 0.8, 0.95, 1.0])
OCV_POINTS = np.array([3.0, 3.3, 3.45, 3.6, 3.7, 3.78, 3.87, 4.0, 4.12, 4.2])

PM_BATTERY, PM_CHARGING, PM_CHARGED, PM_LOW_POWER, PM_SHUTDOWN = 0, 1, 2, 3, 4


class BatteryStates(Rows):
    FIELDS = {
        "charge": ((), float),        # state of charge 0..1
        "capacity_mah": ((), float),
        "current": ((), float),       # A
        "vbat": ((), float),          # terminal voltage under load, V
        "low_time": ((), float),
        "critical_time": ((), float),
        "state": ((), np.int8),
    }

    # The columns (one row per vehicle; shapes and dtypes in FIELDS), declared for the type checker.
    charge: np.ndarray
    capacity_mah: np.ndarray
    current: np.ndarray
    vbat: np.ndarray
    low_time: np.ndarray
    critical_time: np.ndarray
    state: np.ndarray

    def add(self, charge: float = 1.0, capacity_mah: float = CAPACITY_MAH) -> int:
        if not 0.0 <= charge <= 1.0:
            raise ValueError("battery charge must be within 0..1, got %r" % (charge,))
        i = self.append_row(charge=charge, capacity_mah=capacity_mah, current=IDLE_CURRENT_A)
        self.vbat[i] = open_circuit_voltage(np.array([charge]))[0] - IDLE_CURRENT_A * INTERNAL_RESISTANCE
        return i

    @property
    def empty(self) -> np.ndarray:
        return self.state == PM_SHUTDOWN


def open_circuit_voltage(charge: np.ndarray) -> np.ndarray:
    return np.interp(charge, SOC_POINTS, OCV_POINTS)


def supply_current(motor_thrust: np.ndarray) -> np.ndarray:
    """Current (N,) drawn for the motors' thrust (N,4) [N]."""
    return IDLE_CURRENT_A + CURRENT_PER_THRUST * (np.maximum(motor_thrust, 0.0) ** 1.5).sum(axis=1)


def update(b: BatteryStates, dt: float, motor_thrust: np.ndarray) -> None:
    """Advance every battery by ``dt`` seconds under the given motor thrust."""
    if len(b) == 0:
        return
    current = supply_current(motor_thrust)
    b.charge = np.maximum(b.charge - current * dt / (b.capacity_mah * 3.6), 0.0)
    b.current = current
    b.vbat = np.maximum(open_circuit_voltage(b.charge) - current * INTERNAL_RESISTANCE, 0.0)
    low = b.vbat < LOW_VOLTAGE
    if not np.count_nonzero(low) and not np.count_nonzero(b.state):     # every battery fine, none shut down: the same
        b.low_time.fill(0.0)
        b.critical_time.fill(0.0)
        return
    b.low_time = np.where(low, b.low_time + dt, 0.0)
    b.critical_time = np.where(b.vbat < CRITICAL_VOLTAGE, b.critical_time + dt, 0.0)
    state = np.where(b.low_time >= PERSIST_S, PM_LOW_POWER, PM_BATTERY)
    state = np.where((b.critical_time >= PERSIST_S) | (b.state == PM_SHUTDOWN), PM_SHUTDOWN, state)
    b.state = state.astype(np.int8)


def battery_level(charge: float) -> int:
    """``pm.batteryLevel`` in percent."""
    return int(round(min(max(charge, 0.0), 1.0) * 100.0))


def charge_for_voltage(voltage: float, current: float) -> float:
    """State of charge at which the cell reads ``voltage`` (V) under ``current`` (A): the inverse of the
    discharge curve; ValueError outside what the curve can read."""
    ocv = float(voltage) + float(current) * INTERNAL_RESISTANCE
    sag = float(current) * INTERNAL_RESISTANCE
    low, high = float(OCV_POINTS[0]) - sag, float(OCV_POINTS[-1]) - sag
    if not OCV_POINTS[0] <= ocv <= OCV_POINTS[-1]:
        raise ValueError("a battery reads %.2f..%.2f V at the present %.2f A, not %r V"
                         % (max(low, 0.0), high, current, voltage))
    return float(np.interp(ocv, OCV_POINTS, SOC_POINTS))


def set_charge(b: BatteryStates, i: int, charge: float) -> None:
    """Row ``i``'s cell at state of charge ``charge`` (0..1) now, as if drained or charged to it.

    The firmware's low/critical timers start again from the new reading; a cell charged back above
    the critical voltage leaves the shut-down state (a fresh battery in a simulator).
    """
    if not 0.0 <= charge <= 1.0:
        raise ValueError("battery charge must be within 0..1, got %r" % (charge,))
    b.charge[i] = charge
    b.vbat[i] = max(float(open_circuit_voltage(np.array([charge]))[0]) - float(b.current[i]) * INTERNAL_RESISTANCE,
                    0.0)
    b.low_time[i] = 0.0
    b.critical_time[i] = 0.0
    if b.vbat[i] >= CRITICAL_VOLTAGE and b.state[i] == PM_SHUTDOWN:
        b.state[i] = PM_BATTERY
