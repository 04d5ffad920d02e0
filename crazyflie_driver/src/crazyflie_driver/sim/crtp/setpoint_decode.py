"""Port-7 generic setpoints decoded as the current firmware decodes them (pure functions).

Every decoder starts from an all-zero setpoint (all modes disabled, thrust 0), as the firmware
memsets its setpoint before decoding, and fills in the modes and values of its type. Most
decoders check the exact data length with an assert: on a real Crazyflie a wrong length halts the
STM32, so here they raise ``FirmwareAssert`` and the caller halts the simulated Crazyflie. Unknown
types give the all-zero setpoint (motors off). The facts are written down in docs/protocol.md
("Generic setpoints").
"""
from __future__ import annotations

import math
import struct
from typing import Callable, Dict, Optional

from crazyflie_driver.crtp.quaternion import decompress_quaternion as decompress_quat
from crazyflie_driver.sim.onboard.setpoint import MODE_ABS, MODE_VELOCITY, OnboardSetpoint

# type numbers of port 7 channel 0
STOP, LEGACY_VELOCITY_WORLD, LEGACY_Z_DISTANCE, CPPM_EMU, ALT_HOLD, LEGACY_HOVER = 0, 1, 2, 3, 4, 5
FULL_STATE, POSITION, VELOCITY_WORLD, Z_DISTANCE, HOVER, MANUAL = 6, 7, 8, 9, 10, 11

# exact data lengths (after the type byte) the decoders assert
FOUR_FLOATS = struct.Struct("<ffff")
FULL_STATE_FMT = struct.Struct("<hhhhhhhhhIhhh")
MANUAL_FMT = struct.Struct("<fffHB")
CPPM_MIN = 9                      # header byte + 4 channels of u16
CPPM_MAX_AUX = 10
CPPM_ROLL_MAX_DEG = 50.0          # self-levelling stick range (cppm.angRoll default)
CPPM_PITCH_MAX_DEG = 50.0
CPPM_ROLL_RATE_DPS = 720.0        # rate mode stick range
CPPM_PITCH_RATE_DPS = 720.0
CPPM_YAW_RATE_DPS = 400.0
UINT16_MAX = 65535.0
NOTIFY_STOP = 0                   # channel 1 meta command
NOTIFY_STOP_LEN = 4               # u32 remain-valid milliseconds (ignored by current firmware)


class FirmwareAssert(Exception):
    """A packet that trips an assert in the real firmware (which then halts)."""


def _exact(data: bytes, size: int, kind: int) -> None:
    if len(data) != size:
        raise FirmwareAssert("generic setpoint type %d: %d data bytes, the decoder asserts exactly %d"
                             % (kind, len(data), size))


def _velocity_world(kind: int, data: bytes, negate_yaw: bool) -> OnboardSetpoint:
    _exact(data, FOUR_FLOATS.size, kind)
    vx, vy, vz, yawrate = FOUR_FLOATS.unpack(data)
    return OnboardSetpoint(kind, MODE_VELOCITY, MODE_VELOCITY, MODE_VELOCITY, mode_yaw=MODE_VELOCITY,
                           velocity=(vx, vy, vz), attitude_rate=(0.0, 0.0, -yawrate if negate_yaw else yawrate))


def _z_distance(kind: int, data: bytes, negate_yaw: bool) -> OnboardSetpoint:
    _exact(data, FOUR_FLOATS.size, kind)
    roll, pitch, yawrate, z = FOUR_FLOATS.unpack(data)
    return OnboardSetpoint(kind, mode_z=MODE_ABS, mode_roll=MODE_ABS, mode_pitch=MODE_ABS, mode_yaw=MODE_VELOCITY,
                           position=(0.0, 0.0, z), attitude=(roll, pitch, 0.0),
                           attitude_rate=(0.0, 0.0, -yawrate if negate_yaw else yawrate))


def _hover(kind: int, data: bytes, negate_yaw: bool) -> OnboardSetpoint:
    _exact(data, FOUR_FLOATS.size, kind)
    vx, vy, yawrate, z = FOUR_FLOATS.unpack(data)
    return OnboardSetpoint(kind, MODE_VELOCITY, MODE_VELOCITY, MODE_ABS, mode_yaw=MODE_VELOCITY,
                           position=(0.0, 0.0, z), velocity=(vx, vy, 0.0),
                           attitude_rate=(0.0, 0.0, -yawrate if negate_yaw else yawrate), velocity_body=True)


def _alt_hold(kind: int, data: bytes) -> OnboardSetpoint:
    _exact(data, FOUR_FLOATS.size, kind)
    roll, pitch, yawrate, vz = FOUR_FLOATS.unpack(data)
    return OnboardSetpoint(kind, mode_z=MODE_VELOCITY, mode_roll=MODE_ABS, mode_pitch=MODE_ABS, mode_yaw=MODE_VELOCITY,
                           velocity=(0.0, 0.0, vz), attitude=(roll, pitch, 0.0), attitude_rate=(0.0, 0.0, yawrate))


