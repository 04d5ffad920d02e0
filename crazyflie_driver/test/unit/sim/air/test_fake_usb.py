"""The fake Crazyradio, exercised through plain pyusb the way cflib and our driver use a dongle."""
from __future__ import annotations

import errno

import pytest
import usb.core
import usb.util

from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
from crazyflie_driver.radio.crazyradio import Crazyradio
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.cflib_find_patch import install_find_patch
from support.radio_doubles import AirReply, FakeClock, ScriptedMedium

VENDOR_OUT = 0x40


@pytest.fixture
def medium():
    return ScriptedMedium()


@pytest.fixture
def backend(medium):
    return FakeUsbBackend(medium, dongles=1, timing=DongleTiming.instant())


def find_all(backend):
    return list(usb.core.find(idVendor=0x1915, idProduct=0x7777, find_all=True, backend=backend))


def open_dev(backend, i=0):
    dev = find_all(backend)[i]
    dev.set_configuration(1)
    return dev


def test_find_sees_every_dongle_with_full_descriptors(medium):
    backend = FakeUsbBackend(medium, dongles=3, timing=DongleTiming.instant())
    devs = find_all(backend)
    assert len(devs) == 3
    d = devs[0]
    assert (d.bLength, d.bDescriptorType, d.bcdUSB, d.bDeviceClass, d.bMaxPacketSize0) == (18, 1, 0x0200, 0, 64)
    assert (d.idVendor, d.idProduct, d.bcdDevice) == (0x1915, 0x7777, 0x0053)
    assert (d.iManufacturer, d.iProduct, d.iSerialNumber, d.bNumConfigurations) == (1, 2, 0x1D, 1)
    assert d.speed == 2 and d.bus == 1
    assert len({dev.address for dev in devs}) == 3
    # Walking configurations/interfaces/endpoints needs IndexError for alt >= 1.
    cfgs = list(d)
    assert len(cfgs) == 1
    cfg = cfgs[0]
    assert (cfg.wTotalLength, cfg.bNumInterfaces, cfg.bConfigurationValue, cfg.bmAttributes, cfg.bMaxPower) \
        == (32, 1, 1, 0x80, 50)
    intfs = list(cfg)
    assert len(intfs) == 1
    intf = intfs[0]
    assert (intf.bInterfaceClass, intf.bInterfaceSubClass, intf.bInterfaceProtocol, intf.bNumEndpoints) \
        == (0xFF, 0xFF, 0, 2)
    eps = [(e.bEndpointAddress, e.bmAttributes, e.wMaxPacketSize, e.bInterval) for e in intf]
    assert eps == [(0x81, 2, 64, 6), (0x01, 2, 64, 6)]
    with pytest.raises(IndexError):
        backend.get_interface_descriptor(backend.dongles[0], 0, 1, 0)


def test_string_descriptors_through_ctrl_transfer(backend):
    dev = find_all(backend)[0]
    assert dev.langids == (0x0409,)
    assert dev.manufacturer == "Bitcraze"
    assert dev.product == "Crazyradio PA USB Dongle"
    assert dev.serial_number == backend.dongles[0].serial
    assert len(dev.serial_number) == 10 and int(dev.serial_number, 16) >= 0
    assert usb.util.get_string(dev, 2) == "Crazyradio PA USB Dongle"
    with pytest.raises(usb.core.USBError) as info:
        usb.util.get_string(dev, 7)
    assert info.value.errno == errno.EPIPE
    # The PA always sends its whole 22-byte serial descriptor: a short read overflows.
    with pytest.raises(usb.core.USBError) as info:
        dev.ctrl_transfer(0x80, 6, 0x0300 | 0x1D, 0x0409, 8)
    assert info.value.errno == errno.EOVERFLOW
    raw = dev.ctrl_transfer(0x80, 6, 0x0100, 0, 64)
    assert len(raw) == 18 and raw[8:12].tobytes() == b"\x15\x19\x77\x77"
    cfg = dev.ctrl_transfer(0x80, 6, 0x0200, 0, 255)
    assert len(cfg) == 32 and cfg[2] == 32


