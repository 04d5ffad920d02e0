"""The safety policy (server.safety) from figures and time alone, and its hooks in the worker."""
from __future__ import annotations

import logging
import struct
import time

import pytest

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.protocol import setpoints
from crazyflie_driver.protocol.high_level import CMD_GO_TO_2, CMD_STOP
from crazyflie_driver.protocol.supervisor import CMD_WATCHDOG
from crazyflie_driver.server.safety import (
    ERROR,
    OK,
    WARN,
    Action,
    BatteryWatch,
    DescentPlan,
    Reaction,
    SafetyConfig,
    SafetyMonitor,
    thrust_change_for,
)
from crazyflie_driver.server.safety_actions import setpoint_thrust
from crazyflie_driver.server.setpoint import Setpoint
from crazyflie_driver.server.status import worker_status
from support.worker_doubles import FakeCrazyflie, Recorder, started, wait_for
from support.worker_doubles import poll_actions as run

HOVER = 36344
CURRENT_FW = 12


def monitor(config=None, protocol=2, params=None):
    return SafetyMonitor(config or SafetyConfig(), "cf", lambda: protocol, lambda: params or {})


def hover_for(m, t0, seconds, thrust=HOVER, period=0.02):
    t = t0
    while t < t0 + seconds:
        assert m.note_setpoint(t, thrust)
        t += period
    return t - period




# ---------------------------------------------------------------- config

def test_defaults_are_valid_and_watchdog_off():
    c = SafetyConfig()
    assert c.setpoint_silence and c.battery and c.land_on_shutdown and not c.emergency_watchdog
    assert c.setpoint_silence_s < 0.5        # before the firmware's level-out
    assert c.battery_critical_v < c.battery_warning_v


def test_config_from_params_checks_every_value():
    got = SafetyConfig.from_params(lambda name, default: {"safety/descent_rate": 1, "safety/emergency_watchdog":
                                                         True}.get(name, default))
    assert got.descent_rate == 1.0 and got.emergency_watchdog
    with pytest.raises(ValueError, match="safety/setpoint_silence_s"):
        SafetyConfig(setpoint_silence_s=-1.0)
    with pytest.raises(ValueError, match="true or false"):
        SafetyConfig(battery="yes")
    with pytest.raises(ValueError, match="battery_critical_v"):
        SafetyConfig(battery_warning_v=3.3, battery_critical_v=3.4)
    with pytest.raises(ValueError, match="positive"):
        SafetyConfig(descent_max_height=float("nan"))


# ---------------------------------------------------------------- descent plan

def test_descent_plan_phases_and_bounded_speed():
    p = DescentPlan(HOVER, rate=0.3, max_height=2.0, hold_s=0.3)
    assert p.thrust_at(0.1) == HOVER
    assert p.thrust_at(0.4) < HOVER - 2000                     # accelerating down at ~1 m/s²
    coast = p.thrust_at(1.0)
    assert HOVER - 200 < coast < HOVER                         # sinking, barely accelerating
    assert p.thrust_at(p.duration + 0.01) is None
    # integrate the modelled acceleration: the floor from 2 m is reached, at most ~2x the rate
    v = z = 0.0
    t, dt = 0.0, 0.001
    while t < p.duration:
        a = -(HOVER - p.thrust_at(t)) / thrust_change_for(1.0, HOVER)
        v += a * dt
        z += v * dt
        t += dt
    assert z < -2.0
    assert -0.65 < v < -0.3


# ---------------------------------------------------------------- battery

def test_battery_levels_need_persistence_and_only_go_down():
    b = BatteryWatch(3.45, 3.3, 2.0)
    assert b.update(0.0, 3.40) is None
    assert b.update(1.0, 3.40) is None
    assert b.update(1.5, 3.50) is None                          # a short sag is not a level
    assert all(b.update(t, 3.40) is None for t in (2.0, 3.0))
    assert b.update(3.6, 3.40) is None                          # 3.50 V held until 2.0 s: not 2 s below yet
    assert b.update(4.1, 3.40) == WARN
    assert b.update(4.2, 3.40) is None                          # said once
    for t in (4.6, 5.5, 6.5):
        assert b.update(t, 3.2) is None
    assert b.update(6.7, 3.2) == ERROR
    assert b.update(9.0, 4.0) is None and b.level == ERROR
    assert b.update(8.0, float("nan")) is None


