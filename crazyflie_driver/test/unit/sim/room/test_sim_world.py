"""The simulated world: vehicles, readings, battery, tick listeners, real time, mocap, closed loop."""
from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from crazyflie_driver.sim.room import battery
from crazyflie_driver.sim.room.mocap import MocapModel
from crazyflie_driver.sim.room.physics import VehicleParams
from crazyflie_driver.sim.room.world import World

HOVER = int(round(VehicleParams().hover_command()))


def mean_reading(w, v, name, samples=200):
    out = []
    for _ in range(samples):
        w.step(1)
        out.append(v.read(name))
    return float(np.mean(out)), float(np.std(out))


def test_sensors_at_rest():
    w = World(speed=0, seed=3)
    v = w.add_vehicle("cf1", position=(1.0, 2.0, 0.0))
    acc_z, acc_sd = mean_reading(w, v, "acc.z")
    assert acc_z == pytest.approx(1.0, abs=0.02) and 0.002 < acc_sd < 0.02
    assert mean_reading(w, v, "acc.x")[0] == pytest.approx(0.0, abs=0.02)
    for axis in "xyz":
        mean, sd = mean_reading(w, v, "gyro." + axis)
        assert abs(mean) < 0.3 and 0.03 < sd < 0.3
    assert v.read("baro.pressure") == pytest.approx(1013.25, abs=0.5)
    assert v.read("baro.asl") == pytest.approx(0.0, abs=4.0)
    assert 20.0 < v.read("baro.temp") < 35.0
    assert v.read("pm.vbat") == pytest.approx(4.19, abs=0.02) and v.read("pm.state") == 0
    assert v.read("mag.x") > 0.1 and v.read("mag.z") < -0.3          # field north and down
    assert [v.read("motor.m%d" % i) for i in range(1, 5)] == [0.0] * 4
    # the default (complementary) estimator knows no horizontal position; its z is the barometer's
    assert v.read("stabilizer.roll") == 0.0 and v.read("stateEstimate.x") == 0.0
    assert v.read("stateEstimate.z") == pytest.approx(0.0, abs=1e-9)
    assert v.read("no.such") == 0.0 and v.read("garbage") == 0.0
    assert v.pose()[0] == pytest.approx([1.0, 2.0, 0.0])


def test_barometer_follows_altitude():
    w = World(speed=0, seed=3)
    v = w.add_vehicle("cf1", position=(0, 0, 0.0))
    ground = mean_reading(w, v, "baro.pressure", 50)[0]
    v.place((0, 0, 10.0))
    w.bodies.thrust[0] = VehicleParams().thrust(HOVER)
    high = v.read("baro.pressure")
    assert ground - high == pytest.approx(1.18, abs=0.1)           # ≈ 11.8 Pa per m


def test_noise_is_reproducible_with_a_seed():
    def series(seed):
        w = World(speed=0, seed=seed)
        v = w.add_vehicle("cf1")
        return [(w.step(1), v.read("acc.z"), v.read("gyro.x"))[1:] for _ in range(20)]
    assert series(7) == series(7)
    assert series(7) != series(8)


def test_add_and_remove_vehicles_keep_the_others_state():
    w = World(speed=0, seed=1)
    a = w.add_vehicle("a", position=(0, 0, 5.0))
    b = w.add_vehicle("b", position=(1, 0, 0))
    c = w.add_vehicle("c", position=(2, 0, 3.0))
    with pytest.raises(ValueError, match="already"):
        w.add_vehicle("a")
    with pytest.raises(ValueError, match="position"):
        w.add_vehicle("d", position=(0, 0))
    w.step(100)
    w.remove_vehicle("b")
    assert [v.name for v in w.vehicles()] == ["a", "c"]
    assert b.removed and b.read("acc.z") == 0.0
    with pytest.raises(KeyError):
        w.vehicle("b")
    with pytest.raises(KeyError):
        w.remove_vehicle("b")
    w.step(100)
    t = 0.2
    assert c.pose()[0] == pytest.approx([2, 0, 3.0 - 0.5 * 9.81 * t * t], abs=1e-6)
    assert w.vehicle("a") is a
    d = w.add_vehicle("d", position=(5, 5, 0))
    assert d.pose()[0] == pytest.approx([5, 5, 0])


def test_tick_listeners_run_at_their_world_time_period():
    w = World(speed=0)
    seen, fast = [], []
    w.add_tick_listener(seen.append, 0.01)
    w.add_tick_listener(fast.append, 0.001)
    w.step(1000)
    assert len(seen) == 100 and len(fast) == 1000
    assert np.diff(seen) == pytest.approx(np.full(99, 0.01))
    assert seen[-1] == pytest.approx(1.0)
    with pytest.raises(ValueError):
        w.add_tick_listener(seen.append, 0.0)


