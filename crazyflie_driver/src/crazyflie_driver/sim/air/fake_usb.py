"""A pyusb backend that emulates Crazyradio dongles and hands their radio packets to a Medium.

Only the bottom box of the stack is replaced: ``crazyradio.Crazyradio`` (and Bitcraze's cflib, whose
``usb.core.find`` the cflib tests redirect here) talk to these dongles through the ordinary pyusb API, so the code
that flies real hardware is the code under test.

Emulated (facts and sources in docs/simulation.md, "The fake Crazyradio"):

* a Crazyradio PA with firmware 0.53 (default) or a Crazyradio 2.0 with firmware 5.4
  (``model="2.0"``: 250K and channels above 100 are accepted but never sent, the IN reply is 0x00;
  inline mode);
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
* a timing model (``dongle_timing.DongleTiming``) applied with a clock's ``sleep``.

This module is the pyusb side (enumeration, handles, transfers); ``usb_descriptors`` holds the
descriptors, ``dongle`` the dongle's state and firmware.

The 2.0's inline mode (0x23, values 1 and 2 from firmware 5.4) is emulated in ``dongle``. Not emulated:
the 2.0's sniffer mode (0x24-0x26 STALL), the Microsoft OS descriptors of
development builds, the nRF bootloader's own protocol (after LAUNCH_BOOTLOADER and a reset the dongle
re-enumerates as 0x1915/0x0101 and stalls every radio request).
"""
from __future__ import annotations

import array
import errno
from typing import Optional

import usb.backend
import usb.core

from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.sim.air import fake_cable
from crazyflie_driver.sim.air.dongle import DongleFirmware, FakeDongle, fill, no_device, stall, usb_timeout
from crazyflie_driver.sim.air.dongle_timing import DongleClock, DongleTiming
from crazyflie_driver.sim.air.fake_cable import FakeCableCrazyflie
from crazyflie_driver.sim.air.usb_descriptors import (
    DESC_CONFIG,
    DESC_DEVICE,
    DESC_STRING,
    MODELS,
    PA_MODELS,
    DongleModel,
    config_descriptor_bytes,
    configuration_descriptor,
    device_descriptor,
    device_descriptor_bytes,
    endpoint_descriptor,
    interface_descriptor,
    string_descriptor,
)

_GET_STATUS = 0x00
_GET_DESCRIPTOR = 0x06
_GET_CONFIGURATION = 0x08
_SET_CONFIGURATION = 0x09


class _Handle:
    __slots__ = ("dongle", "generation", "closed")

    def __init__(self, dongle: FakeDongle):
        self.dongle = dongle
        self.generation = dongle.generation
        self.closed = False


