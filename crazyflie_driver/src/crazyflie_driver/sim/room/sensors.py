"""Sensor readings of the simulated Crazyflie 2.0 from the true motion (docs/simulation.md, "Sensors").

MPU-9250 gyro (deg/s) and accelerometer (g, specific force: +1 on z at rest), AK8963 magnetometer
(gauss), LPS25H barometer (hPa, °C, metres above sea level), with datasheet-level white noise and a
small residual bias per vehicle (the firmware calibrates the large offsets away at start; the raw
gyro registers keep them). In flight, prop vibration adds noise in proportion to the thrust (EST).
Per-vehicle constants are drawn from the world's seeded generator when the vehicle is added.
"""
from __future__ import annotations

import math
from typing import Dict

import numpy as np

from crazyflie_driver.sim.onboard.imu_filter import GYRO_LPF_HZ
from crazyflie_driver.sim.vehicle_rows import Rows

GRAVITY = 9.81
GYRO_NOISE_DPS = 0.1                  # rms at the 98 Hz DLPF
GYRO_RESIDUAL_BIAS_DPS = 0.05         # after the firmware's at-rest bias estimate (EST)
GYRO_RAW_OFFSET_DPS = 2.0             # zero-rate offset of the raw registers (datasheet ±5)
GYRO_LSB_PER_DPS = 16.4               # ±2000 deg/s range
ACC_NOISE_G = 0.008                   # rms at 94 Hz
ACC_RANGE_G = 16.0                    # full scale the current firmware configures (±16 g)
GYRO_BANDWIDTH_HZ = 98.0              # DLPF bandwidth the gyro noise figure is given at
ACC_RESIDUAL_BIAS_G = 0.005           # after calibration (EST)
ACC_VIBRATION_G = 0.08                # extra rms at hover thrust of the raw samples, before the firmware's
                                      # 30 Hz low-pass (EST, 0.5-1.5 m/s²; white at the 1 kHz read rate)
GYRO_VIBRATION_DPS = 0.3            # extra rms at hover thrust, after the 80 Hz LPF (EST)
MAG_FIELD_WORLD = np.array([0.21, 0.0, -0.43])   # gauss: north along +x, 64° inclination (EST)
MAG_NOISE_GAUSS = 0.004
MAG_LSB_PER_GAUSS = 1.0 / 0.0015      # 0.15 µT per LSB
SEA_LEVEL_HPA = 1013.25
BARO_NOISE_HPA = 0.01                 # 1 Pa rms
BARO_OFFSET_HPA = 0.1                 # per-vehicle offset (EST)
TEMPERATURE_C = 28.0                  # board self-heating (EST)


class SensorStates(Rows):
    FIELDS = {
        "gyro_bias": ((3,), float),      # deg/s, residual after calibration
        "gyro_raw_offset": ((3,), float),
        "acc_bias": ((3,), float),       # g
        "mag_bias": ((3,), float),       # gauss
        "baro_offset": ((), float),      # hPa
        "temperature": ((), float),      # °C
    }

    # The columns (one row per vehicle; shapes and dtypes in FIELDS), declared for the type checker.
    gyro_bias: np.ndarray
    gyro_raw_offset: np.ndarray
    acc_bias: np.ndarray
    mag_bias: np.ndarray
    baro_offset: np.ndarray
    temperature: np.ndarray

    def add(self, rng: np.random.Generator) -> int:
        return self.append_row(
            gyro_bias=rng.normal(0.0, GYRO_RESIDUAL_BIAS_DPS, 3),
            gyro_raw_offset=rng.uniform(-GYRO_RAW_OFFSET_DPS, GYRO_RAW_OFFSET_DPS, 3),
            acc_bias=rng.normal(0.0, ACC_RESIDUAL_BIAS_G, 3),
            mag_bias=rng.normal(0.0, 0.02, 3),
            baro_offset=rng.normal(0.0, BARO_OFFSET_HPA),
            temperature=TEMPERATURE_C + rng.normal(0.0, 1.0))


def vibration(thrust_fraction: np.ndarray) -> np.ndarray:
    """0 with the motors off, ≈1 at hover."""
    return np.minimum(np.maximum(thrust_fraction, 0.0), 2.0)


def gyro_measured(s: SensorStates, omega: np.ndarray, thrust_fraction: np.ndarray,
                  rng: np.random.Generator) -> np.ndarray:
    """Calibrated gyro (N,3) in deg/s for the controller and ``gyro.*`` (standard signs)."""
    sigma = GYRO_NOISE_DPS + GYRO_VIBRATION_DPS * vibration(thrust_fraction)
    return np.degrees(omega) + s.gyro_bias + rng.standard_normal(omega.shape) * sigma[:, None]


