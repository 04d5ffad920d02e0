"""The firmware's setpoint watchdog as the server sees it: said once per cut, with the advice the
firmware's lock calls for, and again only after the Crazyflie could fly again."""
from __future__ import annotations

import logging

from crazyflie_driver.clock import ManualClock
from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.protocol import setpoints
from crazyflie_driver.protocol.commander import stop_packet
from crazyflie_driver.protocol.supervisor import decode_state
from crazyflie_driver.server.setpoint import Setpoint
from crazyflie_driver.server.status import ERROR, WARN, worker_status
from crazyflie_driver.server.watchdog_notice import WatchdogNotice, asks_for_thrust, cut_message
from crazyflie_driver.server.worker import WorkerState
from support.worker_doubles import FakeCrazyflie, started, wait_for

UP = Setpoint(0.0, 0.0, 0.0, 40000)
ZERO = Setpoint(0.0, 0.0, 0.0, 0)


def step(clock: ManualClock, seconds: float = 0.001) -> None:
    """Move the worker's clock on a little (None: a wait_for condition goes on to its own test)."""
    clock.advance(seconds)


def test_which_setpoints_ask_for_thrust():
    assert asks_for_thrust(UP) and not asks_for_thrust(ZERO)
    assert not asks_for_thrust(Setpoint(0.0, 0.0, 0.0, 999))          # the commander takes it as 0
    assert asks_for_thrust(setpoints.position_packet(0.0, 0.0, 1.0, 0.0))
    assert not asks_for_thrust(stop_packet(12))
    assert not asks_for_thrust(CRTPPacket(7, 1, b"\x00\x00\x00\x00\x00"))   # meta: notify-setpoints-stop


def test_messages_name_the_lock_and_the_fix():
    locked = cut_message(2.1, True, 12, False)
    assert "supervisor locked it" in locked and "restart it" in locked and "thrust 0" not in locked
    relock = cut_message(2.0, None, 2, False)
    assert "thrust lock" in relock and "setpoint with thrust 0" in relock
    unknown = cut_message(2.0, None, 12, True)
    assert "radio link is down" in unknown and "restart it" in unknown


def test_said_once_per_cut_and_again_only_after_flying_again():
    n = WatchdogNotice(lambda: 2)           # firmware 2016.02: thrust lock, released by thrust 0
    n.sent(UP, 0.0)
    assert n.flying_for(1.0) == 1.0 and n.due(1.9) is None
    assert n.due(2.0) == 2.0
    n.said("cut", None)
    assert n.due(10.0) is None and n.message == "cut" and not n.locked_until_restart
    n.sent(UP, 11.0)                         # still thrust-locked: not flying, nothing new to say
    assert n.due(20.0) is None and n.message == "cut"
    n.sent(ZERO, 21.0)
    n.sent(UP, 21.1)                         # released, flies again
    assert n.message == "" and n.due(23.2) is not None


def test_supervisor_lock_holds_until_a_restart():
    n = WatchdogNotice(lambda: 12)
    n.sent(UP, 0.0)
    n.said("locked", None)
    assert n.locked_until_restart
    n.sent(ZERO, 3.0)
    n.sent(UP, 3.1)
    assert n.due(10.0) is None and n.message == "locked"
    n.restarted(True)
    assert n.message == "locked"
    n.restarted(False)                       # restarted meanwhile: thrust lock, then flies again
    n.sent(ZERO, 11.0)
    n.sent(UP, 11.1)
    assert n.message == "" and n.due(13.2) is not None


def test_high_level_takeover_is_no_cut():
    n = WatchdogNotice(lambda: 12)
    n.sent(setpoints.position_packet(0.0, 0.0, 1.0, 0.0), 0.0)
    n.handed_over()
    assert n.due(5.0) is None and n.flying_for(1.0) is None


class Supervisor:
    def __init__(self, bits: int) -> None:
        self.bits = bits
        self.asked = 0

    def state(self):
        self.asked += 1
        return decode_state(self.bits)


def worker_with(protocol_version: int, supervisor=None):
    cf = FakeCrazyflie()
    cf.protocol_version = protocol_version
    if supervisor is not None:
        cf.supervisor = supervisor
    clock = ManualClock(100.0, sleep_advances=False)
    w, cf, rec = started(cf=cf, clock=clock, lost_retry_period=0.01)
    return w, cf, rec, clock


