"""A Crazyflie on a USB cable: its USB identity, CRTP over USB through pyusb, and ``UsbLink``.

Facts in docs/protocol.md, "A Crazyflie on a USB cable": vendor 0x0483, product 0x5740, manufacturer
"Bitcraze AB"; vendor request 0x01 (wValue 1, wIndex 1 on / 0 off) routes CRTP to USB; then each bulk
OUT (endpoint 0x01) is one CRTP packet, header byte + payload, and each bulk IN (0x81) one packet
from the Crazyflie. No acks, no safelink, nothing lost on the way: a read that times out means the
Crazyflie had nothing to say.
"""
from __future__ import annotations

import errno
import time
from typing import Callable, List, NamedTuple, Optional

import usb.core
import usb.util

from crazyflie_driver.crtp.uri import UsbUri
from crazyflie_driver.errors import CrazyflieError, RadioNotFound, RadioUnplugged
from crazyflie_driver.radio.crazyradio import RadioAck, serial_number_of
from crazyflie_driver.radio.link import NULL_PACKET, RadioLink

CRAZYFLIE_VENDOR_ID = 0x0483
CRAZYFLIE_PRODUCT_ID = 0x5740
CRAZYFLIE_MANUFACTURER = "Bitcraze AB"
SET_CRTP_TO_USB = 0x01
#: ms a poll waits for a packet from the Crazyflie (its USB task sends as soon as one is queued).
USB_POLL_TIMEOUT_MS = 2
_EP_OUT, _EP_IN = 0x01, 0x81
_TYPE_VENDOR_OUT = 0x40
_GONE_ERRNOS = (errno.ENODEV, errno.EIO, errno.ENOENT, errno.ESHUTDOWN)
_NOTHING = RadioAck(True, False, 0, b"")
_now = time.perf_counter


class UsbCrazyflieInfo(NamedTuple):
    """A Crazyflie on the bus, as ``list_usb_crazyflies`` reports it."""

    index: int  # type: ignore[assignment]  # shadows tuple.index: the public name of the bus position
    serial: Optional[str]
    uri: str


def _find(backend) -> list:
    """Crazyflies on the bus (their manufacturer string tells them from other STM32 devices)."""
    try:
        found = list(usb.core.find(idVendor=CRAZYFLIE_VENDOR_ID, idProduct=CRAZYFLIE_PRODUCT_ID, find_all=True,
                                   backend=backend))
    except usb.core.NoBackendError as exc:
        raise RadioNotFound("no USB backend for pyusb (install libusb-1.0, e.g. the libusb-1.0-0 package)") from exc
    out = []
    for dev in found:
        try:
            if dev.manufacturer == CRAZYFLIE_MANUFACTURER:
                out.append(dev)
                continue
        except (usb.core.USBError, ValueError):
            pass
        usb.util.dispose_resources(dev)
    return out


def list_usb_crazyflies(backend=None) -> List[UsbCrazyflieInfo]:
    """Every Crazyflie on a USB cable, in the order ``usb://N`` numbers them."""
    return [UsbCrazyflieInfo(i, serial_number_of(dev), str(UsbUri(i))) for i, dev in enumerate(_find(backend))]


