"""The simulated firmware controller driven through Vehicle.set_rpyt: signs, thrust rules, safety."""
from __future__ import annotations

import math

import pytest

from crazyflie_driver.sim.onboard.stabilizer import default_params
from crazyflie_driver.sim.room.physics import VehicleParams, euler_from_quat
from crazyflie_driver.sim.room.world import World

HOVER = int(round(VehicleParams().hover_command()))
GENERATIONS = ("current", "2016.02")


def airborne(firmware="current", z=1.0, seed=1):
    """A vehicle hovering at ``z`` (placed there, unlocked, hover thrust for 0.3 s)."""
    w = World(speed=0, seed=seed)
    v = w.add_vehicle("cf1", position=(0.0, 0.0, z), firmware=firmware)
    v.set_rpyt(0, 0, 0, 0)
    w.step(2)
    return w, v


def fly(w, v, seconds, roll=0.0, pitch=0.0, yaw=0.0, thrust=HOVER, rate_hz=100):
    """Send the same setpoint at ``rate_hz`` for ``seconds`` of world time."""
    for _ in range(int(seconds * rate_hz)):
        v.set_rpyt(roll, pitch, yaw, thrust)
        w.step(int(1000 / rate_hz))


def yaw_deg(v):
    return math.degrees(euler_from_quat(v.pose()[1][None])[0, 2])


@pytest.mark.parametrize("firmware", GENERATIONS)
@pytest.mark.parametrize("angle, toward, across", [
    pytest.param("roll", 1, 0, id="positive roll moves toward -y"),
    pytest.param("pitch", 0, 1, id="positive pitch moves toward -x"),    # logged pitch: legacy nose-up-positive
])
def test_a_positive_angle_moves_toward_minus_its_axis_and_logs_as_given(firmware, angle, toward, across):
    w, v = airborne(firmware)
    fly(w, v, 1.0, **{angle: 5.0})
    p = v.pose()[0]
    assert p[toward] < -0.1 and abs(p[across]) < 0.03
    assert v.read("stabilizer." + angle) == pytest.approx(5.0, abs=1.5)


@pytest.mark.parametrize("firmware", GENERATIONS)
def test_positive_yaw_rate_turns_clockwise(firmware):
    w, v = airborne(firmware)
    fly(w, v, 1.0)
    start = yaw_deg(v)
    fly(w, v, 2.0, yaw=30.0)
    turned = yaw_deg(v) - start
    assert turned == pytest.approx(-60.0, abs=8.0)
    assert v.read("stabilizer.yaw") == pytest.approx(yaw_deg(v), abs=0.5)


def test_hover_thrust_holds_altitude_for_the_configured_mass():
    for mass in (0.027, 0.032):
        w = World(speed=0, seed=2)
        v = w.add_vehicle("cf", position=(0, 0, 1.0), mass=mass)
        v.set_rpyt(0, 0, 0, 0)
        hover = int(round(VehicleParams(mass=mass).hover_command()))
        w.bodies.thrust[0] = VehicleParams(mass=mass).thrust(hover)   # rotors already at speed
        fly(w, v, 1.0, thrust=hover)
        assert abs(v.velocity()[2]) < 0.02, mass
        assert v.pose()[0][2] == pytest.approx(1.0, abs=0.01), mass
        fly(w, v, 0.3, thrust=int(hover * 1.1))
        assert v.velocity()[2] > 0.2, mass


def test_thrust_lock_until_a_zero_thrust_setpoint():
    w = World(speed=0, seed=1)
    v = w.add_vehicle("cf1")
    fly(w, v, 0.2, thrust=40000)
    assert v.motors().max() == 0 and v.read("motor.m1") == 0
    v.set_rpyt(0, 0, 0, 0)
    fly(w, v, 0.2, thrust=40000)
    assert v.motors().min() > 30000
    assert v.read("stabilizer.thrust") == 40000


def test_thrust_below_1000_is_off_and_above_60000_clamped():
    w, v = airborne()
    fly(w, v, 0.1, thrust=999)
    assert v.motors().max() == 0
    fly(w, v, 0.1, thrust=65000)
    assert v.read("stabilizer.thrust") == 60000


def test_watchdog_levels_out_after_half_a_second_then_stops_and_locks_current():
    w, v = airborne("current", z=3.0)
    fly(w, v, 0.5, roll=10.0, thrust=HOVER + 3000)
    assert v.read("stabilizer.roll") == pytest.approx(10.0, abs=2.0)
    w.step(400)                                   # 0.4 s silence: still holding the command
    assert v.read("stabilizer.roll") > 5.0
    w.step(600)                                   # 1.0 s silence: levelled, thrust kept
    assert abs(v.read("stabilizer.roll")) < 2.0
    assert v.read("stabilizer.thrust") == HOVER + 3000
    assert v.motors().min() > 0
    w.step(1100)                                  # 2.1 s silence: motors off, locked
    assert v.motors().max() == 0
    assert v.lock_reason == "setpoint watchdog"
    v.set_rpyt(0, 0, 0, 0)
    fly(w, v, 0.2, thrust=40000)
    assert v.motors().max() == 0                  # needs a reboot
    v.reboot()
    v.set_rpyt(0, 0, 0, 0)
    fly(w, v, 0.1, thrust=40000)
    assert v.motors().min() > 0


