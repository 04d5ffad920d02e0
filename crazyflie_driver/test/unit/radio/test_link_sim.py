"""RadioLink through the whole radio path of the simulator: Crazyradio -> fake dongle ->
LocalMedium -> simulated Crazyflie firmware (nRF link layer, port 15), both firmware generations."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp.nrf_system import reboot_packets
from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import CommandValueError, LinkTimeout
from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.radio.link import open_link
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.sim_doubles import FakeVehicle

URI = "radio://0/80/2M/E7E7E7E701"


def make_air(firmware="current", seed=7):
    medium = LocalMedium(dongles=1, seed=seed)
    backend = FakeUsbBackend(medium, dongles=1, timing=DongleTiming.instant())
    u = parse_uri(URI)
    fw = SimulatedCrazyflie(u.address, FakeVehicle(), firmware=firmware)
    medium.add_crazyflie(fw, u.channel, u.datarate)
    return medium, backend, RadioManager(backend), fw


def is_echo(payload):
    return lambda p: p.port == 15 and p.channel == 0 and p.data == payload


@pytest.mark.parametrize("firmware", ["current", "2016.02"])
def test_safelink_and_link_source(firmware):
    medium, backend, manager, fw = make_air(firmware)
    link = open_link(URI, manager)
    try:
        assert link.safelink
        reply = link.request(CRTPPacket(15, 1, b"\x00"), lambda p: p.port == 15 and p.channel == 1,
                             what="link source")
        assert reply.data[:18] == b"Bitcraze Crazyflie"
        for i in range(5):
            payload = bytes([i]) * 4
            assert link.request(CRTPPacket(15, 0, payload), is_echo(payload), what="echo").data == payload
    finally:
        link.close()


def test_rssi_from_2016_empty_acks_only():
    for firmware, expect_rssi in (("2016.02", True), ("current", False)):
        medium, backend, manager, fw = make_air(firmware)
        link = open_link(URI, manager)
        for _ in range(100):                       # drain the boot console text first
            link.poll()
            if fw.pending_outgoing() == 0:
                break
        link.poll()
        link.poll()
        assert (link.stats.rssi is not None) == expect_rssi, firmware
        if expect_rssi:
            assert 30 <= link.stats.rssi <= 50     # default model: about -40 dBm
        link.close()


def test_every_echo_exactly_once_through_ack_loss():
    medium, backend, manager, fw = make_air(seed=3)
    link = open_link(URI, manager)
    got = []
    link.subscribe(15, 0, got.append)
    # Fault injection the way a Crazyradio 2.0 takes it: request 0x30 [packet loss %, ack loss %].
    shared = manager.acquire(0)
    shared.radio.device.ctrl_transfer(0x40, 0x30, 0, 0, b"\x0a\x1e")
    manager.release(shared)
    assert medium.dongle_faults(0).ack_loss == 30.0
    sent = [bytes([i, i ^ 0x5A]) for i in range(60)]
    for payload in sent:
        assert link.send(CRTPPacket(15, 0, payload))
    for _ in range(200):
        link.poll()
        if len(got) >= len(sent):
            break
    assert [p.data for p in got] == sent           # in order, none lost, none twice
    assert 0.4 < link.stats.ack_ratio < 0.8         # about (1 - 0.1) * (1 - 0.3) = 0.63
    link.close()


def test_reboot_over_the_air_and_safelink_again_after_it():
    """The nRF takes the reset itself (RESET_INIT, RESET to firmware); safelink is negotiated again."""
    medium, backend, manager, fw = make_air()
    link = open_link(URI, manager)
    try:
        assert link.safelink
        for packet in reboot_packets():
            assert link.send_nrf_command(packet)
        assert fw.state.reboots == 1 and not fw.link.safelink
        payload = b"\x01\x02"
        assert link.request(CRTPPacket(15, 0, payload), is_echo(payload), what="echo").data == payload
        assert fw.link.safelink
    finally:
        link.close()


def test_stm_power_off_and_on_over_the_air():
    medium, backend, manager, fw = make_air()
    cf = Crazyflie(URI, manager)
    cf.connect()
    try:
        cf.power_off_stm()
        assert not fw.powered and fw.radio_on
        assert cf.send_keepalive()                      # the nRF still acks
        with pytest.raises(LinkTimeout):
            cf.platform.detect_protocol_version()       # the STM answers nothing
        cf.power_on_stm()
        assert fw.powered and cf.platform.detect_protocol_version() == fw.profile.protocol_version
        cf.reboot()
        assert fw.state.reboots == 2
        cf.power_off_all()
        assert not fw.radio_on
        with pytest.raises(LinkTimeout):
            cf.power_on_stm()                           # nothing on the air wakes it
    finally:
        cf.close()


def test_nrf_commands_only_take_nrf_packets():
    medium, backend, manager, fw = make_air()
    link = open_link(URI, manager)
    try:
        with pytest.raises(CommandValueError):
            link.send_nrf_command(b"\x3c\x00\x00")
    finally:
        link.close()