def test_battery_warning_then_critical_descends_once_flying(caplog):
    m = monitor()
    t = hover_for(m, 0.0, 2.0)
    with caplog.at_level(logging.WARNING, logger="crazyflie_driver.server.safety"):
        for i in range(30):
            m.note_battery(t + i * 0.1, 3.40)
            m.note_setpoint(t + i * 0.1, HOVER)
        assert m.poll(t + 3.0) is None
        assert m.battery.level == WARN and m.report()[0] == WARN
        t2 = t + 3.0
        for i in range(25):
            m.note_battery(t2 + i * 0.1, 3.25)
            m.note_setpoint(t2 + i * 0.1, HOVER)
        a = m.poll(t2 + 2.5)
    assert a == Action("thrust", thrust=DescentPlan(HOVER, 0.3, 2.0, 0).thrust_at(0))
    assert m.reaction == Reaction.DESCENT and "battery critical" in m.reason
    texts = [r.getMessage() for r in caplog.records]
    assert sum("warning level" in x for x in texts) == 1 and sum("critical level" in x for x in texts) == 1
    # no new take-off on a critical battery once down
    end = run(m, t2 + 2.6, t2 + 20.0)
    assert end[-1][1] == Action("off") and m.reaction == Reaction.DOWN
    assert not m.note_setpoint(t2 + 21.0, HOVER)
    assert m.note_setpoint(t2 + 21.0, 0)


def test_no_high_level_flight_after_a_battery_critical_landing():
    """The high-level path keeps the setpoint path's rule: a critical battery brings the Crazyflie down and
    no takeoff, go_to or start_trajectory sends it up again (land and stop stay taken)."""
    m = monitor(protocol=CURRENT_FW)
    m.note_high_level(0.0, "takeoff", 2.0)
    assert m.refusal(1.0, "go_to") is None
    for i in range(25):
        m.note_battery(3.0 + i * 0.1, 3.25)
    acts = run(m, 5.5, 25.0)
    assert acts[0][1].kind == "land" and "battery critical" in m.reason
    assert m.reaction == Reaction.DOWN and not m.flying
    for what in ("takeoff", "go_to", "start_trajectory"):
        why = m.refusal(26.0, what)
        assert why is not None and "battery critical (3.25 V)" in why, what
    assert m.refusal(26.0, "land") is None and m.refusal(26.0, "stop") is None


def test_a_critical_battery_without_the_battery_reaction_refuses_nothing():
    m = monitor(SafetyConfig(battery=False), protocol=CURRENT_FW)
    for i in range(25):
        m.note_battery(i * 0.1, 3.25)
    assert m.refusal(3.0, "takeoff") is None


# ---------------------------------------------------------------- setpoint silence

def test_silence_on_the_chapter_path_holds_then_descends_then_stops(caplog):
    m = monitor()
    t = hover_for(m, 0.0, 2.0, thrust=HOVER)
    assert run(m, t, t + 0.3) == []                             # within the silence limit
    with caplog.at_level(logging.INFO, logger="crazyflie_driver.server.safety"):
        acts = run(m, t + 0.31, t + 12.0)
    kinds = [a.kind for _, a in acts]
    assert kinds[-3:] == ["off"] * 3 and kinds.count("off") == 3     # zero thrust, said thrice: one may be lost
    thrusts = [(at, a.thrust) for at, a in acts if a.kind == "thrust"]
    assert thrusts[0][1] == HOVER                               # level hold at the hover thrust
    assert min(x for _, x in thrusts) < HOVER - 2000
    plan = DescentPlan(HOVER, 0.3, 2.0, 0.3)
    first_off = next(at for at, a in acts if a.kind == "off")
    assert first_off - thrusts[0][0] == pytest.approx(plan.duration, abs=0.02)
    said = [r.getMessage() for r in caplog.records]
    assert len([x for x in said if "no setpoint for" in x and "holding level" in x]) == 1
    assert len([x for x in said if "descent over" in x]) == 1
    assert m.report()[0] == WARN and "motors off" in m.report()[1]