def acc_raw(s: SensorStates, specific_force: np.ndarray, thrust_fraction: np.ndarray, samples: int,
            rng: np.random.Generator) -> np.ndarray:
    """``samples`` raw accelerometer readings (samples, N, 3) in m/s² of every vehicle at 1 kHz, as
    the sensors task reads them before its low-pass filter: the specific force (N,3), the residual
    bias, white noise with the vibration's, clipped at the full scale. The vibration figure is of
    the raw sensor: the rotors turn at about 300 Hz at hover, where the firmware's 30 Hz
    second-order filter passes 0.5 %, so 0.08 g after it would need some 17 g of raw vibration,
    beyond the sensor's ±16 g range."""
    sigma = (ACC_NOISE_G + ACC_VIBRATION_G * vibration(thrust_fraction)) * GRAVITY
    noise = rng.standard_normal((samples,) + specific_force.shape) * sigma[:, None]
    full_scale = ACC_RANGE_G * GRAVITY
    return np.clip(noise + (specific_force + s.acc_bias * GRAVITY), -full_scale, full_scale)


def gyro_means(s: SensorStates, rows: np.ndarray, omega: np.ndarray, thrust_fraction: np.ndarray,
               window_s: float, rng: np.random.Generator) -> np.ndarray:
    """The mean gyro readings (N,3, rad/s) of ``rows`` over ``window_s`` that the Kalman filter
    predicts with, given their true mean body rates: the white noise passes the firmware's 80 Hz
    low-pass (rms scaled by the root of the bandwidth ratio; the vibration figure is already after
    it) and then averages down as over 2·B·window independent samples; the bias stays."""
    vib = vibration(thrust_fraction)[:, None]
    gyro_lpf = GYRO_NOISE_DPS * math.sqrt(GYRO_LPF_HZ / GYRO_BANDWIDTH_HZ) + GYRO_VIBRATION_DPS * vib
    gyro_sigma = np.radians(gyro_lpf) / math.sqrt(max(2.0 * GYRO_LPF_HZ * window_s, 1.0))
    return omega + np.radians(s.gyro_bias[rows]) + rng.standard_normal(omega.shape) * gyro_sigma


def pressure_hpa(altitude_m: float) -> float:
    """International standard atmosphere: pressure at an altitude above sea level."""
    return SEA_LEVEL_HPA * (1.0 - 2.25577e-5 * altitude_m) ** 5.25588


def altitude_m(pressure: float) -> float:
    """The firmware's altitude from pressure (inverse of ``pressure_hpa``)."""
    return 44330.8 * (1.0 - (max(pressure, 1e-3) / SEA_LEVEL_HPA) ** 0.190263)


def imu_readings(s: SensorStates, i: int, specific_force: np.ndarray, omega: np.ndarray,
                 rotation: np.ndarray, thrust_fraction: float, rng: np.random.Generator) -> Dict[str, float]:
    """acc.*, gyro.*, mag.* (and raw register variants) of vehicle ``i``; ``rotation`` body -> world."""
    vib = float(vibration(np.array(thrust_fraction)))
    acc = specific_force / GRAVITY + s.acc_bias[i] + rng.standard_normal(3) * (ACC_NOISE_G + ACC_VIBRATION_G * vib)
    gyro_true = np.degrees(omega)
    gyro_noise = rng.standard_normal(3) * (GYRO_NOISE_DPS + GYRO_VIBRATION_DPS * vib)
    gyro = gyro_true + s.gyro_bias[i] + gyro_noise
    raw = np.clip(np.round((gyro_true + s.gyro_raw_offset[i] + gyro_noise) * GYRO_LSB_PER_DPS), -32768, 32767)
    mag = rotation.T @ MAG_FIELD_WORLD + s.mag_bias[i] + rng.standard_normal(3) * MAG_NOISE_GAUSS
    mag_raw = np.clip(np.round(mag * MAG_LSB_PER_GAUSS), -32768, 32767)
    out: Dict[str, float] = {}
    for k, axis in enumerate("xyz"):
        out["acc." + axis] = float(acc[k])
        out["gyro." + axis] = float(gyro[k])
        out["gyro.%sRaw" % axis] = float(raw[k])
        out["mag." + axis] = float(mag[k])
        out["mag_raw." + axis] = float(mag_raw[k])
    return out


def baro_readings(s: SensorStates, i: int, z: float, ground_asl: float, rng: np.random.Generator) -> Dict[str, float]:
    p = pressure_hpa(ground_asl + z) + s.baro_offset[i] + rng.normal(0.0, BARO_NOISE_HPA)
    return {"baro.pressure": float(p), "baro.asl": float(altitude_m(p)),
            "baro.temp": float(s.temperature[i] + rng.normal(0.0, 0.05))}


def heading_deg(mag_x: float, mag_y: float) -> float:
    """Compass heading of a level vehicle (for tests and tools)."""
    return math.degrees(math.atan2(-mag_y, mag_x))
