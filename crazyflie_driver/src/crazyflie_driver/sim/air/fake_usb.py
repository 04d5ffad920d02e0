"""A pyusb backend that emulates Crazyradio dongles and hands their radio packets to a Medium.

Only the bottom box of the stack is replaced: ``crazyradio.Crazyradio`` (and Bitcraze's cflib,
through ``install_find_patch``) talk to these dongles through the ordinary pyusb API, so the code
that flies real hardware is the code under test.

Emulated (facts in CRTP.md §R1-§R3, §R7, §R8):

* a Crazyradio PA with firmware 0.53 (default) or a Crazyradio 2.0 with firmware 5.4
  (``model="2.0"``: 250K and channels above 100 are accepted but never sent, the IN reply is 0x00);
* full device/configuration/interface/endpoint descriptors; string descriptors (LANGID,
  manufacturer, product, serial) answered through ``ctrl_transfer`` as pyusb's ``get_string`` reads them;
* every vendor request of the 0.53 firmware, STALL (``USBError`` errno EPIPE) for unknown ones;
* the bulk protocol: one OUT = one radio packet, the IN reply = status byte + ack payload, no IN
  reply when acks are disabled (the read times out), strict ping-pong (an OUT while the previous
  reply is unread is NAKed until its timeout);
* several handles per dongle sharing one radio state; unplugging (``ENODEV`` from every transfer);
* request 0x30 (the Crazyradio 2.0 packet-loss simulation, 2 data bytes: packet-loss %, ack-loss %)
  forwarded to ``Medium.set_dongle_faults``. It is accepted on the PA model too (a simulator
  extension) unless ``fault_request=False``;
* a timing model (``DongleTiming``) applied with a clock's ``sleep``.

Not emulated: the 2.0's inline and sniffer modes (0x23-0x26 STALL), the Microsoft OS descriptors of
development builds, the nRF bootloader's own protocol (after LAUNCH_BOOTLOADER and a reset the dongle
re-enumerates as 0x1915/0x0101 and stalls every radio request).
"""
from __future__ import annotations

import array
import errno
import threading
from collections import deque
import time as _time
from dataclasses import dataclass
from typing import Callable, Deque, Optional

import usb.backend
import usb.core

# The dongle's USB identity and vendor requests (CRTP.md §R2) are shared with the host driver.
from crazyflie_driver.radio.crazyradio import (
    ACK_ENABLE, PRODUCT_ID, SCAN_CHANNELS, SET_CONT_CARRIER, SET_DATA_RATE, SET_RADIO_ADDRESS,
    SET_RADIO_ARC, SET_RADIO_ARD, SET_RADIO_CHANNEL, SET_RADIO_POWER, VENDOR_ID)

BOOTLOADER_PRODUCT_ID = 0x0101
# Requests the host driver does not use (CRTP.md §R1.2, §R2)
SET_PACKET_LOSS_SIMULATION = 0x30
LAUNCH_BOOTLOADER = 0xFF

_GET_STATUS = 0x00
_GET_DESCRIPTOR = 0x06
_GET_CONFIGURATION = 0x08
_SET_CONFIGURATION = 0x09
_DESC_DEVICE, _DESC_CONFIG, _DESC_STRING = 1, 2, 3

_MAX_SCAN_HITS = 63
VENDOR_REQUEST_LOG = 10000
_MAX_RADIO_PAYLOAD = 32


@dataclass
class DongleTiming:
    """Seconds the fake dongle takes for each kind of transfer (CRTP.md §R8; every figure a knob).

    An acked round trip (bulk OUT + IN) costs ``bulk_round_trip_s`` plus ``retransmission_s`` per
    retry the medium reports; an unacked one costs ARC retransmissions on top (about 2 ms at ARC 3).
    The medium's ``AirReply.latency_s`` is added to the round trip.
    """

    bulk_round_trip_s: float = 0.0008
    retransmission_s: float = 0.00067
    control_transfer_s: float = 0.0015

    @classmethod
    def instant(cls) -> "DongleTiming":
        """No modelled delay at all (unit tests, as-fast-as-possible simulation)."""
        return cls(0.0, 0.0, 0.0)


