"""Arming, recovery, reboot and power of one Crazyflie: the server's decisions, then a worker against the
simulated firmware over the fake radio (the nRF's system commands on the wire, the firmware's own state)."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import CommandRejected
from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server import power_control as P
from crazyflie_driver.server.setpoint import Setpoint
from crazyflie_driver.server.status import worker_status
from crazyflie_driver.server.worker import CrazyflieWorker, WorkerConfig, WorkerState
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.sim_doubles import FakeVehicle
from support.worker_doubles import Recorder, wait_for

URI = "radio://0/80/2M/E7E7E7E701"
PARAM = "ring.headlightEnable"


def test_arming_after_an_emergency_names_the_reboot_service():
    text = P.arm_refusal(True, emergency=True, offline="")
    assert "reboot service" in text
    assert P.arm_refusal(False, emergency=True, offline="") is None       # disarming always goes
    assert P.arm_refusal(True, emergency=False, offline="") is None
    assert "link is lost" in P.arm_refusal(True, emergency=False, offline="its link is lost")
    assert "reboot service" in P.recover_refusal(emergency=True, offline="")


def test_no_reboot_or_power_off_while_it_flies_unless_stopped():
    assert "land it first" in P.power_change_refusal("reboot", 0.1, False, emergency=False)
    assert "supervisor reports it flying" in P.power_change_refusal("power-off", None, True, emergency=False)
    assert P.power_change_refusal("reboot", 0.1, True, emergency=True) is None
    assert P.power_change_refusal("reboot", None, False, emergency=False) is None


class Rig:
    def __init__(self, tmp_path, auto_arm: bool = True) -> None:
        self.medium = LocalMedium(dongles=1, seed=3)
        manager = RadioManager(FakeUsbBackend(self.medium, dongles=1, timing=DongleTiming.instant()))
        u = parse_uri(URI)
        self.fw = SimulatedCrazyflie(u.address, FakeVehicle("cf1"), auto_arm=auto_arm)
        self.medium.add_crazyflie(self.fw, u.channel, u.datarate)
        self.listener = Recorder()
        cf = Crazyflie(URI, radio_manager=manager, cache_dir=str(tmp_path), timeout=1.0)
        self.worker = CrazyflieWorker(WorkerConfig(URI, "cf1"), cf, self.listener)
        self.worker.start()
        self.worker.wait_ready(10.0)

    def logging(self) -> bool:
        blocks = self.fw.logs.blocks.values()
        return bool(blocks) and all(b.running for b in blocks)


@pytest.fixture
def rig(tmp_path):
    r = Rig(tmp_path)
    yield r
    r.worker.stop()


def test_reboot_drops_the_link_and_the_worker_sets_everything_up_again(rig):
    w, fw = rig.worker, rig.fw
    assert w.update_params({PARAM: 1}) == ([PARAM], [])
    assert fw.params.value(PARAM) == 1 and rig.logging()
    blocks = sorted(fw.snapshot()["log_blocks"].values(), key=str)
    w.reboot()
    assert fw.state.reboots == 1
    assert wait_for(lambda: w.state == WorkerState.RUNNING and rig.logging(), 5.0)
    assert fw.params.value(PARAM) == 1                      # the user's value, set again on the firmware
    assert sorted(fw.snapshot()["log_blocks"].values(), key=str) == blocks      # the same blocks, running


def test_power_off_keeps_it_off_until_power_on(rig):
    w, fw = rig.worker, rig.fw
    w.update_params({PARAM: 1})
    w.power_off()
    assert not fw.powered and fw.radio_on and w.state == WorkerState.POWERED_OFF
    assert "power_on" in worker_status(w).message
    acks = w.keepalives_sent
    assert wait_for(lambda: w.keepalives_sent > acks + 2, 5.0)      # polled slowly, acked by the nRF ...
    assert w.state == WorkerState.POWERED_OFF                       # ... and not taken for the Crazyflie
    with pytest.raises(CommandRejected, match="switched off"):
        w.arm(True)
    w.power_on()
    assert fw.powered
    assert wait_for(lambda: w.state == WorkerState.RUNNING and rig.logging(), 5.0)
    assert fw.params.value(PARAM) == 1


def test_after_an_emergency_the_reboot_service_brings_it_back(rig):
    w, fw = rig.worker, rig.fw
    w.emergency()
    assert fw.state.emergency
    assert "reboot service" in worker_status(w).message
    with pytest.raises(CommandRejected, match="reboot service"):
        w.arm(True)
    w.power_on()                                            # it was not switched off: the emergency stays
    assert w.emergency_active and fw.state.emergency
    w.reboot()
    assert not w.emergency_active and not fw.state.emergency
    assert wait_for(lambda: w.state == WorkerState.RUNNING, 5.0)
    assert w.set_setpoint(Setpoint(0.0, 0.0, 0.0, 0))


def test_no_reboot_while_the_server_streams_thrust(rig):
    w, fw = rig.worker, rig.fw
    w.set_setpoint(Setpoint(0.0, 0.0, 0.0, 0))
    w.set_setpoint(Setpoint(0.0, 0.0, 0.0, 30000))
    assert wait_for(lambda: fw.state.last_setpoint is not None and fw.state.last_setpoint[3] == 30000, 2.0)
    with pytest.raises(CommandRejected, match="land it first"):
        w.reboot()
    with pytest.raises(CommandRejected, match="land it first"):
        w.power_off()
    assert fw.state.reboots == 0 and fw.powered


def test_arming_a_crazyflie_that_does_not_arm_itself(tmp_path):
    r = Rig(tmp_path, auto_arm=False)
    try:
        assert not r.fw.state.armed
        r.worker.arm(True)
        assert r.fw.state.armed
        r.worker.arm(False)
        assert not r.fw.state.armed
        r.worker.recover()                          # not crashed: the supervisor says so, nothing to refuse
    finally:
        r.worker.stop()