class UsbCrazyflie:
    """The ``index``-th Crazyflie on a USB cable, with CRTP routed to USB while it is open."""

    def __init__(self, index: int = 0, backend=None, usb_timeout_ms: int = 1000) -> None:
        self.index = index
        self.usb_timeout_ms = usb_timeout_ms
        devices = _find(backend)
        if not 0 <= index < len(devices):
            for dev in devices:
                usb.util.dispose_resources(dev)
            raise RadioNotFound("no Crazyflie usb://%d: %d Crazyflie%s on a USB cable (is it plugged in and switched "
                                "on, and are the udev rules in crazyflie_driver/udev/ installed?)"
                                % (index, len(devices), "" if len(devices) == 1 else "s"))
        self._dev = devices[index]
        for other in devices:
            if other is not self._dev:
                usb.util.dispose_resources(other)
        self._buffer = usb.util.create_buffer(64)
        try:
            self._dev.set_configuration(1)
            usb.util.claim_interface(self._dev, 0)
        except usb.core.USBError as exc:
            usb.util.dispose_resources(self._dev)
            raise self._error(exc, "opening") from exc
        self.set_crtp_to_usb(True)

    def set_crtp_to_usb(self, on: bool) -> None:
        """Route the Crazyflie's CRTP to USB (on) or back to the radio (off)."""
        try:
            self._dev.ctrl_transfer(_TYPE_VENDOR_OUT, SET_CRTP_TO_USB, 1, 1 if on else 0, b"", self.usb_timeout_ms)
        except usb.core.USBError as exc:
            raise self._error(exc, "switching CRTP to USB") from exc

    def write(self, packet: bytes) -> None:
        """One CRTP packet (header + payload) to the Crazyflie."""
        dev = self._dev
        if dev is None:
            raise RadioUnplugged("usb://%d is closed" % self.index)
        try:
            dev.write(_EP_OUT, packet, self.usb_timeout_ms)
        except usb.core.USBError as exc:
            raise self._error(exc, "sending a packet") from exc

    def read(self, timeout_ms: int = USB_POLL_TIMEOUT_MS) -> bytes:
        """One CRTP packet from the Crazyflie, b"" when it had none within ``timeout_ms``."""
        dev = self._dev
        if dev is None:
            raise RadioUnplugged("usb://%d is closed" % self.index)
        try:
            n = dev.read(_EP_IN, self._buffer, timeout_ms)
        except usb.core.USBTimeoutError:
            return b""
        except usb.core.USBError as exc:
            raise self._error(exc, "reading a packet") from exc
        return self._buffer[:n].tobytes()

    def close(self) -> None:
        """CRTP back to the radio, then release the device. Idempotent."""
        dev = self._dev
        if dev is None:
            return
        try:
            self.set_crtp_to_usb(False)
        except CrazyflieError:
            pass                          # unplugged: nothing to switch back
        self._dev = None
        try:
            usb.util.dispose_resources(dev)
        except usb.core.USBError:
            pass

    def _error(self, exc: usb.core.USBError, what: str) -> CrazyflieError:
        if exc.errno in _GONE_ERRNOS or getattr(exc, "backend_error_code", None) == -4:
            return RadioUnplugged("usb://%d was unplugged (%s: %s)" % (self.index, what, exc.strerror or exc))
        return CrazyflieError("usb://%d: USB error while %s: %s" % (self.index, what, exc))


class UsbLink(RadioLink):
    """The link to a Crazyflie on a USB cable, with ``RadioLink``'s interface (send, poll, request,
    subscribe, statistics). A round trip writes the packet (a null packet is not written: it only
    asks for downlink) then reads at most one packet back; nothing is lost, so no safelink and no
    re-sending. ``opener(index)`` opens the device (``RadioManager.usb_factory``, or ``UsbCrazyflie``)."""

    def __init__(self, uri: UsbUri, opener: Callable[[int], UsbCrazyflie], **options) -> None:
        options["safelink"] = False
        super().__init__(uri, manager=_NO_MANAGER, **options)   # type: ignore[arg-type]
        self._opener = opener
        self._usb: Optional[UsbCrazyflie] = None

    @property
    def needs_resending(self) -> bool:
        return False

    @property
    def is_open(self) -> bool:
        return self._usb is not None

    def open(self) -> None:
        with self._send_lock:
            if self._usb is None:
                self._usb = self._opener(self.uri.index)

    def close(self) -> None:
        with self._send_lock:
            device, self._usb = self._usb, None
        if device is not None:
            device.close()

    def _round_trip(self, data: bytes, background: bool = False) -> RadioAck:
        device = self._usb
        if device is None:
            raise CrazyflieError("%s: link is not open" % (self.uri,))
        started = _now()
        if data != NULL_PACKET:
            device.write(data)
        reply = device.read()
        self.stats.record(True, 0, _now() - started)
        return RadioAck(True, False, 0, reply) if reply else _NOTHING

    def __repr__(self) -> str:
        return "<UsbLink %s %s>" % (self.uri, "open" if self.is_open else "closed")


class _NoManager:
    """A USB link takes no Crazyradio."""


_NO_MANAGER = _NoManager()