def test_a_failing_listener_does_not_stop_the_world():
    w = World(speed=0)

    def bad(t):
        raise RuntimeError("boom")
    w.add_tick_listener(bad, 0.001)
    w.step(5)
    assert w.time == pytest.approx(0.005)


def test_background_thread_runs_in_real_time_and_vehicle_calls_are_thread_safe():
    w = World(speed=1.0, seed=1)
    v = w.add_vehicle("cf1")
    errors = []

    def client():
        try:
            for _ in range(300):
                v.set_rpyt(0, 0, 0, 0)
                v.read("acc.z")
                v.pose()
        except Exception as e:       # pragma: no cover - reported below
            errors.append(e)
    w.start()
    t0 = time.monotonic()
    threads = [threading.Thread(target=client) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(5.0)
    time.sleep(max(0.0, 0.5 - (time.monotonic() - t0)))
    elapsed = time.monotonic() - t0
    w.stop()
    assert not errors
    assert w.time == pytest.approx(elapsed, abs=0.25)
    assert not w.running


def test_speed_zero_runs_faster_than_real_time():
    w = World(speed=0)
    w.add_vehicle("cf1")
    w.start()
    time.sleep(0.5)
    w.stop()
    assert w.time > 0.5


def test_bad_speed_is_refused():
    with pytest.raises(ValueError, match="speed"):
        World(speed=-1)


def test_battery_model_hovers_about_seven_minutes():
    b = battery.BatteryStates()
    b.add()
    hover_thrust = np.full((1, 4), VehicleParams().thrust(HOVER))
    start = None
    t = 0.0
    history = {}
    while t < 480.0:
        battery.update(b, 0.1, hover_thrust)
        t += 0.1
        if start is None:
            start = float(b.vbat[0])
        for minute in (1, 3, 5):
            if abs(t - 60 * minute) < 0.05:
                history[minute] = float(b.vbat[0])
        if b.state[0] == battery.PM_LOW_POWER and "low" not in history:
            history["low"] = t
        if b.state[0] == battery.PM_SHUTDOWN:
            history["empty"] = t
            break
    assert start == pytest.approx(3.88, abs=0.05)                      # ≈ 0.3 V sag at hover
    assert start > history[1] > history[3] > history[5]
    assert 6.0 * 60 < history["low"] < 7.5 * 60
    assert 6.3 * 60 < history["empty"] < 7.8 * 60


def test_battery_in_the_world_sags_under_load_and_ends_the_flight():
    w = World(speed=0, seed=1)
    v = w.add_vehicle("cf1", position=(0, 0, 0), mass=0.06, battery_charge=0.08)  # too heavy to lift
    idle = v.read("pm.vbat")
    v.set_rpyt(0, 0, 0, 0)
    w.step(2)
    loaded = []
    for _ in range(200):                         # 40 s at hover-level motor commands
        v.set_rpyt(0, 0, 0, HOVER)
        w.step(200)
        if v.read("pm.state") == battery.PM_SHUTDOWN:
            break
        loaded.append(v.read("pm.vbat"))
    assert idle - loaded[0] > 0.25
    assert loaded[-1] < loaded[0] - 0.15
    assert all(later <= earlier + 0.02 for earlier, later in zip(loaded, loaded[1:]))
    assert v.read("pm.state") == battery.PM_SHUTDOWN
    w.step(20)
    assert v.motors().max() == 0 and v.lock_reason == "battery empty"


def test_mocap_samples_at_its_rate_with_noise_latency_and_dropout():
    w = World(speed=0, seed=1)
    w.add_vehicle("cf1", position=(1.0, 2.0, 0.0))
    w.add_vehicle("cf2", position=(-1.0, 0.0, 0.0))
    m = MocapModel(w, rate=100.0, position_noise=0.0005, latency=0.01, seed=4).attach()
    w.step(1000)
    frames = [f for f in m.pop_frames() if f.name == "cf1"]
    assert len(frames) in (99, 100)
    stamps = np.array([f.stamp for f in frames])
    assert np.diff(stamps) == pytest.approx(np.full(len(stamps) - 1, 0.01))
    assert all(f.delivered - f.stamp == pytest.approx(0.01) for f in frames)
    pos = np.array([f.position for f in frames])
    assert pos.mean(axis=0) == pytest.approx([1.0, 2.0, 0.0], abs=3e-4)
    assert 0.0003 < pos[:, 0].std() < 0.0008
    assert m.latest("cf2").position == pytest.approx([-1.0, 0.0, 0.0], abs=0.003)
    assert abs(np.linalg.norm(frames[0].quaternion) - 1.0) < 1e-9

    dropping = MocapModel(w, dropout=0.5, seed=2).attach()
    w.step(2000)
    got = len(dropping.pop_frames())
    assert 120 < got < 280                        # 2 vehicles × 200 frames, half dropped
    assert dropping.frames_dropped + dropping.frames_captured == 400



def test_body_faults_merge_with_what_the_body_has_and_refuse_out_of_range_values():
    w = World(speed=0, seed=1)
    w.add_vehicle("cf1")
    m = MocapModel(w, rate=100.0, seed=4)
    f = m.set_body_faults("cf1", 10.0, noise=0.01, latency=0.05, rate=20, dropout=0.25, freeze=2.0, hide=math.inf)
    assert (f.noise, f.latency, f.rate, f.dropout, f.freeze_until, f.hide_until) == \
        (0.01, 0.05, 20.0, 0.25, 12.0, math.inf)
    f = m.set_body_faults("cf1", 11.0, rate=100, freeze=0)          # the system's rate; 0 ends the freeze
    assert (f.noise, f.latency, f.rate, f.dropout, f.freeze_until, f.hide_until) == \
        (0.01, 0.05, None, 0.25, -math.inf, math.inf)
    for args, says in [({"noise": -0.1}, "noise must be a finite number >= 0 m"),
                       ({"noise": math.nan}, "noise must be a finite"),
                       ({"latency": math.inf}, "latency must be a finite number >= 0 s"),
                       ({"rate": 0}, r"rate must be in \(0, 100\] Hz"),
                       ({"rate": 101}, r"rate must be in \(0, 100\] Hz"),
                       ({"dropout": 1.5}, "dropout must be a probability 0..1"),
                       ({"freeze": -1}, "freeze must last >= 0 s"),
                       ({"hide": math.nan}, "hide must last >= 0 s"),
                       ({"noise": 0.5, "hide": -1}, "hide must last")]:            # nothing applied
        with pytest.raises(ValueError, match=says):
            m.set_body_faults("cf1", 12.0, **args)
    assert m.body_faults(12.0)["cf1"] == f
    with pytest.raises(KeyError, match="no vehicle called 'cf9'"):
        m.set_body_faults("cf9", 12.0, noise=0.1)

class PositionController:
    """A small offboard position PID (world frame, yaw held at 0) commanding raw RPYT."""

    def __init__(self, hover: float) -> None:
        self.hover = hover
        self.integral_z = 0.0
        self.last = None

    def command(self, pos, t, goal):
        if self.last is None:
            vel = np.zeros(3)
        else:
            vel = (pos - self.last[0]) / (t - self.last[1])
        self.last = (pos, t)
        e = np.asarray(goal) - pos
        self.integral_z = min(max(self.integral_z + e[2] * 0.02, -0.5), 0.5)
        # +x needs nose down (negative pitch); +y needs left side down (negative roll)
        pitch = -float(np.clip(20.0 * e[0] - 12.0 * vel[0], -15, 15))
        roll = -float(np.clip(20.0 * e[1] - 12.0 * vel[1], -15, 15))
        thrust = self.hover + 15000.0 * e[2] - 9000.0 * vel[2] + 4000.0 * self.integral_z
        return roll, pitch, 0.0, int(np.clip(thrust, 10000, 60000))


def test_closed_loop_lift_off_hold_and_land_on_mocap():
    w = World(speed=0, seed=5)
    v = w.add_vehicle("cf1", position=(0.0, 0.0, 0.0), mass=0.030)
    mocap = MocapModel(w, rate=100.0, latency=0.008, seed=5).attach()
    ctl = PositionController(VehicleParams(mass=0.030).hover_command())
    v.set_rpyt(0, 0, 0, 0)
    w.step(20)
    goal = np.array([0.0, 0.0, 0.5])
    errors = []
    for k in range(400):                                   # 8 s at 50 Hz
        w.step(20)
        pos, _, stamp = mocap.latest_pose("cf1")
        v.set_rpyt(*ctl.command(pos, stamp, goal))
        if k >= 300:
            errors.append(np.linalg.norm(v.pose()[0] - goal))
    assert max(errors) < 0.05, max(errors)
    assert np.sqrt(np.mean(np.square(errors))) < 0.03
    for k in range(150):                                   # land: goal sinks to the floor
        goal = np.array([0.0, 0.0, max(0.5 - 0.01 * k, -0.1)])
        w.step(20)
        pos, _, stamp = mocap.latest_pose("cf1")
        if pos[2] < 0.03:
            break
        v.set_rpyt(*ctl.command(pos, stamp, goal))
    for _ in range(25):
        v.set_rpyt(0, 0, 0, 0)
        w.step(20)
    p = v.pose()[0]
    assert p[2] == 0.0 and abs(p[0]) < 0.1 and abs(p[1]) < 0.1
    assert v.motors().max() == 0 and w.bodies.on_ground[0]
