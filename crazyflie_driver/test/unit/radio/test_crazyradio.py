"""Crazyradio over pyusb, checked request by request against the fake dongle."""
from __future__ import annotations

import errno
import sys
import types

import pytest
import usb.core

from crazyflie_driver import usb_choice as usb_backend
from crazyflie_driver.errors import CrazyflieError, RadioAccessDenied, RadioNotFound, RadioUnplugged
from crazyflie_driver.radio import crazyradio
from crazyflie_driver.radio.crazyradio import Crazyradio, RadioAck, inline_frame, list_radios, parse_inline_reply
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import parse_address
from support.radio_doubles import AirReply, FakeClock, ScriptedMedium


@pytest.fixture
def medium():
    return ScriptedMedium()


@pytest.fixture
def backend(medium):
    return FakeUsbBackend(medium, dongles=2, timing=DongleTiming.instant())


def requests(backend, i=0):
    """(bRequest, wValue, wIndex, data) of every vendor request the dongle saw."""
    return [(r[1], r[2], r[3], r[4]) for r in backend.dongles[i].vendor_requests]


def test_open_puts_the_dongle_in_a_known_state(backend):
    radio = Crazyradio(0, backend)
    assert requests(backend) == [
        (0x03, 2, 0, b""), (0x01, 2, 0, b""), (0x20, 0, 0, b""), (0x02, 0, 0, b"\xe7" * 5),
        (0x04, 3, 0, b""), (0x06, 3, 0, b""), (0x05, 0xA0, 0, b""), (0x10, 1, 0, b""),
    ]
    assert radio.version == 0.53
    assert radio.serial == backend.dongles[0].serial
    assert radio.control_transfers == 8
    assert (radio.channel, radio.datarate, radio.address) == (2, 2, b"\xe7" * 5)
    radio.close()


def test_version_of_a_crazyradio_2(medium):
    radio = Crazyradio(0, FakeUsbBackend(medium, model="2.0", timing=DongleTiming.instant()))
    assert radio.version == 5.4
    radio.close()


def test_setters_send_their_request_and_cache_channel_address_rate(backend):
    radio = Crazyradio(0, backend)
    backend.dongles[0].vendor_requests.clear()
    radio.set_channel(80)
    radio.set_channel(80)
    radio.set_address(b"\xe7\xe7\xe7\xe7\x01")
    radio.set_address(bytearray(b"\xe7\xe7\xe7\xe7\x01"))
    radio.set_data_rate(0)
    radio.set_data_rate(0)
    radio.configure(80, 0, b"\xe7\xe7\xe7\xe7\x01")      # nothing changed: no traffic
    radio.configure(81, 0, b"\xe7\xe7\xe7\xe7\x01")      # only the channel
    radio.set_power(1)
    radio.set_arc(10)
    radio.set_ard_time(500)
    radio.set_ard_bytes(32)
    radio.set_ack_enable(False)
    radio.set_cont_carrier(True)
    assert requests(backend) == [
        (0x01, 80, 0, b""), (0x02, 0, 0, b"\xe7\xe7\xe7\xe7\x01"), (0x03, 0, 0, b""), (0x01, 81, 0, b""),
        (0x04, 1, 0, b""), (0x06, 10, 0, b""), (0x05, 1, 0, b""), (0x05, 0xA0, 0, b""),
        (0x10, 0, 0, b""), (0x20, 1, 0, b""),
    ]
    d = backend.dongles[0]
    assert (d.channel, d.address, d.datarate, d.power, d.arc, d.ack_enabled, d.cont_carrier) == \
        (81, b"\xe7\xe7\xe7\xe7\x01", 0, 1, 10, False, True)


@pytest.mark.parametrize("call", [
    lambda r: r.set_channel(126), lambda r: r.set_address(b"\x01\x02"), lambda r: r.set_data_rate(3),
    lambda r: r.set_power(4), lambda r: r.set_arc(16), lambda r: r.set_ard_time(300),
    lambda r: r.set_ard_time(4250), lambda r: r.set_ard_bytes(33), lambda r: r.send_packet(b""),
    lambda r: r.send_packet(bytes(33)), lambda r: r.scan_channels(0, 126),
])
def test_bad_arguments_are_refused_before_any_traffic(backend, call):
    radio = Crazyradio(0, backend)
    before = len(backend.dongles[0].vendor_requests)
    with pytest.raises(ValueError):
        call(radio)
    assert len(backend.dongles[0].vendor_requests) == before


