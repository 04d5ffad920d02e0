"""The simulated firmware's supervisor as port 9 and ``supervisor.info`` show it: stabilizer.stop locks
until reboot, a tumble in flight is a crash that recovery clears, the high-level commander's bits."""
from __future__ import annotations

import math
import struct

import pytest
from test_sim_high_level import ask, hl, takeoff
from test_sim_onboard_flight import Rig

from crazyflie_driver.sim.onboard.stabilizer import BRUSHLESS_IDLE_MOTOR

CAN_ARM, ARMED, AUTO_ARM, CAN_FLY, FLYING, TUMBLED, LOCKED, CRASHED = (1 << k for k in range(8))
HL_ACTIVE, HL_FINISHED, HL_DISABLED = 1 << 8, 1 << 9, 1 << 10
EBUSY = 16


def bits(rig):
    reply = ask(rig, 9, 0, b"\x0c")
    assert reply[1] == 0x8C
    value = struct.unpack_from("<H", reply, 2)[0]
    assert rig.cf.read_value("supervisor.info") == value
    for k in range(11):                             # the one-bit queries agree with the bit field
        assert ask(rig, 9, 0, bytes([k + 1])) == bytes([reply[0], 0x81 + k, (value >> k) & 1])
    return value


def test_boot_state_and_high_level_bits():
    rig = Rig()
    assert bits(rig) == ARMED | AUTO_ARM | CAN_FLY | HL_FINISHED     # no plan yet: "finished"
    hl(rig, takeoff(0.5, 2.0))
    rig.fly(0.5)
    assert bits(rig) & (FLYING | HL_ACTIVE | HL_FINISHED | HL_DISABLED) == FLYING | HL_ACTIVE
    rig.fly(2.0)
    assert bits(rig) & (HL_ACTIVE | HL_FINISHED) == HL_ACTIVE | HL_FINISHED  # holding the end: still active
    rig.position_setpoint(0.0, 0.0, 0.5)            # a low-level setpoint stops the planner: idle, not disabled
    rig.fly(0.1)
    assert bits(rig) & (HL_ACTIVE | HL_DISABLED) == 0
    rig.setpoint = None
    rig.send(7, 1, b"\x00" + struct.pack("<I", 0))
    hl(rig, struct.pack("<BBBBfffff", 12, 0, 0, 0, 0.0, 0.0, 0.3, 0.0, 1.0))
    rig.fly(0.1)
    assert bits(rig) & (HL_ACTIVE | HL_DISABLED) == HL_ACTIVE


def test_stabilizer_stop_locks_until_reboot():
    rig = Rig()
    hl(rig, takeoff(0.5, 1.5))
    rig.fly(2.0)
    rig.param("stabilizer.stop", 1)
    rig.fly(0.05)
    assert rig.vehicle.motors().max() == 0
    rig.param("stabilizer.stop", 0)                 # clearing it does not unlock
    rig.fly(1.0)
    b = bits(rig)
    assert b & (LOCKED | CAN_FLY | ARMED | CAN_ARM) == LOCKED and rig.truth()[2] < 0.02
    assert hl(rig, takeoff(0.5, 1.5))[-1] == EBUSY
    assert ask(rig, 9, 1, b"\x01\x01") == b"\x9d\x81\x00\x00"          # arming refused while locked
    rig.cf.reboot()
    assert rig.cf.params.value("stabilizer.stop") == 0 and not bits(rig) & LOCKED
    rig.param("stabilizer.estimator", 2)
    assert hl(rig, takeoff(0.5, 1.5))[-1] == 0
    rig.fly(2.0)
    assert rig.truth()[2] == pytest.approx(0.5, abs=0.05)


def turned_upside_down_in_flight() -> Rig:
    """A Crazyflie hovering at 1 m, turned upside down (half a turn about x) and given 0.3 s to notice."""
    rig = Rig()
    hl(rig, takeoff(1.0, 1.5))
    rig.fly(2.0)
    rig.vehicle.place((0.0, 0.0, 1.0), yaw=0.0)
    rig.world.bodies.quaternion[0] = (math.sin(math.pi / 2), 0.0, 0.0, math.cos(math.pi / 2))
    rig.fly(0.3)
    return rig


def test_tumble_in_flight_is_a_crash_that_recovery_clears():
    rig = turned_upside_down_in_flight()
    w = rig.world
    i = 0
    b = bits(rig)
    assert b & (CRASHED | LOCKED | CAN_FLY | TUMBLED) == CRASHED | TUMBLED and rig.vehicle.motors().max() == 0
    rig.fly(1.5)                                     # falls, lies on its back
    w.bodies.quaternion[i] = (1.0, 0.0, 0.0, 0.0)
    assert ask(rig, 9, 1, b"\x02") == b"\x9d\x82\x00\x00"               # refused while tumbled
    rig.vehicle.place((0.0, 0.0, 0.0))
    assert ask(rig, 9, 1, b"\x02") == b"\x9d\x82\x01\x01"               # upright again: recovered
    assert bits(rig) & (CRASHED | CAN_FLY | ARMED) == CAN_FLY | ARMED
    assert ask(rig, 13, 0, b"\x02") == b"\xdc\x02\x01\x01"              # platform form: not crashed
    rig.position_setpoint(0.0, 0.0, 0.5)
    rig.fly(3.0)
    assert rig.truth()[2] == pytest.approx(0.5, abs=0.05)


def test_emergency_stop_during_a_crash_locks():
    rig = turned_upside_down_in_flight()
    assert bits(rig) & CRASHED
    rig.send(9, 1, b"\x03")
    assert bits(rig) & (CRASHED | LOCKED) == LOCKED
    rig.vehicle.place((0.0, 0.0, 0.0))
    assert ask(rig, 9, 1, b"\x02")[2:] == b"\x01\x01" and bits(rig) & LOCKED     # no crash, still locked


def test_a_brushless_crazyflie_spins_nothing_until_armed_then_idles_and_flies():
    rig = Rig(platform="brushless")
    assert bits(rig) & (CAN_ARM | ARMED | AUTO_ARM | CAN_FLY) == CAN_ARM
    hl(rig, takeoff(0.5, 1.0))
    rig.fly(1.5)
    assert max(rig.vehicle.motors()) == 0.0 and rig.vehicle.pose()[0][2] < 0.01     # refused: not armed
    rig.cf.reboot()                                   # forget that plan; a reboot leaves it disarmed
    assert not bits(rig) & ARMED
    assert ask(rig, 9, 1, b"\x01\x01")[1:] == b"\x81\x01\x01"       # arm: success, armed
    rig.fly(0.2)
    assert list(rig.vehicle.motors()) == [BRUSHLESS_IDLE_MOTOR] * 4      # armed on the floor: idling
    assert rig.vehicle.pose()[0][2] < 0.01
    hl(rig, takeoff(0.5, 1.5))
    rig.fly(2.5)
    assert rig.vehicle.pose()[0][2] == pytest.approx(0.5, abs=0.05)
    assert ask(rig, 9, 1, b"\x01\x00")[1:] == b"\x81\x01\x00"       # disarmed in the air: motors off
    rig.fly(0.1)
    assert max(rig.vehicle.motors()) == 0.0