class RealClock:
    """Monotonic wall clock; ``sleep`` really sleeps."""

    time = staticmethod(_time.monotonic)
    sleep = staticmethod(_time.sleep)


@dataclass
class _DongleModel:
    name: str
    bcd_device: int
    manufacturer: str
    product: str
    serial_index: int
    interface_subclass: int
    endpoint_interval: int
    serial_digits: int


PA_053 = _DongleModel("PA", 0x0053, "Bitcraze", "Crazyradio PA USB Dongle", 0x1D, 0xFF, 6, 10)
CRAZYRADIO_2_54 = _DongleModel("2.0", 0x0504, "Bitcraze AB", "Crazyradio 2.0", 3, 0x00, 0, 16)
_MODELS = {"PA": PA_053, "pa": PA_053, "2.0": CRAZYRADIO_2_54, "2": CRAZYRADIO_2_54}


def _stall(what: str) -> usb.core.USBError:
    return usb.core.USBError("Pipe error (%s)" % what, -9, errno.EPIPE)


def _no_device() -> usb.core.USBError:
    return usb.core.USBError("No such device (it may have been disconnected)", -4, errno.ENODEV)


def _timeout() -> usb.core.USBTimeoutError:
    return usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)


class _Descriptor:
    """A descriptor object with the attributes pyusb copies (CRTP.md §R7.1)."""

    def __init__(self, **fields):
        self.__dict__.update(fields)


class FakeDongle:
    """One emulated dongle: its identity and the radio state shared by every handle opened on it."""

    def __init__(self, ident: int, model: _DongleModel, serial: str):
        self.ident = ident
        self.model = model
        self.serial = serial
        self.lock = threading.Lock()
        self.unplugged = False
        self.in_bootloader = False
        self.bootloader_requested = False
        self.generation = 0              # bumped on re-enumeration; older handles get ENODEV
        self.configuration = 1           # Linux configures single-config devices on plug-in
        self.claimed_by: Optional[object] = None
        self.reply: Optional[bytes] = None   # IN reply waiting to be read
        self.reply_ready_at = 0.0
        # Counters for tests and benchmarks.
        self.control_transfers = 0
        # (bmRequestType, bRequest, wValue, wIndex, data) of the latest vendor requests (bounded).
        self.vendor_requests: Deque[tuple] = deque(maxlen=VENDOR_REQUEST_LOG)
        self.bulk_out = 0
        self.bulk_in = 0
        self.reset_radio()

    def reset_radio(self) -> None:
        """The firmware's power-up radio settings (CRTP.md §R2 'default' column)."""
        self.channel = 2
        self.address = b"\xe7\xe7\xe7\xe7\xe7"
        self.datarate = 2
        self.power = 3
        self.ard = 0xA0
        self.arc = 3
        self.ack_enabled = True
        self.cont_carrier = False
        self.scan_hits = b""

    @property
    def product_id(self) -> int:
        return BOOTLOADER_PRODUCT_ID if self.in_bootloader else PRODUCT_ID

    def __repr__(self) -> str:
        return "<FakeDongle %d %s serial %s>" % (self.ident, self.model.name, self.serial)


class _Handle:
    __slots__ = ("dongle", "generation", "closed")

    def __init__(self, dongle: FakeDongle):
        self.dongle = dongle
        self.generation = dongle.generation
        self.closed = False


