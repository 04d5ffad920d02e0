"""Onboard flight in the simulated Crazyflie: packets in through the firmware's ports, positions checked
on the world's true state (estimator 1 and 2, PID position controller, setpoint types, mocap loss,
asserts that halt, fuzzing of ports 6 and 7)."""
from __future__ import annotations

import logging
import random
import struct

import numpy as np
import pytest

from crazyflie_driver.crtp.quaternion import compress_quaternion as compress_quat
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from crazyflie_driver.sim.room.world import World

ADDR = b"\xe7\xe7\xe7\xe7\x05"
MOCAP_PERIOD = 0.01
MOCAP_NOISE = 0.0005
SETTLED_S = 11.0       # s after a step from the floor: the PID chain's z overshoot (0.6 m step, 0.765 m
                       # peak) settles through the z position integrator with a time constant of ~3.5 s


class Rig:
    """One world vehicle behind its simulated firmware; mocap streamed as external position packets."""

    def __init__(self, position=(0.0, 0.0, 0.0), seed=3, estimator=2, mocap="position", platform="cf2",
                 gyro_bias=None):
        """``gyro_bias``: the vehicle's residual gyro bias [deg/s; roll, pitch, yaw axes] instead of the
        seeded draw."""
        self.world = World(speed=0, seed=seed)
        self.vehicle = self.world.add_vehicle("cf5", position=position, platform=platform)
        if gyro_bias is not None:
            self.world.sensors.gyro_bias[0] = gyro_bias          # row 0: the world's one vehicle
        self.cf = SimulatedCrazyflie(ADDR, self.vehicle, auto_arm=self.vehicle.auto_arm)
        self.rng = np.random.default_rng(seed)
        self.mocap = mocap
        self.setpoint = None
        self.world.add_tick_listener(self._mocap, MOCAP_PERIOD)
        self.world.add_tick_listener(self._stream, 0.02)
        if estimator is not None:
            self.param("stabilizer.estimator", estimator)

    def send(self, port, channel, payload):
        self.cf.handle_crtp(bytes([(port << 4) | 0x0C | channel]) + payload)

    def param(self, name, value):
        """Set by name (port 2 channel 3 SET_BY_NAME), as hosts do for these parameters."""
        ident = self.cf.params.ident(name)
        entry = self.cf.params.entries[ident]
        from crazyflie_driver.sim.crtp import tables as T
        self.send(2, 2, struct.pack("<H", ident) + T.pack(value, T.CTYPES[entry.ctype]))
        assert self.cf.params.value(name) == pytest.approx(value)

    def _mocap(self, now):
        if self.mocap is None:
            return
        p, q = self.vehicle.pose()
        m = p + self.rng.normal(0.0, MOCAP_NOISE, 3)
        if self.mocap == "position":
            self.send(6, 0, struct.pack("<fff", *m))
        elif self.mocap == "pose":
            self.send(6, 1, bytes([8]) + struct.pack("<7f", *m, *q))
        elif self.mocap == "packed":        # two other Crazyflies share the packet
            mm = [int(round(c * 1000)) for c in m]
            self.send(6, 2, struct.pack("<Bhhh", 4, 9, 9, 9) + struct.pack("<Bhhh", 5, *mm)
                      + struct.pack("<Bhhh", 6, -9, -9, -9))
        elif self.mocap == "packed_pose":
            mm = [int(round(c * 1000)) for c in m]
            self.send(6, 1, bytes([9]) + struct.pack("<BhhhI", 5, *mm, compress_quat(q))
                      + struct.pack("<BhhhI", 7, 1, 2, 3, compress_quat(q)))

    def _stream(self, now):
        if self.setpoint is not None:
            self.send(7, 0, self.setpoint)

    def fly(self, seconds):
        self.world.step(int(round(seconds * 1000)))

    def truth(self):
        return self.vehicle.pose()[0]

    def position_setpoint(self, x, y, z, yaw=0.0):
        self.setpoint = bytes([7]) + struct.pack("<ffff", x, y, z, yaw)