@pytest.fixture(params=["backend", "pyusb"])
def transfers(request, monkeypatch):
    """Bulk transfers straight through the pyusb backend on the open handle (what the radio picks), or
    through pyusb's public ``Device.write``/``read`` (its fallback): the same bytes either way."""
    if request.param == "pyusb":
        monkeypatch.setattr(crazyradio, "bulk_io", lambda dev: (crazyradio._DeviceBulk(dev), None))
    return request.param


def test_bulk_transfers_go_to_the_backend_on_the_devices_open_handle(backend):
    radio = Crazyradio(0, backend)
    bulk, handle = crazyradio.bulk_io(radio.device)
    assert bulk is backend
    assert handle is radio.device._ctx.handle and handle.dongle is backend.dongles[0]
    radio.close()


def test_bulk_transfers_fall_back_to_pyusbs_public_calls():
    class Device:
        def write(self, ep, data, timeout):
            self.wrote = (ep, bytes(data), timeout)
            return len(data)

        def read(self, ep, buff, timeout):
            buff[:2] = crazyradio.array.array("B", b"\x01\xf3")
            return 2

    dev = Device()
    bulk, handle = crazyradio.bulk_io(dev)
    assert bulk.bulk_write(handle, 0x01, 0, b"\x3c\x00", 1000) == 2 and dev.wrote == (0x01, b"\x3c\x00", 1000)
    buff = crazyradio.array.array("B", bytes(4))
    assert bulk.bulk_read(handle, 0x81, 0, buff, 1000) == 2 and buff[:2].tobytes() == b"\x01\xf3"


def test_send_packet_decodes_the_status_byte(backend, medium, transfers):
    radio = Crazyradio(0, backend)
    medium.push(AirReply(True, b"\x2c\x00\x07", retries=3, power_detector=True),
                AirReply(True, b"", retries=0, power_detector=False),
                AirReply(False))
    assert radio.send_packet(b"\x2c\x00") == RadioAck(True, True, 3, b"\x2c\x00\x07")
    assert radio.send_packet(b"\xff") == RadioAck(True, False, 0, b"")
    radio.set_arc(5)
    assert radio.send_packet(b"\xff") == RadioAck(False, False, 5, b"")
    assert [t.data for t in medium.transmits] == [b"\x2c\x00", b"\xff", b"\xff"]


def test_send_with_acks_disabled_does_not_wait_for_a_reply(medium, transfers):
    clock = FakeClock()
    backend = FakeUsbBackend(medium, timing=DongleTiming.instant(), clock=clock)
    radio = Crazyradio(0, backend)
    radio.set_ack_enable(False)
    ack = radio.send_packet(b"\x80\x01")
    assert ack.ack is False
    assert clock.now == 0.0                    # no read, so no timeout spent
    assert medium.transmits[-1].ack_enabled is False


def test_usb_timeout_counts_as_unacked(medium, transfers):
    clock = FakeClock()
    backend = FakeUsbBackend(medium, timing=DongleTiming.instant(), clock=clock)
    radio = Crazyradio(0, backend, usb_timeout_ms=50)
    medium.push(AirReply(True, b"", latency_s=1.0))
    assert radio.send_packet(b"\xff") == RadioAck(False, False, 3, b"")


def test_unplug_during_use(backend, medium, transfers):
    radio = Crazyradio(0, backend)
    backend.unplug(0)
    with pytest.raises(RadioUnplugged, match="Crazyradio 0 was unplugged"):
        radio.send_packet(b"\xff")
    with pytest.raises(RadioUnplugged):
        radio.set_channel(99)
    radio.close()
    with pytest.raises(RadioUnplugged, match="closed"):
        radio.send_packet(b"\xff")


def test_not_found_messages(medium):
    with pytest.raises(RadioNotFound, match="no Crazyradio found .*udev rules for group plugdev"):
        Crazyradio(0, FakeUsbBackend(medium, dongles=0))
    with pytest.raises(RadioNotFound, match="no Crazyradio with index 2: 2 Crazyradios are plugged in"):
        Crazyradio(2, FakeUsbBackend(medium, dongles=2))


