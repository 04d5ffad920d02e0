"""Fault injection: the command's words, the world server's fault operations and their effect on the
air, the vehicles and the motion capture (in process, on a stepped world)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.sim.air.faults import FaultError, parse_command, split_commands
from crazyflie_driver.sim.air.medium import RemoteMedium
from crazyflie_driver.sim.room.battery import CRITICAL_VOLTAGE, PERSIST_S, PM_SHUTDOWN
from crazyflie_driver.sim.room.mocap import MocapModel
from crazyflie_driver.sim.room.world import World
from crazyflie_driver.sim.world_server import WorldServer

URI1 = "radio://0/80/2M/E7E7E7E701"
URI2 = "radio://1/80/2M/E7E7E7E702"
A1 = bytes.fromhex("E7E7E7E701")


# --- the words ------------------------------------------------------------------------------------
@pytest.mark.parametrize("words, op, args", [
    ("unplug 0", "set_dongle_faults", {"dongle": 0, "unplugged": True}),
    ("replug 1", "set_dongle_faults", {"dongle": 1, "unplugged": False}),
    ("loss 0 --packet 0.3 --ack 10%", "set_dongle_faults", {"dongle": 0, "packet_loss": 30.0, "ack_loss": 10.0}),
    ("loss 0 --ack 1", "set_dongle_faults", {"dongle": 0, "ack_loss": 100.0}),
    ("latency 0 50ms", "set_dongle_faults", {"dongle": 0, "latency_s": 0.05}),
    ("latency 0 0.02s", "set_dongle_faults", {"dongle": 0, "latency_s": 0.02}),
    ("power crazyflie1 off", "power", {"uri": "crazyflie1", "on": False}),
    ("battery crazyflie1 3.3", "set_battery", {"uri": "crazyflie1", "voltage": 3.3}),
    ("battery crazyflie1 3.1V", "set_battery", {"uri": "crazyflie1", "voltage": 3.1}),
    ("battery crazyflie1 20%", "set_battery", {"uri": "crazyflie1", "charge": 0.2}),
    ("mocap crazyflie1 --freeze 2", "set_mocap_faults", {"uri": "crazyflie1", "freeze_s": 2.0}),
    ("mocap crazyflie1 --freeze", "set_mocap_faults", {"uri": "crazyflie1", "freeze_s": True}),
    ("mocap cf --hide 200ms --noise 0.01 --latency 30ms --rate 20 --dropout 0.1", "set_mocap_faults",
     {"uri": "cf", "hide_s": 0.2, "noise_m": 0.01, "latency_s": 0.03, "rate_hz": 20.0, "dropout": 0.1}),
    ("mocap cf --noise 0", "set_mocap_faults", {"uri": "cf", "noise_m": 0.0}),
    ("mocap cf --clear", "set_mocap_faults", {"uri": "cf", "clear": True}),
    ("list", "faults", {}),
    ("clear", "clear_faults", {}),
    ("clear 1", "clear_faults", {"dongle": 1}),
    ("clear crazyflie1", "clear_faults", {"uri": "crazyflie1"}),
])
def test_words_become_one_control_operation(words, op, args):
    got_op, got_args = parse_command(words)
    assert got_op == op
    assert got_args == pytest.approx(args)


@pytest.mark.parametrize("words, says", [
    ("", "say which fault"),
    ("explode 0", "invalid choice"),
    ("unplug", "required"),
    ("unplug zero", "dongle must be a number"),
    ("unplug -1", "dongle must be >= 0"),
    ("loss 0", "give --packet"),
    ("loss 0 --packet 1.5", "fraction 0..1"),
    ("loss 0 --ack lots", "fraction 0..1"),
    ("latency 0 50", "give a unit, e.g. 50ms"),
    ("latency 0 fast", "duration like"),
    ("power cf1 maybe", "invalid choice"),
    ("battery cf1 7", "within 2.5..4.3 V"),
    ("battery cf1 full", "volts"),
    ("mocap cf1", "say what goes wrong"),
    ("mocap cf1 --noise -1", "from 0 to 100 m"),
    ("mocap cf1 --noise lots", "--noise must be a number from 0 to 100 m, got 'lots'"),
    ("mocap cf1 --noise nan", "from 0 to 100 m"),
    ("mocap cf1 --noise inf", "--noise must be a number from 0 to 100 m, got 'inf'"),
    ("mocap cf1 --noise 1e300", "from 0 to 100 m"),
    ("mocap cf1 --latency 1e300", "--latency '1e300' is over 1 s"),
    ("mocap cf1 --latency 2s", "is over 1 s"),
    ("mocap cf1 --latency inf", "duration >= 0"),
    ("mocap cf1 --rate 0", ">= 0.1 Hz"),
    ("mocap cf1 --rate 1e-300", ">= 0.1 Hz"),
    ("mocap cf1 --rate fast", "--rate must be a number >= 0.1 Hz, got 'fast'"),
    ("mocap cf1 --freeze -2", ">= 0"),
    ("unplug 0 'unclosed", "cannot read"),
])
def test_bad_words_say_what_to_type(words, says):
    with pytest.raises(FaultError, match=says.replace(".", r"\.").replace("(", r"\(")):
        parse_command(words)


def test_launch_argument_splits_commands():
    assert split_commands(" unplug 0 ;; battery cf1 3.5; ") == ["unplug 0", "battery cf1 3.5"]


# --- the operations on a world --------------------------------------------------------------------
@pytest.fixture
def served():
    world = World(speed=0, seed=3)
    server = WorldServer(world, dongles=2, port=0, seed=1)
    server.add_crazyflie(URI1, "cf1", (0.0, 0.0, 0.0))
    server.add_crazyflie(URI2, "cf2", (1.0, 0.0, 0.0))
    host, port = server.start()
    medium = RemoteMedium(host, port)
    yield world, server, medium
    medium.close()
    server.stop()


def apply(medium, words):
    op, args = parse_command(words)
    return medium.control(op, **args)


def test_unplug_and_replug_reach_the_air(served):
    world, server, medium = served
    assert medium.transmit(0, 80, 2, A1, b"\xff").acked
    assert apply(medium, "unplug 0")["unplugged"]
    reply = medium.transmit(0, 80, 2, A1, b"\xff")
    assert reply.unplugged and not reply.acked
    assert apply(medium, "list") == [["dongle 0", "unplugged"]]
    assert not apply(medium, "replug 0")["unplugged"]
    assert medium.transmit(0, 80, 2, A1, b"\xff").acked
    assert apply(medium, "list") == []


def test_loss_and_latency_reach_the_air(served):
    world, server, medium = served
    apply(medium, "loss 0 --packet 100%")
    assert not any(medium.transmit(0, 80, 2, A1, b"\xff").acked for _ in range(20))
    apply(medium, "loss 0 --packet 0 --ack 1")
    assert not any(medium.transmit(0, 80, 2, A1, b"\xff").acked for _ in range(20))
    apply(medium, "loss 0 --ack 0")
    apply(medium, "latency 0 50ms")
    reply = medium.transmit(0, 80, 2, A1, b"\xff")
    assert reply.acked and reply.latency_s == pytest.approx(0.05)
    assert apply(medium, "list") == [["dongle 0", "latency 50 ms"]]
    assert apply(medium, "clear 0") == []
    assert medium.transmit(0, 80, 2, A1, b"\xff").latency_s == 0.0


def test_power_off_means_no_acks_until_switched_on(served):
    world, server, medium = served
    assert apply(medium, "power cf1 off") == {"powered": False}
    assert not any(medium.transmit(0, 80, 2, A1, b"\xff").acked for _ in range(5))
    assert apply(medium, "list") == [["cf1", "switched off"]]
    assert apply(medium, "power " + URI1 + " on") == {"powered": True}
    assert medium.transmit(0, 80, 2, A1, b"\xff").acked


def test_battery_drained_to_a_voltage_reads_it_and_the_firmware_reacts(served):
    world, server, medium = served
    state = apply(medium, "battery cf1 3.6")
    assert state["vbat"] == pytest.approx(3.6, abs=0.005)
    assert server.crazyflie("cf1").vehicle.read("pm.vbat") == pytest.approx(3.6, abs=0.005)
    assert apply(medium, "battery cf1 50%")["charge"] == pytest.approx(0.5)
    assert "battery set to 50 %" in apply(medium, "list")[0][1]
    apply(medium, "battery cf1 2.99")                     # below critical: the firmware shuts down after 5 s
    assert state["state"] != PM_SHUTDOWN
    world.step(int((PERSIST_S + 0.1) * 1000))
    b = world.vehicle("cf1").battery()
    assert b["vbat"] < CRITICAL_VOLTAGE and b["state"] == PM_SHUTDOWN
    assert world.vehicle("cf1").lock_reason == "battery empty"
    assert world.vehicle("cf2").battery()["state"] != PM_SHUTDOWN


@pytest.mark.parametrize("op, args, says", [
    ("set_dongle_faults", {}, "set_dongle_faults: 'dongle' is required"),
    ("set_dongle_faults", {"dongle": 2}, "no simulated dongle 2 (this world has 2: 0..1)"),
    ("set_dongle_faults", {"dongle": "0"}, "'dongle' must be an integer"),
    ("set_dongle_faults", {"dongle": 0, "packet_loss": 130}, "'packet_loss' must be a number in [0, 100]"),
    ("set_dongle_faults", {"dongle": 0, "latency_s": 3}, "'latency_s' must be a number in [0, 1]"),
    ("set_dongle_faults", {"dongle": 0, "unplugged": "yes"}, "'unplugged' must be true or false"),
    ("power", {"uri": "cf1"}, "power: 'on' is required"),
    ("power", {"uri": "cf9", "on": True}, "no simulated Crazyflie called 'cf9'"),
    ("set_battery", {"uri": "cf1"}, "give either 'voltage'"),
    ("set_battery", {"uri": "cf1", "voltage": 4.5}, "a battery reads"),
    ("set_battery", {"uri": "cf1", "charge": 2}, "'charge' must be a number in [0, 1]"),
    ("set_mocap_faults", {"uri": "cf1", "freeze_s": 1}, "no motion-capture system"),
    ("set_mocap_faults", {"uri": "cf1", "noise_m": 1e300}, "no motion-capture system"),
    ("explode", {}, "unknown control operation 'explode'"),
])
def test_bad_arguments_get_a_clear_error_and_change_nothing(served, op, args, says):
    world, server, medium = served
    with pytest.raises(CrazyflieError) as e:
        medium.control(op, **args)
    assert says in str(e.value)
    assert medium.control("faults") == []
    assert medium.transmit(0, 80, 2, A1, b"\xff").acked          # and the server still serves


# --- motion capture -------------------------------------------------------------------------------
def frames_of(model, name):
    return [f for f in model.pop_frames() if f.name == name]


def test_mocap_freeze_holds_the_pose_with_fresh_stamps_then_lets_go(served):
    world, server, medium = served
    server.mocap = MocapModel(world, rate=100.0, position_noise=0.001, latency=0.0, seed=2).attach()
    world.step(100)
    server.mocap.pop_frames()
    assert apply(medium, "mocap cf1 --freeze 0.5")["faults"] == "frozen for 0.5 s more"
    world.step(400)
    cf1 = frames_of(server.mocap, "cf1")
    assert len(cf1) == 40 and np.diff([f.stamp for f in cf1]) == pytest.approx(np.full(39, 0.01))
    assert all(np.array_equal(f.position, cf1[0].position) for f in cf1)       # noise would move it
    assert apply(medium, "list") == [["cf1", "mocap frozen for 0.1 s more"]]
    world.step(200)
    later = [f for f in frames_of(server.mocap, "cf1") if f.stamp > 0.61]
    assert len({tuple(f.position) for f in later}) == len(later)
    assert apply(medium, "list") == []


def test_mocap_hide_rate_latency_noise_dropout_per_body(served):
    world, server, medium = served
    server.mocap = MocapModel(world, rate=100.0, position_noise=0.0, latency=0.0, seed=2).attach()
    apply(medium, "mocap cf1 --hide 0.3")
    apply(medium, "mocap cf2 --rate 20 --latency 50ms --noise 0.01")
    world.step(1000)
    frames = server.mocap.pop_frames()
    cf1 = [f for f in frames if f.name == "cf1"]
    cf2 = [f for f in frames if f.name == "cf2"]
    assert min(f.stamp for f in cf1) == pytest.approx(0.3) and len(cf1) == 71      # 0.30 .. 1.00
    assert len(cf2) in (19, 20)
    assert all(f.delivered - f.stamp == pytest.approx(0.05) for f in cf2)
    assert 0.004 < np.array([f.position[0] for f in cf2]).std() < 0.02
    assert "rate 20.0 Hz" in dict(map(tuple, apply(medium, "list")))["cf2"]
    apply(medium, "mocap cf2 --clear --dropout 1")
    world.step(200)
    assert [f for f in frames_of(server.mocap, "cf2") if f.stamp > 1.0] == []     # (one in flight before)
    apply(medium, "clear")
    world.step(100)
    assert len(frames_of(server.mocap, "cf2")) == 10
    with pytest.raises(CrazyflieError, match=r"rate must be in \(0, 100\] Hz"):
        apply(medium, "mocap cf2 --rate 500")
    apply(medium, "mocap cf2 --freeze")
    assert dict(map(tuple, apply(medium, "list")))["cf2"] == "mocap frozen for good"
    assert server.mocap.body_faults(1e9)["cf2"].freeze_until == math.inf


@pytest.mark.parametrize("args, says", [
    ({"noise_m": float("inf")}, "'noise_m' must be a number in [0, 100]"),
    ({"noise_m": 1e300}, "'noise_m' must be a number in [0, 100]"),
    ({"latency_s": 1e300}, "'latency_s' must be a number in [0, 1]"),
    ({"rate_hz": 1e-300}, "'rate_hz' must be a number in [0.1, inf]"),
])
def test_the_world_refuses_mocap_faults_beyond_what_a_tracking_system_does(served, args, says):
    """The bounds hold for any client of the world server, not only for the fault tool's words."""
    world, server, medium = served
    server.mocap = MocapModel(world, rate=100.0, latency=0.0, seed=2).attach()
    with pytest.raises(CrazyflieError) as e:
        medium.control("set_mocap_faults", uri="cf1", **args)
    assert says in str(e.value)
    assert medium.control("faults") == []
    with pytest.raises(ValueError, match="finite"):
        server.mocap.set_body_faults("cf1", 0.0, latency=math.inf)