def hover_error(rig, goal, seconds=2.0):
    errs = []
    for _ in range(int(seconds * 100)):
        rig.fly(0.01)
        errs.append(np.linalg.norm(rig.truth() - np.asarray(goal)))
    return float(np.mean(errs)), float(np.max(errs))


@pytest.mark.parametrize("mocap", ["position", "pose", "packed", "packed_pose"])
def test_position_setpoints_with_kalman_and_mocap(mocap):
    """Every mocap packet format feeds the filter and the hover holds; no gyro bias, whose offset is
    the next test's."""
    rig = Rig(position=(0.3, -0.2, 0.0), mocap=mocap, gyro_bias=(0.0, 0.0, 0.0))
    rig.position_setpoint(0.3, -0.2, 0.6)
    rig.fly(SETTLED_S)
    mean, worst = hover_error(rig, (0.3, -0.2, 0.6), 1.0)
    assert mean < 0.02 and worst < 0.04, (mocap, mean, worst)
    assert rig.cf.state.external_measurements > 500
    if mocap != "position":
        return
    rig.position_setpoint(1.0, 0.5, 0.8, 90.0)
    rig.fly(6.0)
    mean, _ = hover_error(rig, (1.0, 0.5, 0.8))
    assert mean < 0.03, (mocap, mean)
    assert rig.vehicle.read("stateEstimate.yaw") == pytest.approx(90.0, abs=3.0)
    # the estimate is what the firmware believes: close to, but not equal to, the truth
    est = np.array([rig.vehicle.read("stateEstimate." + a) for a in "xyz"])
    assert 0.0 < np.linalg.norm(est - rig.truth()) < 0.01
    assert rig.vehicle.read("locSrv.x") == pytest.approx(rig.truth()[0], abs=0.02)


def hover_offset(rig, goal, seconds=2.0):
    """Mean of truth - goal [m; world frame] over ``seconds``."""
    rows = []
    for _ in range(int(seconds * 100)):
        rig.fly(0.01)
        rows.append(rig.truth() - np.asarray(goal))
    return np.mean(rows, axis=0)


def test_residual_gyro_bias_offsets_the_hover():
    """The firmware's Kalman filter has no gyro-bias state: a residual roll bias left by the at-rest
    calibration tilts the attitude estimate until the position innovations balance it, and the
    Crazyflie hovers off the goal along y, on the bias's side, about a centimetre (saturating:
    2.5 mm at 0.005 deg/s, 11 mm at 0.05, 13 mm at 0.2). Position-only mocap cannot remove it."""
    goal = (0.0, 0.0, 0.6)
    offsets = {}
    for bias in (0.0, 0.05, -0.05):
        rig = Rig(mocap="position", gyro_bias=(bias, 0.0, 0.0))
        rig.position_setpoint(*goal)
        rig.fly(SETTLED_S)
        offsets[bias] = hover_offset(rig, goal)
    assert np.linalg.norm(offsets[0.0][:2]) < 0.007, offsets             # the accelerometer's residual bias
    for bias in (0.05, -0.05):
        moved = offsets[bias] - offsets[0.0]
        assert 0.006 < np.sign(bias) * moved[1] < 0.02, offsets
        assert abs(moved[0]) < 0.002, offsets                              # roll moves y only


def test_packed_positions_for_other_ids_do_not_reach_the_estimator():
    rig = Rig(mocap=None)
    rig.send(6, 2, struct.pack("<Bhhh", 4, 1000, 1000, 1000) + struct.pack("<Bhhh", 6, 1000, 1000, 1000))
    assert rig.cf.state.external_measurements == 0
    rig.send(6, 2, struct.pack("<Bhhh", 5, 1000, 2000, 0))
    assert rig.cf.state.external_measurements == 1 and rig.vehicle.read("locSrv.y") == 2.0