def test_permission_denied_names_the_udev_rules(medium):
    class NoPermission(FakeUsbBackend):
        def open_device(self, dev):
            raise usb.core.USBError("Access denied (insufficient permissions)", -3, errno.EACCES)

    with pytest.raises(RadioAccessDenied, match="99-crazyradio.rules.*plugdev"):
        Crazyradio(0, NoPermission(medium, timing=DongleTiming.instant()))


def test_dongle_in_use_elsewhere(backend):
    radio = Crazyradio(0, backend)
    with pytest.raises(RadioAccessDenied, match="in use"):
        Crazyradio(0, backend)
    radio.close()
    Crazyradio(0, backend).close()           # free again after close


def test_old_firmware_refused(medium):
    backend = FakeUsbBackend(medium, timing=DongleTiming.instant())
    backend.dongles[0].model = type(backend.dongles[0].model)(**{**vars(backend.dongles[0].model),
                                                                 "bcd_device": 0x0030})
    with pytest.raises(CrazyflieError, match="firmware 0.30.*update"):
        Crazyradio(0, backend)


def test_two_dongles_are_independent(backend, medium):
    a, b = Crazyradio(0, backend), Crazyradio(1, backend)
    a.set_channel(10)
    b.set_channel(20)
    a.send_packet(b"\x01")
    b.send_packet(b"\x02")
    assert [(t.dongle, t.channel, t.data) for t in medium.transmits] == [(0, 10, b"\x01"), (1, 20, b"\x02")]
    assert a.serial != b.serial


def test_scan_channels(backend, medium):
    radio = Crazyradio(0, backend)
    medium.responder = lambda tx: AirReply(tx.channel == 80 and tx.data == b"\xff\xff\xff")
    assert radio.scan_channels(60, 100, b"\xff\xff\xff") == [80]
    # The firmware left the radio on its last channel: the next set_channel must really be sent.
    backend.dongles[0].vendor_requests.clear()
    radio.set_channel(2)
    assert requests(backend) == [(0x01, 2, 0, b"")]


def test_list_radios(backend):
    radios = list_radios(backend)
    assert [(r.index, r.serial, r.version) for r in radios] == [
        (0, backend.dongles[0].serial, 0.53), (1, backend.dongles[1].serial, 0.53)]


def test_backend_choice(monkeypatch, medium):
    monkeypatch.delenv("CRAZYFLIE_BACKEND", raising=False)
    assert usb_backend.get_backend() is None
    fake = FakeUsbBackend(medium, timing=DongleTiming.instant())
    with usb_backend.use_backend(fake):
        assert usb_backend.get_backend() is fake
        manager = usb_backend.radio_manager()
        assert usb_backend.radio_manager() is manager        # one per process
        shared = manager.acquire(0)                          # opened on the backend chosen now
        assert shared.radio.serial == fake.dongles[0].serial
        manager.release(shared)
    assert usb_backend.get_backend() is None
    monkeypatch.setenv("CRAZYFLIE_BACKEND", "bogus")
    with pytest.raises(CrazyflieError, match="CRAZYFLIE_BACKEND='bogus'"):
        usb_backend.get_backend()


def test_sim_backend_attaches_to_a_remote_medium(monkeypatch):
    created = []

    class RemoteMedium(ScriptedMedium):
        def __init__(self, host, port):
            super().__init__(dongles=2)
            created.append((host, port))

        def dongle_model(self):
            return "2.0"                                     # the world plugs Crazyradio 2.0s

    module = types.ModuleType("crazyflie_driver.sim.air.medium")
    module.RemoteMedium = RemoteMedium
    module.parse_address = parse_address                 # the world's own address rules (loopback only)
    monkeypatch.setitem(sys.modules, "crazyflie_driver.sim.air.medium", module)
    monkeypatch.setattr(usb_backend, "_sim_backends", {})
    monkeypatch.setenv("CRAZYFLIE_BACKEND", "sim")
    monkeypatch.setenv("CRAZYFLIE_SIM_ADDRESS", "127.0.0.1:19999")
    backend = usb_backend.get_backend()
    assert isinstance(backend, FakeUsbBackend)
    assert usb_backend.get_backend() is backend          # one per address and process
    assert created == [("127.0.0.1", 19999)]
    assert len(backend.dongles) == 2
    assert [d.model.name for d in backend.dongles] == ["2.0", "2.0"]
    monkeypatch.setenv("CRAZYFLIE_SIM_ADDRESS", "nonsense")
    with pytest.raises(CrazyflieError, match="host:port"):
        usb_backend.get_backend()
    monkeypatch.setenv("CRAZYFLIE_SIM_ADDRESS", "192.168.1.5:19840")
    with pytest.raises(CrazyflieError, match="only loopback"):
        usb_backend.get_backend()