def delivered(model):
    """Frames delivered since the last call, by body: [(stamp, delivered)]."""
    out = {}
    for f in model.pop_frames():
        out.setdefault(f.name, []).append((f.stamp, f.delivered))
    return out


@pytest.mark.parametrize("ending", ["clear", "clear cf1", "mocap cf1 --clear", "mocap cf1 --latency 20ms"])
def test_a_cleared_or_changed_latency_fault_never_stalls_any_body(served, ending):
    """cf1 at 1 s of extra latency, then its fault ends (or shrinks): cf2's frames keep coming every
    10 ms with the system's latency, and cf1's own frames stay in capture order (the ones in flight
    that newer frames overtake are dropped, never delivered late)."""
    world, server, medium = served
    server.mocap = MocapModel(world, rate=100.0, position_noise=0.0, latency=0.008, seed=2).attach()
    apply(medium, "mocap cf1 --latency 1")
    world.step(1500)                                  # 1.5 s: cf1's pipeline holds 1 s of frames
    before = delivered(server.mocap)
    assert all(d - s == pytest.approx(1.008, abs=0.011) for s, d in before["cf1"])
    apply(medium, ending)
    ended = float(world.time)
    got = {}
    for _ in range(50):                               # 0.5 s, tick by tick of the capture period
        world.step(10)
        for name, frames in delivered(server.mocap).items():
            got.setdefault(name, []).extend(frames)
    cf2 = [s for s, _ in got["cf2"]]
    assert len(cf2) >= 49 and max(np.diff(cf2)) == pytest.approx(0.01)
    assert all(d - s < 0.02 for s, d in got["cf2"])
    cf1 = [s for s, _ in before["cf1"] + got["cf1"]]
    assert all(b > a for a, b in zip(cf1, cf1[1:]))   # in capture order: nothing old arrives late
    assert max(cf1) > ended + 0.4                      # and its fresh frames come at once
    assert server.mocap.frames_superseded > 0