def test_setpoints_back_during_the_hold_resume_but_not_during_the_descent():
    m = monitor()
    t = hover_for(m, 0.0, 2.0)
    run(m, t, t + 0.35)
    assert m.reaction == Reaction.HOLD and m.report()[0] == ERROR
    assert m.note_setpoint(t + 0.4, HOVER + 100)
    assert m.reaction == Reaction.NONE and m.poll(t + 0.41) is None
    t = hover_for(m, t + 0.42, 1.0)
    run(m, t, t + 1.0)
    assert m.reaction == Reaction.DESCENT
    assert not m.note_setpoint(t + 1.01, HOVER) and m.ignored_setpoints == 1


def test_a_motors_off_setpoint_ends_a_reaction_and_goes_out():
    m = monitor()
    t = hover_for(m, 0.0, 1.0)
    run(m, t, t + 1.0)
    assert m.reaction == Reaction.DESCENT
    assert not m.note_setpoint(t + 1.0, HOVER)
    assert m.note_setpoint(t + 1.01, 0)
    assert m.reaction == Reaction.NONE and m.poll(t + 1.02) is None and m.finished(t + 1.02)
    assert "motors off by the user" in m.events[-1]


def test_no_reaction_on_the_ground_or_when_switched_off():
    m = monitor()
    hover_for(m, 0.0, 1.0, thrust=0)
    assert run(m, 1.0, 3.0) == []
    m = monitor(SafetyConfig(setpoint_silence=False))
    t = hover_for(m, 0.0, 1.0)
    assert run(m, t, t + 3.0) == []


def test_silence_with_onboard_control_lands_by_the_high_level_commander():
    m = monitor(protocol=CURRENT_FW, params={"stabilizer.estimator": 2})
    t = 0.0
    while t < 2.0:
        m.note_pose(t, 0.8)
        m.note_setpoint(t, HOVER)
        t += 0.02
    m.note_pose(t + 0.3, 0.8)
    acts = run(m, t, t + 0.5)
    assert acts[0][1] == Action("land", duration=pytest.approx(0.8 / 0.3), distance=0.8)
    plan_end = acts[0][0] + 0.8 / 0.3
    # the poses say it still flies after the plan's end (its clock or its position loop runs behind):
    # the motors stay on until it rests on the floor
    for k in range(100):
        m.note_pose(t + 0.5 + k * 0.03, max(0.8 - k * 0.01, 0.05))
    assert run(m, t + 0.51, plan_end + 0.4) == [] and not m.finished(plan_end + 0.4)
    m.note_pose(plan_end + 0.5, 0.01)
    acts = run(m, plan_end + 0.5, plan_end + 1.0)
    assert [a.kind for _, a in acts] == ["hl_stop", "off", "off", "off"]
    assert acts[0][0] == pytest.approx(plan_end + 0.5, abs=0.015)
    assert m.finished(plan_end + 1.0) and m.reaction == Reaction.DOWN


def test_an_onboard_landing_without_poses_stops_after_its_settling_time():
    m = monitor(protocol=CURRENT_FW)
    m.note_high_level(0.0, "takeoff")
    assert m.begin_shutdown(1.0, 10.0)
    acts = run(m, 1.0, 12.0)
    assert acts[0][1] == Action("land", duration=pytest.approx(2.0 / 0.3), distance=2.0)
    assert acts[1] == (pytest.approx(1.0 + 2.0 / 0.3 + 2.0, abs=0.015), Action("hl_stop"))


def test_streamed_port7_setpoints_land_onboard_and_a_released_stream_is_not_silence():
    m = monitor(protocol=CURRENT_FW)
    m.note_setpoint(0.0, None)
    assert run(m, 0.0, 1.0)[0][1].kind == "land"
    m = monitor(protocol=CURRENT_FW)
    m.note_setpoint(0.0, None)
    m.note_stream_released(0.1)
    m.note_high_level(0.2, "takeoff")
    assert run(m, 0.2, 3.0) == []
    assert m.flying


def test_a_removal_between_a_released_stream_and_its_high_level_command_still_lands():
    """notify-setpoints-stop hands a flying Crazyflie to the high-level commander: it is still in the
    air, so a removal that looks before the go_to that follows is noted lands it, not drops it."""
    m = monitor(protocol=CURRENT_FW)
    for k in range(50):
        m.note_setpoint(k * 0.02, None)            # flying on a position stream, with motion capture
        m.note_pose(k * 0.02, 0.5)
    m.note_stream_released(1.0)                    # a go_to's notify-setpoints-stop went out ...
    assert m.flying
    assert m.begin_shutdown(1.01, 10.0)            # ... and the removal looks before the go_to is noted
    assert run(m, 1.01, 2.0)[0][1].kind == "land"