class WireBackend(FakeUsbBackend):
    """The fake dongle, recording every bulk OUT as the bytes on the wire."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.outs = []

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        self.outs.append(bytes(data))
        return super().bulk_write(dev_handle, ep, intf, data, timeout)


def test_inline_frame_and_reply_bytes():
    assert inline_frame(80, 2, b"\xe7\xe7\xe7\xe7\x01", b"\x3c\x01") == b"\x0a\x12\x50\xe7\xe7\xe7\xe7\x01\x3c\x01"
    assert parse_inline_reply(b"\x04\x23\x3c\x01", 3) == RadioAck(True, True, 2, b"\x3c\x01")
    assert parse_inline_reply(b"\x02\x30", 3) == RadioAck(False, False, 3, b"")
    assert parse_inline_reply(b"\x02\x04", 3) == RadioAck(False, False, 3, b"")   # invalid settings
    assert parse_inline_reply(b"", 3) == RadioAck(False, False, 3, b"")


@pytest.mark.parametrize("model, capable", [("PA", False), ("PA-99.55", False), ("2.0-5.0", False), ("2.0", True)])
def test_inline_mode_is_chosen_by_firmware_version(medium, model, capable):
    radio = Crazyradio(0, FakeUsbBackend(medium, model=model, timing=DongleTiming.instant()))
    assert radio.inline_capable is capable
    if not capable:
        with pytest.raises(CrazyflieError, match="no inline mode"):
            radio.set_inline_mode(True)
    radio.close()


def test_inline_packets_to_two_crazyflies_need_no_vendor_request_between_them(medium, transfers):
    backend = WireBackend(medium, model="2.0", timing=DongleTiming.instant())
    radio = Crazyradio(0, backend)
    a, b = b"\xe7\xe7\xe7\xe7\x01", b"\xe7\xe7\xe7\xe7\x02"
    backend.dongles[0].vendor_requests.clear()
    medium.push(AirReply(True, b"\x01"), AirReply(True, b""), AirReply(True, b"\x02"), AirReply(False))
    acks = [radio.send_inline(80, 2, a, b"\xff"), radio.send_inline(20, 1, b, b"\xff"),
            radio.send_inline(80, 2, a, b"\xff"), radio.send_inline(20, 1, b, b"\xfe")]
    assert requests(backend) == [(0x23, 1, 0, b"")]                 # inline mode on once, then none
    assert backend.outs == [b"\x09\x12\x50" + a + b"\xff", b"\x09\x11\x14" + b + b"\xff",
                            b"\x09\x12\x50" + a + b"\xff", b"\x09\x11\x14" + b + b"\xfe"]
    assert [(k.ack, k.data) for k in acks] == [(True, b"\x01"), (True, b""), (True, b"\x02"), (False, b"")]
    assert (radio.channel, radio.datarate, radio.address) == (20, 1, b)
    radio.close()


def test_a_legacy_setting_request_leaves_inline_mode_and_the_next_packet_reenters(medium):
    backend = WireBackend(medium, model="2.0", timing=DongleTiming.instant())
    radio = Crazyradio(0, backend)
    a = b"\xe7\xe7\xe7\xe7\x01"
    radio.send_inline(80, 2, a, b"\xff")
    radio.send_no_ack(b"\xff\x01")                                   # a broadcast: ACK_ENABLE 0 leaves inline mode
    assert backend.dongles[0].inline_mode == 0
    backend.dongles[0].vendor_requests.clear()
    assert radio.send_inline(80, 2, a, b"\xff").ack
    assert requests(backend) == [(0x23, 1, 0, b"")]
    assert backend.outs[-1] == b"\x09\x12\x50" + a + b"\xff"
    radio.close()