class FakeUsbBackend(usb.backend.IBackend):
    """pyusb backend with ``dongles`` emulated Crazyradios attached to ``medium``.

    ``model`` is "PA" (firmware 0.53) or "2.0" (firmware 5.4). ``clock`` needs ``time()`` and
    ``sleep(s)``; tests inject a fake one to check the timing model without waiting.
    Dongle ids (``FakeDongle.ident``, the ``dongle`` argument of ``Medium.transmit``) are
    ``first_id .. first_id + dongles - 1`` and stable for the backend's lifetime.
    """

    def __init__(self, medium, dongles: int = 1, model: str = "PA",
                 timing: Optional[DongleTiming] = None, clock=None, first_id: int = 0,
                 fault_request: bool = True):
        super().__init__()
        if model not in _MODELS:
            raise ValueError("unknown Crazyradio model %r, use 'PA' or '2.0'" % (model,))
        if dongles < 0:
            raise ValueError("dongles must be >= 0, got %d" % dongles)
        self.medium = medium
        self.timing = timing if timing is not None else DongleTiming()
        self.clock = clock if clock is not None else RealClock()
        self.fault_request = fault_request
        m = _MODELS[model]
        self.dongles = [FakeDongle(first_id + i, m, self._serial_for(first_id + i, m))
                        for i in range(dongles)]

    @staticmethod
    def _serial_for(ident: int, model: _DongleModel) -> str:
        return ("%0*X" % (model.serial_digits, 0xC0FFEE0000 + ident))[-model.serial_digits:]

    # -- test/fault helpers ------------------------------------------------------------------
    def dongle(self, ident: int) -> FakeDongle:
        for d in self.dongles:
            if d.ident == ident:
                return d
        raise KeyError("no fake dongle with id %d" % ident)

    def unplug(self, ident: int) -> None:
        """Pull the dongle out: it leaves the bus and every open handle gets ENODEV."""
        self.dongle(ident).unplugged = True

    def replug(self, ident: int) -> None:
        """Plug it back in: power-up radio state; handles from before stay dead."""
        d = self.dongle(ident)
        with d.lock:
            d.unplugged = False
            d.in_bootloader = False
            d.bootloader_requested = False
            d.generation += 1
            d.configuration = 1
            d.claimed_by = None
            d.reply = None
            d.reset_radio()

    # -- enumeration and descriptors ------------------------------------------------------------
    def enumerate_devices(self):
        return [d for d in self.dongles if not d.unplugged]

    def get_device_descriptor(self, dev: FakeDongle):
        m = dev.model
        return _Descriptor(
            bLength=18, bDescriptorType=_DESC_DEVICE, bcdUSB=0x0200,
            bDeviceClass=0, bDeviceSubClass=0, bDeviceProtocol=0, bMaxPacketSize0=64,
            idVendor=VENDOR_ID, idProduct=dev.product_id, bcdDevice=m.bcd_device,
            iManufacturer=1, iProduct=2, iSerialNumber=m.serial_index, bNumConfigurations=1,
            bus=1, address=dev.ident + 2, port_number=dev.ident + 1, port_numbers=(dev.ident + 1,),
            speed=2)  # libusb speed 2 = full speed

    def get_configuration_descriptor(self, dev: FakeDongle, config: int):
        if config != 0:
            raise IndexError("configuration index %d out of range" % config)
        return _Descriptor(
            bLength=9, bDescriptorType=_DESC_CONFIG, wTotalLength=32, bNumInterfaces=1,
            bConfigurationValue=1, iConfiguration=0, bmAttributes=0x80, bMaxPower=50,
            extra_descriptors=[])

    def get_interface_descriptor(self, dev: FakeDongle, intf: int, alt: int, config: int):
        if config != 0 or intf != 0 or alt != 0:
            raise IndexError("interface %d alt %d (configuration %d) out of range" % (intf, alt, config))
        return _Descriptor(
            bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0,
            bNumEndpoints=2, bInterfaceClass=0xFF, bInterfaceSubClass=dev.model.interface_subclass,
            bInterfaceProtocol=0, iInterface=0, extra_descriptors=[])

    def get_endpoint_descriptor(self, dev: FakeDongle, ep: int, intf: int, alt: int, config: int):
        if config != 0 or intf != 0 or alt != 0 or ep not in (0, 1):
            raise IndexError("endpoint %d out of range" % ep)
        return _Descriptor(
            bLength=7, bDescriptorType=5, bEndpointAddress=0x81 if ep == 0 else 0x01,
            bmAttributes=0x02, wMaxPacketSize=64, bInterval=dev.model.endpoint_interval,
            bRefresh=0, bSynchAddress=0, extra_descriptors=[])

    def _device_descriptor_bytes(self, d: FakeDongle) -> bytes:
        m = d.model
        return bytes([18, 1, 0x00, 0x02, 0, 0, 0, 64,
                      VENDOR_ID & 0xFF, VENDOR_ID >> 8, d.product_id & 0xFF, d.product_id >> 8,
                      m.bcd_device & 0xFF, m.bcd_device >> 8, 1, 2, m.serial_index, 1])

    def _config_descriptor_bytes(self, d: FakeDongle) -> bytes:
        interval = d.model.endpoint_interval
        return bytes([9, 2, 32, 0, 1, 1, 0, 0x80, 50,
                      9, 4, 0, 0, 2, 0xFF, d.model.interface_subclass, 0, 0,
                      7, 5, 0x81, 0x02, 64, 0, interval,
                      7, 5, 0x01, 0x02, 64, 0, interval])

    def _string_descriptor(self, d: FakeDongle, index: int) -> bytes:
        if index == 0:
            return bytes([4, 3, 0x09, 0x04])  # one LANGID: 0x0409 (English, US)
        text = {1: d.model.manufacturer, 2: d.model.product, d.model.serial_index: d.serial}.get(index)
        if text is None:
            raise _stall("no string descriptor %d" % index)
        raw = text.encode("utf-16-le")
        return bytes([len(raw) + 2, 3]) + raw

    # -- handles ----------------------------------------------------------------------------------
    def open_device(self, dev: FakeDongle) -> _Handle:
        if dev.unplugged:
            raise _no_device()
        return _Handle(dev)

    def close_device(self, dev_handle: _Handle) -> None:
        d = dev_handle.dongle
        with d.lock:
            if d.claimed_by is dev_handle:
                d.claimed_by = None
        dev_handle.closed = True

    def _live(self, h: _Handle) -> FakeDongle:
        d = h.dongle
        if d.unplugged or h.generation != d.generation or h.closed:
            raise _no_device()
        return d

    def set_configuration(self, dev_handle: _Handle, config_value: int) -> None:
        d = self._live(dev_handle)
        if config_value not in (0, 1):
            raise _stall("configuration %d does not exist" % config_value)
        with d.lock:
            d.configuration = config_value

    def get_configuration(self, dev_handle: _Handle) -> int:
        return self._live(dev_handle).configuration

    def set_interface_altsetting(self, dev_handle: _Handle, intf: int, altsetting: int) -> None:
        self._live(dev_handle)
        if intf != 0 or altsetting != 0:
            raise _stall("interface %d alt %d does not exist" % (intf, altsetting))

    def claim_interface(self, dev_handle: _Handle, intf: int) -> None:
        d = self._live(dev_handle)
        if intf != 0:
            raise usb.core.USBError("Entity not found", -5, errno.ENOENT)
        with d.lock:
            if d.claimed_by is not None and d.claimed_by is not dev_handle:
                raise usb.core.USBError("Resource busy", -6, errno.EBUSY)
            d.claimed_by = dev_handle

    def release_interface(self, dev_handle: _Handle, intf: int) -> None:
        d = dev_handle.dongle
        with d.lock:
            if d.claimed_by is dev_handle:
                d.claimed_by = None

    def reset_device(self, dev_handle: _Handle) -> None:
        """USB reset. After LAUNCH_BOOTLOADER the dongle re-enumerates as the Nordic bootloader."""
        d = self._live(dev_handle)
        with d.lock:
            d.reply = None
            if d.claimed_by is dev_handle:
                d.claimed_by = None
            if d.bootloader_requested:
                d.bootloader_requested = False
                d.in_bootloader = True
                d.generation += 1
        # The kernel re-applies configuration 1 after a reset, so get_configuration stays 1.

    def clear_halt(self, dev_handle: _Handle, ep: int) -> None:
        self._live(dev_handle)

    def is_kernel_driver_active(self, dev_handle: _Handle, intf: int) -> bool:
        self._live(dev_handle)
        return False

    def detach_kernel_driver(self, dev_handle: _Handle, intf: int) -> None:
        self._live(dev_handle)

    def attach_kernel_driver(self, dev_handle: _Handle, intf: int) -> None:
        self._live(dev_handle)

    # -- control transfers --------------------------------------------------------------------
    def ctrl_transfer(self, dev_handle: _Handle, bmRequestType: int, bRequest: int, wValue: int,
                      wIndex: int, data, timeout: int) -> int:
        d = self._live(dev_handle)
        with d.lock:
            if d.unplugged:
                raise _no_device()
            d.control_transfers += 1
            if self.timing.control_transfer_s:
                self.clock.sleep(self.timing.control_transfer_s)
            kind = bmRequestType & 0x60
            if kind == 0x00:
                return self._standard_request(d, bmRequestType, bRequest, wValue, wIndex, data)
            if kind != 0x40 or (bmRequestType & 0x1F) != 0:
                raise _stall("request type 0x%02X not supported" % bmRequestType)
            if d.configuration != 1:
                raise _stall("vendor request while not configured")
            if d.in_bootloader:
                raise _stall("vendor request 0x%02X to the bootloader" % bRequest)
            d.vendor_requests.append((bmRequestType, bRequest, wValue, wIndex, bytes(data)))
            if bmRequestType & 0x80:
                return self._vendor_in(d, bRequest, wValue, wIndex, data)
            return self._vendor_out(d, bRequest, wValue, wIndex, bytes(data))

    def _standard_request(self, d: FakeDongle, rtype: int, req: int, wValue: int, wIndex: int,
                          data) -> int:
        if rtype == 0x80 and req == _GET_DESCRIPTOR:
            dtype, index = wValue >> 8, wValue & 0xFF
            if dtype == _DESC_DEVICE:
                raw = self._device_descriptor_bytes(d)
            elif dtype == _DESC_CONFIG and index == 0:
                raw = self._config_descriptor_bytes(d)
            elif dtype == _DESC_STRING:
                raw = self._string_descriptor(d, index)
                if index == d.model.serial_index and d.model is PA_053 and len(data) < len(raw):
                    # The PA always sends the full 22-byte serial descriptor: the host overflows.
                    raise usb.core.USBError("Overflow", -8, errno.EOVERFLOW)
            else:
                raise _stall("descriptor 0x%04X not available" % wValue)
            return _fill(data, raw)
        if rtype == 0x80 and req == _GET_STATUS:
            return _fill(data, b"\x00\x00")  # bus powered, no remote wakeup
        if rtype == 0x80 and req == _GET_CONFIGURATION:
            return _fill(data, bytes([d.configuration]))
        if rtype == 0x00 and req == _SET_CONFIGURATION and wValue in (0, 1):
            d.configuration = wValue
            return 0
        raise _stall("standard request 0x%02X/0x%02X not supported" % (rtype, req))

    def _vendor_out(self, d: FakeDongle, req: int, wValue: int, wIndex: int, data: bytes) -> int:
        is_v2 = d.model is CRAZYRADIO_2_54
        if req == SET_RADIO_CHANNEL:
            if wValue <= 125:
                d.channel = wValue
        elif req == SET_RADIO_ADDRESS:
            if is_v2:
                if len(data) == 5:
                    d.address = data
            elif 3 <= len(data) <= 5:
                d.address = data + d.address[len(data):]
            else:
                raise _stall("SET_RADIO_ADDRESS with %d bytes" % len(data))
        elif req == SET_DATA_RATE:
            if wValue < 3:
                d.datarate = wValue
        elif req == SET_RADIO_POWER:
            d.power = min(wValue, 3) if is_v2 else wValue & 3
        elif req == SET_RADIO_ARD:
            if not is_v2:
                d.ard = wValue & 0xFF
        elif req == SET_RADIO_ARC:
            d.arc = wValue & 0x0F
        elif req == ACK_ENABLE:
            d.ack_enabled = wValue != 0
        elif req == SET_CONT_CARRIER:
            d.cont_carrier = wValue != 0
        elif req == SCAN_CHANNELS:
            if not data:
                raise _stall("START_SCAN_CHANNELS without a packet")
            self._scan(d, wValue, min(wIndex, 125), data)
        elif req == SET_PACKET_LOSS_SIMULATION and (is_v2 or self.fault_request):
            if len(data) != 2 or data[0] > 100 or data[1] > 100:
                raise _stall("SET_PACKET_LOSS_SIMULATION needs 2 bytes of percent (0-100)")
            self.medium.set_dongle_faults(d.ident, packet_loss=float(data[0]), ack_loss=float(data[1]))
        elif req == LAUNCH_BOOTLOADER:
            d.bootloader_requested = True
        else:
            raise _stall("unknown vendor request 0x%02X" % req)
        return len(data)

    def _vendor_in(self, d: FakeDongle, req: int, wValue: int, wIndex: int, data) -> int:
        if req == SCAN_CHANNELS:
            return _fill(data, d.scan_hits)
        raise _stall("unknown vendor IN request 0x%02X" % req)

    def _scan(self, d: FakeDongle, start: int, stop: int, packet: bytes) -> None:
        """Firmware scan: send the packet on start..stop (every 2nd channel at 2M on the PA)."""
        step = 2 if (d.datarate == 2 and d.model is PA_053) else 1
        hits = bytearray()
        spent = 0.0
        channel = start
        for channel in range(start, stop + 1, step):
            if not self._radio_allowed(d, channel):
                continue
            reply = self.medium.transmit(d.ident, channel, d.datarate, d.address,
                                         packet[:_MAX_RADIO_PAYLOAD], True, d.arc)
            if reply.unplugged:
                d.unplugged = True
                raise _no_device()
            spent += self._air_time(d, reply)
            if reply.acked and len(hits) < _MAX_SCAN_HITS:
                hits.append(channel)
        if start <= stop:
            d.channel = channel
        d.scan_hits = bytes(hits)
        if spent:
            self.clock.sleep(spent)

    def _radio_allowed(self, d: FakeDongle, channel: int) -> bool:
        if d.model is CRAZYRADIO_2_54:
            return d.datarate != 0 and channel <= 100
        return True

    def _air_time(self, d: FakeDongle, reply) -> float:
        t = self.timing
        retries = reply.retries if reply.acked else d.arc
        return t.bulk_round_trip_s + retries * t.retransmission_s + reply.latency_s

    # -- bulk transfers -----------------------------------------------------------------------------
    def bulk_write(self, dev_handle: _Handle, ep: int, intf: int, data, timeout: int) -> int:
        d = self._live(dev_handle)
        if ep != 0x01:
            raise _stall("bulk OUT to endpoint 0x%02X" % ep)
        with d.lock:
            clock = self.clock
            if d.reply is not None or d.cont_carrier or d.in_bootloader:
                # Ping-pong: the firmware does not take the next OUT before the last reply is read
                # (and never while the carrier test runs): the host's OUT is NAKed until it times out.
                clock.sleep(timeout / 1000.0)
                raise _timeout()
            start = clock.time()
            d.bulk_out += 1
            n = len(data)
            if n == 0:
                return 0
            packet = data[:_MAX_RADIO_PAYLOAD].tobytes() if n > _MAX_RADIO_PAYLOAD else data.tobytes()
            if not self._radio_allowed(d, d.channel):
                d.reply = b"\x00"  # Crazyradio 2.0: invalid settings, nothing sent, "no ack"
                d.reply_ready_at = start + self.timing.bulk_round_trip_s
                return n
            reply = self.medium.transmit(d.ident, d.channel, d.datarate, d.address, packet,
                                         d.ack_enabled, d.arc)
            if reply.unplugged:
                d.unplugged = True
                raise _no_device()
            if not d.ack_enabled:
                # No IN reply; the dongle still needs the air time before it takes the next OUT.
                busy = self.timing.bulk_round_trip_s + reply.latency_s
                if busy > 0:
                    clock.sleep(busy)
                return n
            if reply.acked:
                payload = reply.payload
                if len(payload) > _MAX_RADIO_PAYLOAD:
                    payload = payload[:_MAX_RADIO_PAYLOAD]
                status = 1 | (0x02 if reply.power_detector else 0) | ((reply.retries & 0x0F) << 4)
                d.reply = bytes((status,)) + payload
            else:
                d.reply = b"\x00"
            d.reply_ready_at = start + self._air_time(d, reply)
            return n

    def bulk_read(self, dev_handle: _Handle, ep: int, intf: int, buff, timeout: int) -> int:
        d = self._live(dev_handle)
        if ep != 0x81:
            raise _stall("bulk IN from endpoint 0x%02X" % ep)
        with d.lock:
            clock = self.clock
            reply = d.reply
            if reply is None:
                clock.sleep(timeout / 1000.0 if timeout else 1.0)
                raise _timeout()
            wait = d.reply_ready_at - clock.time()
            if wait > 0:
                if timeout and wait > timeout / 1000.0:
                    clock.sleep(timeout / 1000.0)
                    raise _timeout()
                clock.sleep(wait)
            if d.unplugged:
                raise _no_device()
            d.reply = None
            d.bulk_in += 1
            n = min(len(reply), len(buff))
            buff[:n] = array.array("B", reply[:n])
            return n

    def intr_write(self, dev_handle, ep, intf, data, timeout):
        raise _stall("no interrupt endpoints")

    def intr_read(self, dev_handle, ep, intf, size_or_buffer, timeout):
        raise _stall("no interrupt endpoints")

    def iso_write(self, dev_handle, ep, intf, data, timeout):
        raise _stall("no isochronous endpoints")

    def iso_read(self, dev_handle, ep, intf, size_or_buffer, timeout):
        raise _stall("no isochronous endpoints")