def test_a_released_stream_on_the_ground_is_not_flight():
    m = monitor(protocol=CURRENT_FW)
    m.note_setpoint(0.0, None, stop=True)
    m.note_stream_released(0.1)
    assert not m.flying and not m.begin_shutdown(0.2, 10.0)


def test_finished_only_once_the_last_zero_thrust_went_out():
    m = monitor()
    t = hover_for(m, 0.0, 1.0)
    m.begin_shutdown(t, 1.0)
    acts = run(m, t, t + 0.5 - 0.015)
    assert acts[-1][1].kind == "thrust" and not m.finished(t + 0.5)
    offs = [m.poll(t + 0.5 + k * 0.01) for k in range(3)]
    assert offs == [Action("off")] * 3 and not m.finished(t + 0.53)
    assert m.poll(t + 0.54) is None and m.finished(t + 0.54)


def test_shutdown_lands_or_descends_only_what_flies_within_the_budget():
    assert not monitor().begin_shutdown(0.0) and monitor().finished(0.0)
    m = monitor()
    t = hover_for(m, 0.0, 1.0)
    assert m.begin_shutdown(t, 3.0)
    acts = run(m, t, t + 5.0)
    assert acts[0][1].kind == "thrust" and acts[0][1].thrust < HOVER - 2000    # no hold: descend at once
    assert acts[-1][1] == Action("off") and acts[-3][0] <= t + 2.5 + 0.02       # cut at the budget
    assert m.finished(t + 5.0)
    m = monitor(SafetyConfig(land_on_shutdown=False))
    hover_for(m, 0.0, 1.0)
    assert not m.begin_shutdown(1.0)


def test_after_shutdown_began_no_setpoint_goes_out_again():
    m = monitor()
    t = hover_for(m, 0.0, 1.0)
    assert m.begin_shutdown(t, 10.0)
    acts = run(m, t, t + 9.0)
    assert acts[-1][1] == Action("off") and m.finished(t + 9.0)
    # a controller still running, wound up by the descent: its full thrust must not take off again
    assert not m.note_setpoint(t + 9.1, 60000)
    assert m.poll(t + 9.2) is None and not m.flying and m.finished(t + 9.2)
    m = monitor()
    m.note_setpoint(0.0, 0)
    assert not m.begin_shutdown(0.1) and not m.note_setpoint(0.2, HOVER)    # on the ground: no take-off either


def test_after_a_descent_a_new_flight_starts_from_zero_thrust():
    m = monitor()
    t = hover_for(m, 0.0, 1.0)
    run(m, t, t + 10.0)
    assert m.reaction == Reaction.DOWN
    assert not m.note_setpoint(t + 10.1, 60000)     # a wound-up controller's thrust
    assert m.note_setpoint(t + 10.2, 0)             # the thrust lock's zero
    assert m.note_setpoint(t + 10.3, HOVER) and m.flying


def test_a_landing_under_way_is_not_sent_twice():
    m = monitor(protocol=CURRENT_FW)
    m.note_high_level(0.0, "takeoff")
    m.note_high_level(3.0, "land", 2.0)          # the user's (or the swarm's stale-pose) landing
    assert m.begin_shutdown(3.5, 10.0)           # still in the air: the reaction waits for that landing
    assert run(m, 3.5, 6.0) == [] and m.reaction == Reaction.DOWN and m.finished(6.0)
    m = monitor(protocol=CURRENT_FW)
    m.note_high_level(0.0, "takeoff")
    assert m.begin_shutdown(1.0, 10.0)
    assert [a.kind for _, a in run(m, 1.0, 11.0)][:2] == ["land", "hl_stop"]


def test_setpoint_thrust_of_worker_setpoints():
    assert setpoint_thrust(Setpoint(0, 0, 0, 30000)) == (30000, False)
    assert setpoint_thrust(setpoints.position_packet(0, 0, 1, 0)) == (None, False)
    assert setpoint_thrust(CRTPPacket(7, 0, bytes([setpoints.TYPE_STOP]))) == (None, True)