def test_crazyradio_2_model(medium):
    backend = FakeUsbBackend(medium, model="2.0", timing=DongleTiming.instant())
    dev = find_all(backend)[0]
    assert dev.bcdDevice == 0x0504
    assert (dev.manufacturer, dev.product) == ("Bitcraze AB", "Crazyradio 2.0")
    assert len(dev.serial_number) == 16
    intf = dev[0][(0, 0)]
    assert intf.bInterfaceSubClass == 0
    assert [e.bInterval for e in intf] == [0, 0]


def test_configuration_survives_reset(backend):
    dev = open_dev(backend)
    dev.reset()
    assert dev.get_active_configuration().bConfigurationValue == 1
    dev.write(1, b"\xff")
    assert dev.read(0x81, 64).tobytes() == b"\x03"


def ctrl(dev, req, value=0, index=0, data=b""):
    return dev.ctrl_transfer(VENDOR_OUT, req, value, index, data, 1000)


def test_every_vendor_request_changes_the_radio_state(backend, medium):
    dev = open_dev(backend)
    d = backend.dongles[0]
    assert (d.channel, d.address, d.datarate, d.power, d.arc, d.ard, d.ack_enabled) == \
        (2, b"\xe7" * 5, 2, 3, 3, 0xA0, True)
    ctrl(dev, 0x01, 80)
    ctrl(dev, 0x01, 126)                      # > 125: ignored
    assert d.channel == 80
    ctrl(dev, 0x02, data=b"\x01\x02\x03\x04\x05")
    assert d.address == b"\x01\x02\x03\x04\x05"
    ctrl(dev, 0x02, data=b"\xaa\xbb\xcc")     # 3 bytes: first bytes only
    assert d.address == b"\xaa\xbb\xcc\x04\x05"
    with pytest.raises(usb.core.USBError) as info:
        ctrl(dev, 0x02, data=b"\x01\x02")
    assert info.value.errno == errno.EPIPE
    ctrl(dev, 0x03, 0)
    ctrl(dev, 0x03, 3)                        # >= 3: ignored
    assert d.datarate == 0
    ctrl(dev, 0x04, 6)
    assert d.power == 2                       # value & 3
    ctrl(dev, 0x05, 0x85)
    assert d.ard == 0x85
    ctrl(dev, 0x06, 0x1F)
    assert d.arc == 15                        # & 0x0F
    ctrl(dev, 0x10, 0)
    assert d.ack_enabled is False
    ctrl(dev, 0x10, 7)
    assert d.ack_enabled is True
    ctrl(dev, 0x20, 1)
    assert d.cont_carrier is True
    ctrl(dev, 0x30, data=b"\x0a\x14")
    assert medium.faults == [(0, 10.0, 20.0, None, None)]
    with pytest.raises(usb.core.USBError) as info:
        ctrl(dev, 0x30, data=b"\x0a")
    assert info.value.errno == errno.EPIPE
    for unknown in (0x07, 0x22, 0x23, 0x99):
        with pytest.raises(usb.core.USBError) as info:
            ctrl(dev, unknown, 1)
        assert info.value.errno == errno.EPIPE
    assert len(medium.transmits) == 0


def test_fault_request_can_be_refused_on_the_pa(medium):
    backend = FakeUsbBackend(medium, timing=DongleTiming.instant(), fault_request=False)
    dev = open_dev(backend)
    with pytest.raises(usb.core.USBError):
        ctrl(dev, 0x30, data=b"\x0a\x14")
    assert medium.faults == []


def test_vendor_requests_stall_when_unconfigured(backend):
    dev = open_dev(backend)
    dev.set_configuration(0)
    with pytest.raises(usb.core.USBError) as info:
        ctrl(dev, 0x01, 10)
    assert info.value.errno == errno.EPIPE
    assert backend.dongles[0].channel == 2


