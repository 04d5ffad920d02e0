"""usb://N: a Crazyflie on a USB cable, through pyusb and the fake backend, up to the server's registry."""
from __future__ import annotations

import pytest
import usb.core

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.crtp.uri import UsbUri
from crazyflie_driver.errors import RadioNotFound
from crazyflie_driver.radio.crazyradio import list_radios
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.radio.usb_crazyflie import UsbCrazyflie, UsbLink, list_usb_crazyflies
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.radio_doubles import FakeClock, ScriptedMedium


class CableMedium(ScriptedMedium):
    """A medium whose Crazyflie on the cable echoes every packet back (port 15 style) and records them."""

    def __init__(self):
        super().__init__()
        self.up = []
        self.down = []

    def usb_count(self):
        return 1

    def usb_send(self, index, data):
        self.up.append((index, bytes(data)))
        self.down.append(bytes(data))
        return True

    def usb_receive(self, index):
        return self.down.pop(0) if self.down else None


def backend_for(medium, cables=1):
    return FakeUsbBackend(medium, dongles=1, timing=DongleTiming.instant(), clock=FakeClock(), usb_crazyflies=cables)


def test_the_crazyflie_on_the_cable_has_its_usb_identity_beside_the_dongle():
    backend = backend_for(CableMedium())
    dev = usb.core.find(idVendor=0x0483, idProduct=0x5740, backend=backend)
    assert (dev.bcdDevice, dev.manufacturer, dev.product) == (0x0200, "Bitcraze AB", "Crazyflie 2.x")
    assert len(dev.serial_number) == 24
    assert [r.index for r in list_radios(backend)] == [0]               # a Crazyflie is no Crazyradio
    assert [c.uri for c in list_usb_crazyflies(backend)] == ["usb://0"]
    assert list_usb_crazyflies(backend_for(CableMedium(), cables=0)) == []


def test_crtp_over_usb_bytes_on_the_wire():
    medium = CableMedium()
    backend = backend_for(medium)
    cf = UsbCrazyflie(0, backend)
    cable = backend.cables[0]
    assert cable.crtp_to_usb                                          # vendor request 0x01, wValue 1, wIndex 1
    cf.write(b"\xf0\x01\x02")                                         # port 15 ch 0, payload 01 02
    assert medium.up == [(0, b"\xf0\x01\x02")]
    assert cf.read() == b"\xf0\x01\x02"
    assert cf.read() == b""                                           # nothing more: a read timeout
    cf.close()
    assert not cable.crtp_to_usb
    assert medium.transmits == []                                     # nothing went through the radio


def test_usb_link_writes_no_null_packets_and_dispatches_what_comes_up():
    medium = CableMedium()
    backend = backend_for(medium)
    link = UsbLink(UsbUri(0), lambda i: UsbCrazyflie(i, backend))
    link.open()
    got = []
    link.subscribe(15, 0, got.append)
    assert link.send(CRTPPacket(15, 0, b"\x07"))
    assert got == [CRTPPacket(15, 0, b"\x07")]
    assert link.poll()
    assert medium.up == [(0, b"\xfc\x07")]                            # the poll only read
    assert not link.needs_resending and not link.safelink
    link.close()
    assert not link.is_open


def test_no_crazyflie_on_the_cable_is_a_clear_error():
    with pytest.raises(RadioNotFound, match="no Crazyflie usb://1: 1 Crazyflie on a USB cable"):
        UsbCrazyflie(1, backend_for(CableMedium()))


def test_the_server_registry_serves_a_simulated_crazyflie_on_the_cable(tmp_path):
    from crazyflie_driver.protocol.crazyflie import Crazyflie
    from crazyflie_driver.server.registry import CrazyflieRegistry
    from crazyflie_driver.server.worker import WorkerConfig, WorkerState
    from support.radio_rig import RadioRig

    rig = RadioRig()
    assert rig.medium.plug_usb(rig.firmware) == 0
    backend = FakeUsbBackend(rig.medium, dongles=1, timing=DongleTiming.instant(), usb_crazyflies=1)
    manager = RadioManager(backend=backend)
    reg = CrazyflieRegistry(lambda uri: Crazyflie(uri, radio_manager=manager, cache_dir=str(tmp_path), timeout=1.0))
    try:
        worker = reg.add(WorkerConfig(uri="usb://0", tf_prefix="cf1", enable_logging=False), timeout=10.0)
        assert worker.state == WorkerState.RUNNING
        assert worker.param_values["ring.effect"] == rig.firmware.params.value("ring.effect")
        assert [w.uri for w in reg.workers()] == ["usb://0"]
        assert backend.cables[0].bulk_out > 10 and rig.medium.round_trips == 0      # all of it over the cable
    finally:
        reg.shutdown()


def test_cflib_finds_and_connects_the_simulated_crazyflie_on_the_cable():
    import json
    import pathlib
    import subprocess

    from support.cflib_python import cflib_python

    session = pathlib.Path(__file__).resolve().parents[2] / "support" / "cflib_usb_session.py"
    run = subprocess.run([cflib_python(), str(session)], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    seen = json.loads(run.stdout.strip().splitlines()[-1])
    assert seen["found"] == ["usb://0"]
    assert seen["ring.effect"] == "6"                       # cflib reads the parameter TOC and value over USB
    assert seen["radio_round_trips"] == 0 and seen["cable_out"] > 10