# ---------------------------------------------------------------- the worker carries it out

class SafetyLink:
    """The link's send/stats for the worker's safety packets."""

    def __init__(self, cf):
        self.cf, self.stats, self.sent = cf, cf.link.stats, []

    def send(self, packet):
        return self.cf._packet("raw", packet.port, packet.channel, bytes(packet.data))


def test_worker_descends_after_cmd_vel_stops_and_the_status_says_why():
    cf = FakeCrazyflie()
    cf.link = SafetyLink(cf)
    cf.protocol_version = 2
    rec = Recorder()
    events = []
    rec.on_safety = events.append
    w, cf, _ = started(cf=cf, listener=rec, safety=SafetyConfig(descent_max_height=0.3))
    try:
        for _ in range(30):
            w.cmd_vel(0.0, 0.0, float(HOVER), 0.0)
            time.sleep(0.02)
        t0 = time.monotonic()
        assert wait_for(lambda: w.safety.reaction == Reaction.DOWN, 5.0)
        sent = [p for p in cf.of_kind("setpoint") if p[0] > t0]
        thrusts = [p[2][3] for p in sent]
        assert thrusts[0] == HOVER and min(thrusts[:-1]) < HOVER - 2000 and thrusts[-1] == 0
        assert sent[0][0] - t0 < 0.35
        assert any("no setpoint for" in e for e in events)
        status = worker_status(w)
        assert status.level == WARN and "motors off" in status.message
        assert dict(status.values)["safety_reaction"] == "down"
    finally:
        w.stop()


def test_worker_without_safety_config_does_what_it_is_told():
    w, cf, _ = started()
    try:
        w.cmd_vel(0.0, 0.0, float(HOVER), 0.0)
        time.sleep(0.5)
        assert [p[2][3] for p in cf.of_kind("setpoint")][-1] == HOVER
        assert w.safety.reaction == Reaction.NONE and worker_status(w).level == OK
    finally:
        w.stop()


def test_worker_sends_the_watchdog_keepalive_only_when_asked():
    for on in (True, False):
        cf = FakeCrazyflie()
        cf.link = SafetyLink(cf)
        cf.protocol_version = CURRENT_FW
        w, cf, _ = started(cf=cf, safety=SafetyConfig(emergency_watchdog=on))
        try:
            time.sleep(0.6)
            keepalives = [p for p in cf.of_kind("raw") if p[2][0] == 9 and p[2][2] == bytes([CMD_WATCHDOG])]
            assert (2 <= len(keepalives) <= 4) if on else not keepalives
        finally:
            w.stop()


class HighLevelDouble:
    def __init__(self, cf):
        self.cf = cf

    def command(self, packet, idempotent=True):
        self.cf._packet("hl", bytes(packet.data))


def test_worker_lands_onboard_on_shutdown():
    cf = FakeCrazyflie()
    cf.link = SafetyLink(cf)
    cf.high_level = HighLevelDouble(cf)
    cf.protocol_version = CURRENT_FW
    w, cf, _ = started(cf=cf, safety=SafetyConfig())
    try:
        w.set_packet_setpoint(setpoints.position_packet(0.0, 0.0, 0.5, 0.0))
        time.sleep(0.05)
        assert w.begin_safe_shutdown(3.0)
        assert wait_for(w.safe_to_close, 5.0)
        hl = [p[2][0] for p in cf.of_kind("hl")]
        assert [h[0] for h in hl] == [CMD_GO_TO_2, CMD_STOP]
        _, _, relative, _, x, y, z, yaw, duration = struct.unpack("<BBBB5f", hl[0])
        assert relative and (x, y, yaw) == (0.0, 0.0, 0.0) and z == pytest.approx(-2.0) and duration == 1.0
        assert [p[2][3] for p in cf.of_kind("setpoint")][-3:] == [0, 0, 0]      # then motors off, for sure
        notify = setpoints.notify_setpoints_stop_packet(0)
        raw = [p for p in cf.of_kind("raw") if p[2] == (notify.port, notify.channel, bytes(notify.data))]
        land_at = cf.of_kind("hl")[0][0]
        assert raw and raw[0][0] >= land_at      # planned first, then handed over: no idle planner in between
    finally:
        w.stop()