def test_status_byte_and_payload(backend, medium):
    dev = open_dev(backend)
    ctrl(dev, 0x01, 80)
    medium.push(AirReply(True, b"\x2c\x01\x02", retries=2, power_detector=True),
                AirReply(True, b"", retries=15, power_detector=False),
                AirReply(False, b"ignored", retries=3),
                AirReply(True, bytes(range(40))))
    assert dev.write(1, b"\x3c" + bytes(14)) == 15
    assert dev.read(0x81, 64).tobytes() == bytes([0x23]) + b"\x2c\x01\x02"
    dev.write(1, b"\xff")
    assert dev.read(0x81, 64).tobytes() == bytes([0xF1])
    dev.write(1, b"\xff")
    assert dev.read(0x81, 64).tobytes() == b"\x00"
    dev.write(1, bytes(40))                   # bytes past 32 are dropped
    reply = dev.read(0x81, 64).tobytes()
    assert reply[0] == 0x03 and reply[1:] == bytes(range(32))
    tx = medium.transmits
    assert tx[0].channel == 80 and tx[0].datarate == 2 and tx[0].address == b"\xe7" * 5
    assert tx[0].data == b"\x3c" + bytes(14) and tx[0].ack_enabled and tx[0].arc == 3
    assert len(tx[3].data) == 32


def test_bulk_read_fills_the_buffer_in_place(backend, medium):
    dev = open_dev(backend)
    medium.push(AirReply(True, b"\x01\x02"))
    dev.write(1, b"\xff")
    buf = usb.util.create_buffer(64)
    assert dev.read(0x81, buf) == 3
    assert buf[:3].tobytes() == b"\x03\x01\x02"


def test_ack_disabled_sends_once_and_gives_no_reply(medium):
    clock = FakeClock()
    backend = FakeUsbBackend(medium, timing=DongleTiming.instant(), clock=clock)
    dev = open_dev(backend)
    ctrl(dev, 0x10, 0)
    dev.write(1, b"\x80\x01")
    assert medium.transmits[-1].ack_enabled is False
    with pytest.raises(usb.core.USBTimeoutError):
        dev.read(0x81, 64, 50)
    assert clock.sleeps[-1] == pytest.approx(0.05)
    dev.write(1, b"\x80\x02")                 # no reply pending: the next OUT goes through
    assert len(medium.transmits) == 2


def test_ping_pong_out_blocked_until_reply_read(medium):
    clock = FakeClock()
    backend = FakeUsbBackend(medium, timing=DongleTiming.instant(), clock=clock)
    dev = open_dev(backend)
    dev.write(1, b"\xff")
    with pytest.raises(usb.core.USBTimeoutError):
        dev.write(1, b"\xff", 20)
    assert len(medium.transmits) == 1
    assert dev.read(0x81, 64).tobytes() == b"\x03"


def test_continuous_carrier_consumes_no_packets(medium):
    clock = FakeClock()
    backend = FakeUsbBackend(medium, timing=DongleTiming.instant(), clock=clock)
    dev = open_dev(backend)
    ctrl(dev, 0x20, 1)
    with pytest.raises(usb.core.USBTimeoutError):
        dev.write(1, b"\xff", 10)
    assert medium.transmits == []


def test_scan_channels(medium):
    backend = FakeUsbBackend(medium, timing=DongleTiming.instant())
    medium.responder = lambda tx: AirReply(tx.channel in (10, 40, 41))
    dev = open_dev(backend)
    ctrl(dev, 0x21, 0, 200, b"\xff")          # stop capped at 125, every 2nd channel at 2M
    sent = [t.channel for t in medium.transmits]
    assert sent == list(range(0, 126, 2))
    assert dev.ctrl_transfer(0xC0, 0x21, 0, 0, 64).tobytes() == bytes([10, 40])
    assert backend.dongles[0].channel == 124
    medium.transmits.clear()
    ctrl(dev, 0x03, 1)
    ctrl(dev, 0x21, 38, 42, b"\xff")
    assert [t.channel for t in medium.transmits] == [38, 39, 40, 41, 42]
    assert dev.ctrl_transfer(0xC0, 0x21, 0, 0, 64).tobytes() == bytes([40, 41])
    with pytest.raises(usb.core.USBError):
        ctrl(dev, 0x21, 0, 10, b"")


def test_crazyradio_2_never_sends_at_250k_or_above_channel_100(medium):
    backend = FakeUsbBackend(medium, model="2.0", timing=DongleTiming.instant())
    dev = open_dev(backend)
    ctrl(dev, 0x03, 0)
    dev.write(1, b"\xff")
    assert dev.read(0x81, 64).tobytes() == b"\x00"
    ctrl(dev, 0x03, 2)
    ctrl(dev, 0x01, 101)
    dev.write(1, b"\xff")
    assert dev.read(0x81, 64).tobytes() == b"\x00"
    assert medium.transmits == []
    ctrl(dev, 0x01, 100)
    ctrl(dev, 0x06, 0x1F)
    assert backend.dongles[0].arc == 15
    ctrl(dev, 0x02, data=b"\x01\x02\x03")      # 2.0: wLength must be 5, else ignored (no STALL)
    assert backend.dongles[0].address == b"\xe7" * 5
    dev.write(1, b"\xff")
    assert dev.read(0x81, 64).tobytes() == b"\x03"
    assert medium.transmits[0].channel == 100