def _fill(buff, raw: bytes) -> int:
    """Copy an IN data stage into pyusb's buffer in place, as the libusb1 backend does."""
    n = min(len(buff), len(raw))
    if n:
        buff[:n] = array.array("B", raw[:n])
    return n


# -- making usb.core.find use the fake, whatever backend the caller passes ---------------------
_original_find: Optional[Callable] = None
_original_libusb_package = None


def install_find_patch(backend: FakeUsbBackend) -> Callable[[], None]:
    """Wrap ``usb.core.find`` so every call uses ``backend`` (cflib always passes its own backend=).

    Also replaces ``libusb_package.get_libusb1_backend`` when that module is installed. Returns the
    matching uninstall function (same as ``uninstall_find_patch``). Installing twice replaces the
    backend of the first patch.
    """
    global _original_find, _original_libusb_package
    if _original_find is None:
        _original_find = usb.core.find
    original = _original_find

    def find(*args, **kwargs):
        kwargs["backend"] = backend
        return original(*args, **kwargs)

    find.__doc__ = original.__doc__
    find.fake_backend = backend  # type: ignore[attr-defined]
    usb.core.find = find
    try:
        import libusb_package  # type: ignore
    except ImportError:
        pass
    else:
        if _original_libusb_package is None:
            _original_libusb_package = libusb_package.get_libusb1_backend
        libusb_package.get_libusb1_backend = lambda *a, **k: backend
    return uninstall_find_patch


def uninstall_find_patch() -> None:
    """Restore ``usb.core.find`` (and libusb_package) as they were before ``install_find_patch``."""
    global _original_find, _original_libusb_package
    if _original_find is not None:
        usb.core.find = _original_find
        _original_find = None
    if _original_libusb_package is not None:
        import libusb_package  # type: ignore
        libusb_package.get_libusb1_backend = _original_libusb_package
        _original_libusb_package = None