def test_watchdog_2016_relocks_thrust_until_a_zero_setpoint():
    w, v = airborne("2016.02", z=3.0)
    fly(w, v, 0.3, thrust=HOVER)
    w.step(2100)
    assert v.motors().max() == 0 and v.lock_reason == ""
    fly(w, v, 0.1, thrust=40000)
    assert v.motors().max() == 0
    v.set_rpyt(0, 0, 0, 0)
    fly(w, v, 0.1, thrust=40000)
    assert v.motors().min() > 0


def test_an_idle_vehicle_on_the_floor_is_not_locked_by_the_watchdog():
    w = World(speed=0, seed=1)
    v = w.add_vehicle("cf1")
    v.set_rpyt(0, 0, 0, 0)
    w.step(3000)
    assert v.lock_reason == "" and v.read("sys.canfly") == 1.0
    fly(w, v, 0.1, thrust=40000)
    assert v.motors().min() > 0


def test_emergency_stop_cuts_motors_at_once_and_holds_until_reboot():
    w, v = airborne(z=2.0)
    fly(w, v, 0.3)
    v.emergency_stop()
    w.step(1)
    assert v.motors().max() == 0
    assert v.lock_reason == "emergency stop" and v.read("sys.canfly") == 0.0
    v.emergency_stop()                            # idempotent
    v.set_rpyt(0, 0, 0, 0)
    fly(w, v, 0.2, thrust=50000)
    assert v.motors().max() == 0
    w.step(2000)
    assert v.pose()[0][2] == 0.0                  # fell to the floor, not through it


def test_tumble_detection_locks_the_current_firmware_only():
    for firmware, expect in (("current", "tumbled"), ("2016.02", "")):
        w, v = airborne(firmware, z=20.0)
        fly(w, v, 1.3, roll=75.0, thrust=50000)
        assert v.lock_reason == expect, firmware
        assert (v.motors().max() == 0) == bool(expect)


def test_param_defaults_follow_the_firmware_generation():
    cur, old = default_params("current"), default_params("2016.02")
    assert cur["pid_rate.roll_kp"] == 250.0 and cur["pid_rate.roll_ki"] == 500.0 and cur["pid_rate.roll_kd"] == 2.5
    assert cur["pid_attitude.pitch_kp"] == 6.0 and cur["pid_attitude.yaw_kd"] == 0.35
    assert old["pid_rate.roll_kp"] == 70.0 and old["pid_attitude.roll_kp"] == 3.5
    assert old["pid_attitude.yaw_kp"] == 10.0 and old["pid_rate.yaw_ki"] == 16.7
    assert len(cur) == 18
    w = World(speed=0)
    assert w.add_vehicle("a", firmware="2016.02").param_defaults() == old
    with pytest.raises(ValueError, match="firmware"):
        w.add_vehicle("b", firmware="2019.1")


def test_write_param_changes_gains_live():
    w, v = airborne()
    for name in ("pid_attitude.roll_kp", "pid_attitude.roll_ki"):
        v.write_param(name, 0.0)
    assert w.onboard.params(0)["pid_attitude.roll_kp"] == 0.0
    fly(w, v, 0.5, roll=10.0)
    assert abs(v.read("stabilizer.roll")) < 1.0  # no angle loop: no tilt
    v.write_param("pid_attitude.roll_kp", 6.0)
    fly(w, v, 0.5, roll=10.0)
    assert v.read("stabilizer.roll") > 5.0
    v.write_param("ring.effect", 3)              # not physics-backed: ignored
    v.reboot()
    assert w.onboard.params(0)["pid_attitude.roll_ki"] == 3.0


def test_motor_power_set_drives_the_motors_directly():
    w = World(speed=0)
    v = w.add_vehicle("cf1")
    v.write_param("motorPowerSet.m2", 12000)
    v.write_param("motorPowerSet.enable", 1)
    w.step(5)
    assert list(v.motors()) == [0, 12000, 0, 0]
    assert v.read("motor.m2") == 12000


def test_current_firmware_clamping_keeps_the_torque_2016_clips_each_motor():
    for firmware in GENERATIONS:
        w, v = airborne(firmware, z=5.0)
        o = w.onboard.s
        fly(w, v, 0.05, thrust=60000)
        if w.ticks % 2 == 0:
            w.step(1)                             # next tick has no rate-loop update
        o.rate_out[0] = (20000.0, 0.0, 0.0)       # a big roll demand, then one mixing tick
        v.set_rpyt(0, 0, 0, 60000)
        w.step(1)
        m = v.motors()
        if firmware == "current":
            assert m.max() == 65535 and m[2] - m[1] == pytest.approx(20000, abs=1)
        else:
            assert m[2] == 65535 and m[1] == 50000


def test_the_state_says_when_the_supervisor_locked():
    """A test times a cut from the lock's own world time, not from when it happened to look."""
    w, v = airborne("current", z=3.0)
    assert v.state()["locked_at"] is None
    fly(w, v, 0.3, thrust=HOVER)
    last_setpoint = w.time - 0.01                 # fly() steps 10 ms after its last setpoint
    w.step(2500)
    s = v.state()
    assert s["locked"] == "setpoint watchdog"
    assert s["locked_at"] == pytest.approx(last_setpoint + 2.0, abs=0.0015)    # the 2 s watchdog, to a tick
    w.step(100)
    assert v.state()["locked_at"] == s["locked_at"]      # stays the first lock's time
    w2, v2 = airborne("current", z=3.0)
    w2.step(37)
    v2.emergency_stop()
    assert v2.state()["locked"] == "emergency stop" and v2.state()["locked_at"] == pytest.approx(w2.time)