def test_several_handles_share_one_radio(backend, medium):
    dev_a = open_dev(backend)
    dev_b = find_all(backend)[0]            # a second Device/handle, as cflib's get_serials() makes
    assert dev_b.serial_number == backend.dongles[0].serial
    ctrl(dev_b, 0x01, 33)
    dev_a.write(1, b"\xff")
    dev_a.read(0x81, 64)
    assert medium.transmits[-1].channel == 33
    # Only one handle may claim the interface.
    with pytest.raises(usb.core.USBError) as info:
        dev_b.write(1, b"\xff")
    assert info.value.errno == errno.EBUSY
    usb.util.dispose_resources(dev_a)
    dev_b.write(1, b"\xff")
    assert dev_b.read(0x81, 64).tobytes() == b"\x03"


def test_two_dongles_have_stable_ids(medium):
    backend = FakeUsbBackend(medium, dongles=2, timing=DongleTiming.instant())
    for i in (1, 0, 1):
        dev = find_all(backend)[i]
        dev.write(1, bytes([i]))
        dev.read(0x81, 64)
        usb.util.dispose_resources(dev)
    assert [t.dongle for t in medium.transmits] == [1, 0, 1]
    assert find_all(backend)[1].serial_number != find_all(backend)[0].serial_number


def only_a_new_handle_works(backend, dev):
    """After a re-plug: the handle opened before stays dead, a fresh one is answered (a null packet's ack)."""
    with pytest.raises(usb.core.USBError):
        dev.write(1, b"\xff")
    usb.util.dispose_resources(dev)
    new = open_dev(backend)
    new.write(1, b"\xff")
    assert new.read(0x81, 64).tobytes() == b"\x03"


def test_unplug(backend, medium):
    dev = open_dev(backend)
    backend.unplug(0)
    for op in (lambda: dev.write(1, b"\xff"), lambda: ctrl(dev, 0x01, 5)):
        with pytest.raises(usb.core.USBError) as info:
            op()
        assert info.value.errno == errno.ENODEV
    assert find_all(backend) == []
    backend.replug(0)
    only_a_new_handle_works(backend, dev)


def test_unplug_reported_by_the_medium(backend, medium):
    dev = open_dev(backend)
    medium.push(AirReply(False, unplugged=True))
    with pytest.raises(usb.core.USBError) as info:
        dev.write(1, b"\xff")
    assert info.value.errno == errno.ENODEV
    assert backend.dongles[0].unplugged


def test_a_dongle_the_world_unplugged_is_back_when_the_world_plugs_it_in(backend, medium):
    dev = open_dev(backend)
    medium.set_dongle_faults(0, unplugged=True)
    medium.push(AirReply(False, unplugged=True))
    with pytest.raises(usb.core.USBError):
        dev.write(1, b"\xff")
    assert len(find_all(backend)) == len(backend.dongles) - 1       # off the bus while the world says so
    medium.set_dongle_faults(0, unplugged=False)
    assert len(find_all(backend)) == len(backend.dongles)           # re-enumerated, as after a re-plug
    only_a_new_handle_works(backend, dev)


def test_bootloader_after_reset(backend):
    dev = open_dev(backend)
    ctrl(dev, 0xFF)
    dev.reset()
    assert find_all(backend) == []
    boot = list(usb.core.find(idVendor=0x1915, idProduct=0x0101, find_all=True, backend=backend))
    assert len(boot) == 1
    with pytest.raises(usb.core.USBError) as info:
        boot[0].ctrl_transfer(VENDOR_OUT, 0x01, 5, 0, b"")
    assert info.value.errno == errno.EPIPE