def _cppm(kind: int, data: bytes) -> OnboardSetpoint:
    if len(data) < CPPM_MIN:
        raise FirmwareAssert("generic setpoint type 3 (CPPM): %d data bytes, the decoder asserts at least %d"
                             % (len(data), CPPM_MIN))
    n_aux = data[0] & 0x0F
    _exact(data, CPPM_MIN + 2 * n_aux, kind)
    roll_us, pitch_us, yaw_us, thrust_us = struct.unpack_from("<HHHH", data, 1)
    aux = struct.unpack_from("<%dH" % n_aux, data, CPPM_MIN) if n_aux else ()
    level = not (n_aux >= 1 and aux[0] < 1500)

    def unit(us: int, mid: float, span: float) -> float:
        return (us - mid) / span

    sp = OnboardSetpoint(kind, mode_yaw=MODE_VELOCITY)
    if level:
        sp.mode_roll = sp.mode_pitch = MODE_ABS
        sp.attitude = (-unit(roll_us, 1500, 500) * CPPM_ROLL_MAX_DEG, -unit(pitch_us, 1500, 500) * CPPM_PITCH_MAX_DEG,
                       0.0)
        rates = (0.0, 0.0)
    else:
        sp.mode_roll = sp.mode_pitch = MODE_VELOCITY
        rates = (-unit(roll_us, 1500, 500) * CPPM_ROLL_RATE_DPS, -unit(pitch_us, 1500, 500) * CPPM_PITCH_RATE_DPS)
    sp.attitude_rate = (rates[0], rates[1], -unit(yaw_us, 1500, 500) * CPPM_YAW_RATE_DPS)
    sp.thrust = max(0.0, unit(thrust_us, 1000, 1000) * UINT16_MAX)
    return sp


def _full_state(kind: int, data: bytes) -> OnboardSetpoint:
    _exact(data, FULL_STATE_FMT.size, kind)
    x, y, z, vx, vy, vz, ax, ay, az, quat, rr, rp, ry = FULL_STATE_FMT.unpack(data)
    mrad_to_deg = 180.0 / (math.pi * 1000.0)
    return OnboardSetpoint(kind, MODE_ABS, MODE_ABS, MODE_ABS, mode_quat=MODE_ABS,
                           position=(x / 1000.0, y / 1000.0, z / 1000.0),
                           velocity=(vx / 1000.0, vy / 1000.0, vz / 1000.0),
                           acceleration=(ax / 1000.0, ay / 1000.0, az / 1000.0),
                           attitude_rate=(rr * mrad_to_deg, rp * mrad_to_deg, ry * mrad_to_deg),
                           quaternion=decompress_quat(quat))


def _position(kind: int, data: bytes) -> OnboardSetpoint:
    # No length assert in the firmware: it reads 16 bytes whatever came; the bytes past a short
    # packet are whatever the buffer held, here zeros.
    x, y, z, yaw = FOUR_FLOATS.unpack(bytes(data[:FOUR_FLOATS.size]).ljust(FOUR_FLOATS.size, b"\x00"))
    return OnboardSetpoint(kind, MODE_ABS, MODE_ABS, MODE_ABS, mode_yaw=MODE_ABS, position=(x, y, z),
                           attitude=(0.0, 0.0, yaw))


def _manual(kind: int, data: bytes) -> OnboardSetpoint:
    _exact(data, MANUAL_FMT.size, kind)
    roll, pitch, yawrate, thrust, rate = MANUAL_FMT.unpack(data)
    sp = OnboardSetpoint(kind, mode_yaw=MODE_VELOCITY, thrust=float(thrust))
    if rate == 1:
        sp.mode_roll = sp.mode_pitch = MODE_VELOCITY
        sp.attitude_rate = (roll, pitch, yawrate)
    else:
        sp.mode_roll = sp.mode_pitch = MODE_ABS
        sp.attitude = (roll, pitch, 0.0)
        sp.attitude_rate = (0.0, 0.0, yawrate)
    return sp


_DECODERS: Dict[int, Callable[[int, bytes], OnboardSetpoint]] = {
    STOP: lambda k, d: OnboardSetpoint(k),
    LEGACY_VELOCITY_WORLD: lambda k, d: _velocity_world(k, d, True),
    LEGACY_Z_DISTANCE: lambda k, d: _z_distance(k, d, True),
    CPPM_EMU: _cppm,
    ALT_HOLD: _alt_hold,
    LEGACY_HOVER: lambda k, d: _hover(k, d, True),
    FULL_STATE: _full_state,
    POSITION: _position,
    VELOCITY_WORLD: lambda k, d: _velocity_world(k, d, False),
    Z_DISTANCE: lambda k, d: _z_distance(k, d, False),
    HOVER: lambda k, d: _hover(k, d, False),
    MANUAL: _manual,
}

# data length each type's decoder requires (None: no check, or a length that depends on the data)
EXPECTED_LENGTH: Dict[int, Optional[int]] = {
    STOP: None, LEGACY_VELOCITY_WORLD: 16, LEGACY_Z_DISTANCE: 16, CPPM_EMU: None, ALT_HOLD: 16, LEGACY_HOVER: 16,
    FULL_STATE: FULL_STATE_FMT.size, POSITION: None, VELOCITY_WORLD: 16, Z_DISTANCE: 16, HOVER: 16,
    MANUAL: MANUAL_FMT.size,
}


def decode_setpoint(payload: bytes) -> OnboardSetpoint:
    """Port 7 channel 0 payload (type byte + data) -> ``OnboardSetpoint``; raises ``FirmwareAssert``."""
    if not payload:
        raise FirmwareAssert("generic setpoint: empty packet (the decoder asserts a type byte)")
    kind, data = payload[0], bytes(payload[1:])
    decoder = _DECODERS.get(kind)
    if decoder is None:
        return OnboardSetpoint(kind)            # unknown type: the zeroed setpoint, motors off
    return decoder(kind, data)


def decode_meta(payload: bytes) -> Optional[int]:
    """Port 7 channel 1: the notify-setpoints-stop value (ms), None for other meta commands."""
    if not payload:
        raise FirmwareAssert("generic setpoint meta command: empty packet")
    if payload[0] != NOTIFY_STOP:
        return None
    if len(payload) - 1 != NOTIFY_STOP_LEN:
        raise FirmwareAssert("notify-setpoints-stop: %d data bytes, the decoder asserts exactly %d"
                             % (len(payload) - 1, NOTIFY_STOP_LEN))
    return struct.unpack_from("<I", payload, 1)[0]