def test_complementary_estimator_ignores_external_position():
    """The trap: extpos streamed but estimator 1 running; position control then chases x = y = 0."""
    rig = Rig(position=(1.0, 1.0, 0.0), estimator=1)
    rig.position_setpoint(1.0, 1.0, 0.5)
    rig.fly(3.0)
    assert rig.vehicle.read("stateEstimate.x") == 0.0 and rig.vehicle.read("stateEstimate.y") == 0.0
    p = rig.truth()
    assert rig.vehicle.read("locSrv.x") == pytest.approx(p[0], abs=0.1)      # the packets did arrive
    assert np.hypot(p[0] - 1.0, p[1] - 1.0) > 1.0                               # it flew away from the goal
    assert abs(p[2] - 0.5) < 0.15                                                # height from the barometer
    # the same flight with the Kalman estimator holds the goal
    ok = Rig(position=(1.0, 1.0, 0.0), estimator=2)
    ok.position_setpoint(1.0, 1.0, 0.5)
    ok.fly(5.0)
    assert np.linalg.norm(ok.truth() - (1.0, 1.0, 0.5)) < 0.05


def test_hover_and_velocity_world_setpoints():
    rig = Rig()
    rig.setpoint = bytes([10]) + struct.pack("<ffff", 0.0, 0.0, 0.0, 0.5)        # hover at 0.5 m
    rig.fly(5.0)
    assert rig.truth()[2] == pytest.approx(0.5, abs=0.05)
    start = rig.truth().copy()
    rig.setpoint = bytes([10]) + struct.pack("<ffff", 0.3, 0.0, 0.0, 0.5)        # 0.3 m/s body x
    rig.fly(3.0)
    moved = rig.truth() - start
    assert 0.5 < moved[0] < 1.1 and abs(moved[1]) < 0.15
    start = rig.truth().copy()
    rig.setpoint = bytes([8]) + struct.pack("<ffff", 0.0, -0.4, 0.1, 0.0)        # world velocity
    rig.fly(3.0)
    moved = rig.truth() - start
    assert -1.4 < moved[1] < -0.7 and 0.15 < moved[2] < 0.45 and abs(moved[0]) < 0.25
    assert rig.vehicle.read("ctrltarget.vy") == pytest.approx(-0.4)


def test_yaw_rate_sign_legacy_and_new():
    for kind, sign in ((5, -1.0), (10, 1.0)):
        rig = Rig()
        rig.setpoint = bytes([kind]) + struct.pack("<ffff", 0.0, 0.0, 30.0, 0.5)
        rig.fly(3.0)
        yaw = rig.vehicle.read("stateEstimate.yaw")
        assert sign * yaw > 30.0, (kind, yaw)                 # counter-clockwise for 10, clockwise for 5


def test_mocap_loss_makes_the_estimate_drift():
    rig = Rig()
    rig.position_setpoint(0.0, 0.0, 0.7)
    rig.fly(SETTLED_S)
    assert np.linalg.norm(rig.truth() - (0, 0, 0.7)) < 0.03
    rig.mocap = None
    rig.fly(1.0)
    after_1s = np.linalg.norm(rig.truth()[:2])
    rig.fly(2.0)
    after_3s = np.linalg.norm(rig.truth()[:2])
    assert 0.01 < after_1s < 0.15 and after_3s > 3 * after_1s            # quadratic run-away, the truth moves
    est = np.array([rig.vehicle.read("stateEstimate." + a) for a in "xy"])
    assert np.linalg.norm(est) < 0.05                                   # while the firmware believes it holds
    rig.mocap = "position"
    rig.fly(4.0)
    assert np.linalg.norm(rig.truth() - (0, 0, 0.7)) < 0.05             # and it comes back


def test_reset_estimation_uses_initial_position():
    rig = Rig(position=(2.0, -1.0, 0.0), mocap=None)
    rig.param("kalman.initialX", 2.0)
    rig.param("kalman.initialY", -1.0)
    rig.param("kalman.resetEstimation", 1)
    rig.fly(0.001)
    assert rig.vehicle.read("stateEstimate.x") == pytest.approx(2.0)
    assert rig.vehicle.read("stateEstimate.y") == pytest.approx(-1.0)
    rig.param("stabilizer.estimator", 1)
    rig.fly(0.001)
    assert rig.vehicle.read("stateEstimate.x") == 0.0