def test_timing_model(medium):
    clock = FakeClock()
    timing = DongleTiming(bulk_round_trip_s=0.0008, retransmission_s=0.0007, control_transfer_s=0.0015)
    backend = FakeUsbBackend(medium, timing=timing, clock=clock)
    dev = open_dev(backend)
    ctrl(dev, 0x01, 80)
    assert clock.sleeps == [pytest.approx(0.0015)]
    clock.sleeps.clear()
    medium.push(AirReply(True, b"", retries=0), AirReply(True, b"", retries=2),
                AirReply(False), AirReply(True, b"", latency_s=0.01))
    expected = [0.0008, 0.0008 + 2 * 0.0007, 0.0008 + 3 * 0.0007, 0.0108]
    for want in expected:
        t0 = clock.now
        dev.write(1, b"\xff")
        dev.read(0x81, 64)
        assert clock.now - t0 == pytest.approx(want)
    # A read with a shorter timeout than the remaining air time times out; the reply stays.
    medium.push(AirReply(True, b"", latency_s=0.5))
    dev.write(1, b"\xff")
    with pytest.raises(usb.core.USBTimeoutError):
        dev.read(0x81, 64, 100)
    assert dev.read(0x81, 64, 1000).tobytes() == b"\x03"


def test_install_find_patch_overrides_any_backend(backend):
    class Other:
        pass

    uninstall = install_find_patch(backend)
    try:
        devs = list(usb.core.find(idVendor=0x1915, idProduct=0x7777, find_all=True, backend=Other()))
        assert len(devs) == 1 and devs[0].backend is backend
        assert usb.core.find(idVendor=0x1915, idProduct=0x7777).serial_number == backend.dongles[0].serial
    finally:
        uninstall()
    assert not hasattr(usb.core.find, "fake_backend")


def test_invalid_construction(medium):
    with pytest.raises(ValueError, match="model"):
        FakeUsbBackend(medium, model="3.0")


def test_crazyradio_2_inline_mode_frames(medium):
    backend = FakeUsbBackend(medium, model="2.0", timing=DongleTiming.instant())
    dev = open_dev(backend)
    d = backend.dongles[0]
    ctrl(dev, 0x23, 1)
    assert d.inline_mode == 1
    medium.push(AirReply(True, b"\x3c\x01", retries=2, power_detector=True), AirReply(False))
    # [total length 10, 2M | ack, channel 80, address E7E7E7E701] + payload 3C 01
    dev.write(1, b"\x0a\x12\x50\xe7\xe7\xe7\xe7\x01\x3c\x01")
    assert dev.read(0x81, 64).tobytes() == b"\x04\x23\x3c\x01"   # length 4, 2 retries | RPD | ack
    dev.write(1, b"\x09\x11\x14\xe7\xe7\xe7\xe7\x02\xff")           # 1M, channel 20, another address
    assert dev.read(0x81, 64).tobytes() == b"\x02\x30"               # lost after ARC 3 retries
    assert [(t.channel, t.datarate, t.address, t.data) for t in medium.transmits] == [
        (80, 2, b"\xe7\xe7\xe7\xe7\x01", b"\x3c\x01"), (20, 1, b"\xe7\xe7\xe7\xe7\x02", b"\xff")]
    assert [r[1] for r in d.vendor_requests] == [0x23]              # no setup between packets
    assert (d.channel, d.datarate, d.address, d.inline_mode) == (20, 1, b"\xe7\xe7\xe7\xe7\x02", 1)


def test_crazyradio_2_inline_mode_invalid_settings_no_ack_and_rssi(medium):
    backend = FakeUsbBackend(medium, model="2.0", timing=DongleTiming.instant())
    dev = open_dev(backend)
    ctrl(dev, 0x23, 1)
    dev.write(1, b"\x09\x02\x65\xe7\xe7\xe7\xe7\xe7\xff")           # channel 101: never sent
    assert dev.read(0x81, 64).tobytes() == b"\x02\x04"
    dev.write(1, b"\x09\x02\x50\xff\xff\xff\xff\xff\xff")           # ack bit off: sent once, still a reply
    assert dev.read(0x81, 64).tobytes() == b"\x02\x00"
    assert [(t.channel, t.ack_enabled) for t in medium.transmits] == [(80, False)]
    ctrl(dev, 0x23, 2)                                             # mode 2: one RSSI byte after the status
    medium.push(AirReply(True, b"\x01", power_detector=True))
    dev.write(1, b"\x09\x12\x50\xe7\xe7\xe7\xe7\xe7\xff")
    reply = dev.read(0x81, 64).tobytes()
    assert (reply[0], reply[1], reply[3:]) == (4, 0x03, b"\x01") and reply[2] < 64