def watchdog_lines(caplog):
    return [r for r in caplog.records if "watchdog stopped the motors" in r.getMessage()]


def test_worker_says_it_once_with_the_thrust_lock_advice(caplog):
    caplog.set_level(logging.WARNING, logger="crazyflie_driver.server")
    w, cf, rec, clock = worker_with(2)
    try:
        w.set_setpoint(UP)
        assert wait_for(lambda: any(p[1] == "setpoint" and p[2][3] == 40000 for p in cf.packets))
        clock.advance(1.5)
        assert not wait_for(lambda: watchdog_lines(caplog), 0.1)
        clock.advance(0.6)
        assert wait_for(lambda: watchdog_lines(caplog))
        clock.advance(5.0)
        assert not wait_for(lambda: len(watchdog_lines(caplog)) > 1, 0.2)
        line = watchdog_lines(caplog)[0]
        assert line.levelno == logging.WARNING and cf.uri in line.getMessage()
        assert "setpoint with thrust 0" in line.getMessage()
        status = worker_status(w)
        assert status.level == WARN and "thrust lock" in status.message
        zeros = len([p for p in cf.of_kind("setpoint") if p[2][3] == 0])
        w.set_setpoint(ZERO)                 # the latest setpoint wins: let this one go out first
        assert wait_for(lambda: len([p for p in cf.of_kind("setpoint") if p[2][3] == 0]) > zeros)
        w.set_setpoint(UP)
        assert wait_for(lambda: w.watchdog.message == "")
        assert worker_status(w).message == "running"
        clock.advance(2.1)
        assert wait_for(lambda: len(watchdog_lines(caplog)) == 2)
    finally:
        w.stop()


def test_worker_asks_the_supervisor_and_waits_while_it_still_flies(caplog):
    caplog.set_level(logging.WARNING, logger="crazyflie_driver.server")
    sup = Supervisor(1 << 4)                 # flying: its clock is behind ours
    w, cf, rec, clock = worker_with(12, sup)
    try:
        w.set_setpoint(UP)
        assert wait_for(lambda: any(p[1] == "setpoint" and p[2][3] == 40000 for p in cf.packets))
        clock.advance(2.05)
        assert wait_for(lambda: sup.asked >= 1)
        assert not watchdog_lines(caplog)
        sup.bits = 1 << 6                    # locked
        clock.advance(0.2)
        assert wait_for(lambda: watchdog_lines(caplog))
        assert "supervisor locked it" in watchdog_lines(caplog)[0].getMessage()
        status = worker_status(w)
        assert status.level == ERROR and "restart it" in status.message
    finally:
        w.stop()


def test_radio_lost_while_flying_says_what_the_firmware_does(caplog):
    caplog.set_level(logging.WARNING, logger="crazyflie_driver.server")
    w, cf, rec, clock = worker_with(12, Supervisor(1 << 6))
    try:
        w.set_setpoint(UP)
        assert wait_for(lambda: any(p[1] == "setpoint" and p[2][3] == 40000 for p in cf.packets))
        cf.unplugged = True
        assert wait_for(lambda: step(clock) or rec.lost)     # the worker's clock moves on
        assert "plug it back in" in rec.lost[0] and "it was flying" in rec.lost[0]
        for _ in range(7):                   # the pilot keeps asking for thrust: none of it goes out
            w.set_setpoint(UP)
            assert wait_for(lambda: step(clock) or w._pending is None)
            clock.advance(0.3)
        assert wait_for(lambda: watchdog_lines(caplog))
        assert "radio link is down" in watchdog_lines(caplog)[0].getMessage()
        clock.advance(0.9)
        cf.unplugged = False
        assert wait_for(lambda: step(clock) or (rec.restored == 1 and w.state == WorkerState.RUNNING))
        restored = [r.getMessage() for r in caplog.records if "link restored" in r.getMessage()]
        assert len(restored) == 1 and restored[0].startswith("%s: link restored after 3." % cf.uri)
        assert len(watchdog_lines(caplog)) == 1 and w.watchdog.locked_until_restart
    finally:
        w.stop()