def test_pid_gains_are_parameters():
    rig = Rig()
    assert rig.cf.params.value("posCtlPid.zKi") == pytest.approx(0.5)
    assert rig.cf.params.value("velCtlPid.vzKi") == pytest.approx(15.0)
    assert rig.cf.params.value("posCtlPid.thrustBase") == 36000
    rig.param("posCtlPid.xKp", 0.0)                  # no position feedback on x: it does not go there
    rig.position_setpoint(0.8, 0.0, 0.5)
    rig.fly(4.0)
    assert abs(rig.truth()[0]) < 0.2 and rig.truth()[2] == pytest.approx(0.5, abs=0.08)


def test_wrong_length_halts_like_the_firmware_assert(caplog):
    rig = Rig()
    rig.position_setpoint(0.0, 0.0, 0.5)
    rig.fly(3.0)
    assert rig.truth()[2] > 0.4
    rig.setpoint = None
    with caplog.at_level(logging.ERROR):
        rig.send(7, 0, bytes([10]) + struct.pack("<fff", 0, 0, 0))               # hover, 12 bytes instead of 16
    assert "type 10" in rig.cf.state.halted and "7c0a" in caplog.text
    assert rig.vehicle.lock_reason == "firmware assert"
    rig.send(15, 0, b"ping")
    assert rig.cf.pop_outgoing() is None                                          # no more answers
    rig.position_setpoint(0.0, 0.0, 0.5)
    rig.fly(1.5)
    assert rig.truth()[2] < 0.01 and rig.vehicle.motors().max() == 0             # fell, motors stay off
    rig.cf.reboot()
    assert not rig.cf.state.halted and rig.vehicle.lock_reason == ""


def test_notify_setpoint_stop_hands_over_and_stops_without_a_plan():
    rig = Rig()
    rig.position_setpoint(0.0, 0.0, 0.5)
    rig.fly(3.0)
    rig.setpoint = None
    rig.send(7, 1, b"\x00" + struct.pack("<I", 100))
    rig.fly(0.02)
    assert rig.vehicle.motors().max() == 0 and rig.cf.state.setpoint_stop_notices == 1
    assert not rig.cf.state.halted


def test_setpoint_watchdog_levels_then_locks():
    rig = Rig()
    rig.position_setpoint(0.0, 0.0, 0.5)
    rig.fly(3.0)
    rig.setpoint = None
    rig.fly(1.0)
    assert rig.vehicle.motors().max() > 0 and rig.vehicle.lock_reason == ""
    rig.fly(1.2)
    assert rig.vehicle.lock_reason == "setpoint watchdog" and rig.vehicle.motors().max() == 0


def test_fuzz_ports_6_and_7_never_break_the_world():
    rig = Rig(mocap=None)
    rnd = random.Random(11)
    halts = 0
    for k in range(3000):
        port = rnd.choice((6, 7))
        channel = rnd.randrange(4)
        kind = rnd.randrange(14)
        payload = bytes([kind]) + bytes(rnd.randrange(256) for _ in range(rnd.randrange(30)))
        rig.send(port, channel, payload[:30])
        if k % 10 == 0:
            rig.fly(0.005)
        if rig.cf.state.halted:
            assert rig.cf.state.halted.startswith("port 7"), rig.cf.state.halted
            halts += 1
            rig.cf.reboot()
    assert halts > 50
    state = rig.vehicle.state()
    assert np.all(np.isfinite(state["position"])) and np.all(np.isfinite(state["velocity"]))
    rig.cf.reboot()
    rig.vehicle.place((0.0, 0.0, 0.0))
    rig.param("stabilizer.estimator", 2)
    rig.mocap = "position"
    rig.position_setpoint(0.0, 0.0, 0.5)
    rig.fly(5.0)
    assert np.linalg.norm(rig.truth() - (0, 0, 0.5)) < 0.05          # still flies after all that