@pytest.mark.parametrize("request_", [(0x01, 80, b""), (0x02, 0, b"\xe7" * 5), (0x03, 2, b""), (0x10, 1, b"")])
def test_crazyradio_2_settings_requests_leave_inline_mode(medium, request_):
    backend = FakeUsbBackend(medium, model="2.0", timing=DongleTiming.instant())
    dev = open_dev(backend)
    ctrl(dev, 0x23, 1)
    ctrl(dev, request_[0], request_[1], data=request_[2])
    assert backend.dongles[0].inline_mode == 0
    dev.write(1, b"\xff")                                          # the legacy format again
    assert dev.read(0x81, 64).tobytes() == b"\x03"


@pytest.mark.parametrize("model, mode", [("PA", 1), ("2.0-5.0", 1), ("2.0", 3)])
def test_inline_mode_stalls_where_the_firmware_lacks_it(medium, model, mode):
    backend = FakeUsbBackend(medium, model=model, timing=DongleTiming.instant())
    dev = open_dev(backend)
    with pytest.raises(usb.core.USBError) as err:
        ctrl(dev, 0x23, mode)
    assert err.value.errno == errno.EPIPE


def test_crazyradio_2_fault_request_works_in_inline_mode(medium):
    backend = FakeUsbBackend(medium, model="2.0", timing=DongleTiming.instant())
    dev = open_dev(backend)
    ctrl(dev, 0x23, 1)
    ctrl(dev, 0x30, data=b"\x0a\x05")
    assert medium.faults == [(0, 10.0, 5.0, None, None)]
    assert backend.dongles[0].inline_mode == 1


def test_inline_mode_timing_is_one_bulk_round_trip(medium):
    clock = FakeClock()
    timing = DongleTiming(bulk_round_trip_s=0.0008, retransmission_s=0.0007, control_transfer_s=0.0015)
    backend = FakeUsbBackend(medium, model="2.0", timing=timing, clock=clock)
    dev = open_dev(backend)
    ctrl(dev, 0x23, 1)
    medium.push(AirReply(True, b"", retries=1))
    t0 = clock.now
    dev.write(1, b"\x09\x12\x50\xe7\xe7\xe7\xe7\xe7\xff")
    dev.read(0x81, 64)
    assert clock.now - t0 == pytest.approx(0.0008 + 0.0007)


def test_inline_broadcast_burst_counted_per_packet():
    """A 2.0 in inline mode, 9 broadcast packets (a 17-pose burst): per packet one packet to the world,
    one OUT, one IN, no vendor request and one wait that ends 0.6 ms (the round trip less the ack wait)
    after its OUT began, so the time the world took to answer (here 0.25 ms) lies inside it."""
    clock = FakeClock()
    world_s = 0.00025

    def answer(tx):
        clock.now += world_s            # the host time of a request to the world's process
        return AirReply(False, b"", retries=3, power_detector=False)

    medium = ScriptedMedium(answer)
    backend = FakeUsbBackend(medium, model="2.0", clock=clock)
    radio = Crazyradio(0, backend=backend)
    radio.send_inline(80, 2, b"\xe7\xe7\xe7\xe7\x01", b"\xff")
    d = backend.dongles[0]
    sent, waits = len(medium.transmits), len(clock.sleeps)
    controls, outs, ins = d.control_transfers, d.bulk_out, d.bulk_in
    t0 = clock.now
    for i in range(9):
        assert not radio.send_inline(80, 2, BROADCAST_ADDRESS, bytes([0x61, 9, i]) + bytes(22), ack=False).ack
    assert len(medium.transmits) - sent == 9
    assert all(tx.address == BROADCAST_ADDRESS and not tx.ack_enabled for tx in medium.transmits[sent:])
    assert (d.control_transfers - controls, d.bulk_out - outs, d.bulk_in - ins) == (0, 9, 9)
    assert clock.sleeps[waits:] == pytest.approx([0.0006 - world_s] * 9)
    assert clock.now - t0 == pytest.approx(9 * 0.0006)