class FakeUsbBackend(usb.backend.IBackend):
    """pyusb backend with ``dongles`` emulated Crazyradios attached to ``medium``.

    ``model`` is a name of ``usb_descriptors.MODELS``: "PA" (firmware 0.53), "PA-99.55", "2.0" (firmware
    5.4, inline mode) or "2.0-5.0". ``timing`` defaults to the model's (``DongleTiming``). ``clock`` needs
    ``time()`` and ``sleep(s)``; tests inject a fake one to check the timing model without waiting.
    Dongle ids (``FakeDongle.ident``, the ``dongle`` argument of ``Medium.transmit``) are
    ``first_id .. first_id + dongles - 1`` and stable for the backend's lifetime.
    """

    def __init__(self, medium, dongles: int = 1, model: str = "PA",
                 timing: Optional[DongleTiming] = None, clock=None, first_id: int = 0,
                 fault_request: bool = True, usb_crazyflies: int = 0):
        super().__init__()
        if model not in MODELS:
            raise ValueError("unknown Crazyradio model %r, use 'PA' or '2.0'" % (model,))
        if dongles < 0:
            raise ValueError("dongles must be >= 0, got %d" % dongles)
        self.medium = medium
        m = MODELS[model]
        if timing is None:
            timing = DongleTiming.crazyradio_2() if m.is_crazyradio_2 else DongleTiming()
        self.timing = timing
        self.clock = clock if clock is not None else DongleClock()
        self.firmware = DongleFirmware(medium, self.timing, self.clock, fault_request)
        self.dongles = [FakeDongle(first_id + i, m, self._serial_for(first_id + i, m))
                        for i in range(dongles)]
        # Simulated Crazyflies on a USB cable (the medium's usb_send/usb_receive), usb://0 first.
        self.cables = [FakeCableCrazyflie(first_id + dongles + i, i) for i in range(usb_crazyflies)]

    @staticmethod
    def _serial_for(ident: int, model: DongleModel) -> str:
        return ("%0*X" % (model.serial_digits, 0xC0FFEE0000 + ident))[-model.serial_digits:]

    # -- test/fault helpers ------------------------------------------------------------------
    def dongle(self, ident: int) -> FakeDongle:
        for d in self.dongles:
            if d.ident == ident:
                return d
        raise KeyError("no fake dongle with id %d" % ident)

    def unplug(self, ident: int) -> None:
        """Pull the dongle out: it leaves the bus and every open handle gets ENODEV."""
        d = self.dongle(ident)
        d.unplugged = True
        d.pulled_by_medium = False

    def replug(self, ident: int) -> None:
        """Plug it back in: power-up radio state; handles from before stay dead."""
        d = self.dongle(ident)
        with d.lock:
            d.unplugged = False
            d.pulled_by_medium = False
            d.in_bootloader = False
            d.bootloader_requested = False
            d.generation += 1
            d.configuration = 1
            d.claimed_by = None
            d.reply = None
            d.reset_radio()

    # -- enumeration and descriptors ------------------------------------------------------------
    def enumerate_devices(self):
        for d in self.dongles:
            if d.pulled_by_medium and self._plugged_in_again(d.ident):
                self.replug(d.ident)     # the host sees a new device, as after a real re-plug
        return [d for d in self.dongles if not d.unplugged] + [c for c in self.cables if not c.unplugged]

    def _plugged_in_again(self, ident: int) -> bool:
        """A dongle the world unplugged (``Medium.set_dongle_faults``) is back when the world says so."""
        try:
            return not self.medium.dongle_faults(ident).unplugged
        except (ValueError, IndexError, CrazyflieError):   # no such dongle there, or no world: stays out
            return False

    def get_device_descriptor(self, dev: FakeDongle):
        if isinstance(dev, FakeCableCrazyflie):
            return fake_cable.device_descriptor(dev)
        return device_descriptor(dev.model, dev.ident, dev.product_id)

    def get_configuration_descriptor(self, dev: FakeDongle, config: int):
        return configuration_descriptor(config)

    def get_interface_descriptor(self, dev: FakeDongle, intf: int, alt: int, config: int):
        return interface_descriptor(dev.model, intf, alt, config)

    def get_endpoint_descriptor(self, dev: FakeDongle, ep: int, intf: int, alt: int, config: int):
        return endpoint_descriptor(dev.model, ep, intf, alt, config)

    # -- handles ----------------------------------------------------------------------------------
    def open_device(self, dev: FakeDongle) -> _Handle:
        if dev.unplugged:
            raise no_device()
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
            raise no_device()
        return d

    def set_configuration(self, dev_handle: _Handle, config_value: int) -> None:
        d = self._live(dev_handle)
        if config_value not in (0, 1):
            raise stall("configuration %d does not exist" % config_value)
        with d.lock:
            d.configuration = config_value

    def get_configuration(self, dev_handle: _Handle) -> int:
        return self._live(dev_handle).configuration

    def set_interface_altsetting(self, dev_handle: _Handle, intf: int, altsetting: int) -> None:
        self._live(dev_handle)
        if intf != 0 or altsetting != 0:
            raise stall("interface %d alt %d does not exist" % (intf, altsetting))

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
                raise no_device()
            d.control_transfers += 1
            if self.timing.control_transfer_s:
                self.clock.sleep(self.timing.control_transfer_s)
            kind = bmRequestType & 0x60
            if kind == 0x00:
                return self._standard_request(d, bmRequestType, bRequest, wValue, wIndex, data)
            if kind != 0x40 or (bmRequestType & 0x1F) != 0:
                raise stall("request type 0x%02X not supported" % bmRequestType)
            if d.configuration != 1:
                raise stall("vendor request while not configured")
            if d.in_bootloader:
                raise stall("vendor request 0x%02X to the bootloader" % bRequest)
            d.vendor_requests.append((bmRequestType, bRequest, wValue, wIndex, bytes(data)))
            if isinstance(d, FakeCableCrazyflie):
                if bmRequestType & 0x80 or not fake_cable.vendor_out(d, bRequest, wValue, wIndex):
                    raise stall("vendor request 0x%02X to a Crazyflie" % bRequest)
                return 0
            if bmRequestType & 0x80:
                return self.firmware.vendor_in(d, bRequest, wValue, wIndex, data)
            return self.firmware.vendor_out(d, bRequest, wValue, wIndex, bytes(data))

    def _standard_request(self, d: FakeDongle, rtype: int, req: int, wValue: int, wIndex: int,
                          data) -> int:
        if rtype == 0x80 and req == _GET_DESCRIPTOR:
            dtype, index = wValue >> 8, wValue & 0xFF
            if isinstance(d, FakeCableCrazyflie):
                return fill(data, self._cable_descriptor(d, dtype, index, wValue))
            return fill(data, self._dongle_descriptor(d, dtype, index, wValue, len(data)))
        if rtype == 0x80 and req == _GET_STATUS:
            return fill(data, b"\x00\x00")  # bus powered, no remote wakeup
        if rtype == 0x80 and req == _GET_CONFIGURATION:
            return fill(data, bytes([d.configuration]))
        if rtype == 0x00 and req == _SET_CONFIGURATION and wValue in (0, 1):
            d.configuration = wValue
            return 0
        raise stall("standard request 0x%02X/0x%02X not supported" % (rtype, req))

    def _dongle_descriptor(self, d: FakeDongle, dtype: int, index: int, wValue: int, room: int) -> bytes:
        """A Crazyradio's descriptor for GET_DESCRIPTOR into a ``room``-byte buffer; STALL if it has none."""
        if dtype == DESC_DEVICE:
            return device_descriptor_bytes(d.model, d.product_id)
        if dtype == DESC_CONFIG and index == 0:
            return config_descriptor_bytes(d.model)
        if dtype != DESC_STRING:
            raise stall("descriptor 0x%04X not available" % wValue)
        raw = string_descriptor(d.model, d.serial, index)
        if raw is None:
            raise stall("no string descriptor %d" % index)
        if index == d.model.serial_index and d.model in PA_MODELS and room < len(raw):
            # The PA always sends the full 22-byte serial descriptor: the host overflows.
            raise usb.core.USBError("Overflow", -8, errno.EOVERFLOW)
        return raw

    def _cable_descriptor(self, cf: FakeCableCrazyflie, dtype: int, index: int, wValue: int) -> bytes:
        raw = None
        if dtype == DESC_DEVICE:
            raw = fake_cable.device_descriptor_bytes()
        elif dtype == DESC_CONFIG and index == 0:
            raw = config_descriptor_bytes(cf.model)
        elif dtype == DESC_STRING:
            raw = fake_cable.string_descriptor(cf, index)
        if raw is None:
            raise stall("descriptor 0x%04X not available" % wValue)
        return raw

    # -- bulk transfers -----------------------------------------------------------------------------
    def bulk_write(self, dev_handle: _Handle, ep: int, intf: int, data, timeout: int) -> int:
        d = self._live(dev_handle)
        if isinstance(d, FakeCableCrazyflie):          # a Crazyflie on a USB cable, not a dongle
            return self._cable_write(d, ep, data)
        if ep != 0x01:
            raise stall("bulk OUT to endpoint 0x%02X" % ep)
        with d.lock:
            clock = self.clock
            if d.reply is not None or d.cont_carrier or d.in_bootloader:
                # Ping-pong: the firmware does not take the next OUT before the last reply is read
                # (and never while the carrier test runs): the host's OUT is NAKed until it times out.
                clock.sleep(timeout / 1000.0)
                raise usb_timeout()
            start = clock.time()
            d.bulk_out += 1
            n = len(data)
            if n == 0:
                return 0
            self.firmware.send_packet(d, data, start)
            return n

    def bulk_read(self, dev_handle: _Handle, ep: int, intf: int, buff, timeout: int) -> int:
        d = self._live(dev_handle)
        if isinstance(d, FakeCableCrazyflie):          # a Crazyflie on a USB cable, not a dongle
            return self._cable_read(d, ep, buff, timeout)
        if ep != 0x81:
            raise stall("bulk IN from endpoint 0x%02X" % ep)
        with d.lock:
            clock = self.clock
            reply = d.reply
            if reply is None:
                clock.sleep(timeout / 1000.0 if timeout else 1.0)
                raise usb_timeout()
            wait = d.reply_ready_at - clock.time()
            if wait > 0:
                if timeout and wait > timeout / 1000.0:
                    clock.sleep(timeout / 1000.0)
                    raise usb_timeout()
                clock.sleep(wait)
            if d.unplugged:
                raise no_device()
            d.reply = None
            d.bulk_in += 1
            n = len(reply)
            if n > len(buff):
                n, reply = len(buff), reply[:len(buff)]
            buff[:n] = array.array("B", reply)
            return n

    def _cable_write(self, cf: FakeCableCrazyflie, ep: int, data) -> int:
        """One CRTP packet down the cable (dropped by a Crazyflie that is off, as its USB is unpowered)."""
        if ep != 0x01:
            raise stall("bulk OUT to endpoint 0x%02X" % ep)
        with cf.lock:
            cf.bulk_out += 1
            if len(data):
                self.medium.usb_send(cf.index, data.tobytes()[:32])
            return len(data)

    def _cable_read(self, cf: FakeCableCrazyflie, ep: int, buff, timeout: int) -> int:
        """The Crazyflie's next packet while its CRTP goes to USB; a timeout when it has none."""
        if ep != 0x81:
            raise stall("bulk IN from endpoint 0x%02X" % ep)
        with cf.lock:
            packet = self.medium.usb_receive(cf.index) if cf.crtp_to_usb else None
            if packet is None:
                self.clock.sleep(timeout / 1000.0 if timeout else 1.0)
                raise usb_timeout()
            cf.bulk_in += 1
            n = min(len(packet), len(buff))
            buff[:n] = array.array("B", packet[:n])
            return n

    def intr_write(self, dev_handle, ep, intf, data, timeout):
        raise stall("no interrupt endpoints")

    def intr_read(self, dev_handle, ep, intf, size_or_buffer, timeout):
        raise stall("no interrupt endpoints")

    def iso_write(self, dev_handle, ep, intf, data, timeout):
        raise stall("no isochronous endpoints")

    def iso_read(self, dev_handle, ep, intf, size_or_buffer, timeout):
        raise stall("no isochronous endpoints")
