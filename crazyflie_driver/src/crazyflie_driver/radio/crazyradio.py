"""The Crazyradio dongle over pyusb: vendor requests and bulk transfers, nothing else.

Facts in docs/protocol.md, "The Crazyradio dongle". Channel, address and data rate are cached so that a caller may
set them before every packet and only pay for a control transfer (about 1-2.5 ms) when one changes.
"""
from __future__ import annotations

import array
import errno
from typing import Any, List, NamedTuple, Optional

import usb.core
import usb.util

from crazyflie_driver.errors import CrazyflieError, RadioAccessDenied, RadioInUse, RadioNotFound, RadioUnplugged

VENDOR_ID = 0x1915
PRODUCT_ID = 0x7777

SET_RADIO_CHANNEL = 0x01
SET_RADIO_ADDRESS = 0x02
SET_DATA_RATE = 0x03
SET_RADIO_POWER = 0x04
SET_RADIO_ARD = 0x05
SET_RADIO_ARC = 0x06
ACK_ENABLE = 0x10
SET_CONT_CARRIER = 0x20
SCAN_CHANNELS = 0x21
SET_INLINE_MODE = 0x23

DR_250KPS, DR_1MPS, DR_2MPS = 0, 1, 2
P_M18DBM, P_M12DBM, P_M6DBM, P_0DBM = 0, 1, 2, 3

DEFAULT_ADDRESS = b"\xe7\xe7\xe7\xe7\xe7"
#: Crazyradio PA firmware from which a bulk OUT of 33-64 bytes with acks off goes out as two
#: radio packets of half its length each (the "99.55" image; 0.53 drops the bytes past 32).
TWO_PER_TRANSFER_FROM = 99.55
#: Crazyradio 2.0 firmware versions (all of them: releases from 1.0 on, PA versions being 0.x and
#: 99.x) whose legacy path splits an unacked OUT of more than 32 bytes the same way.
CRAZYRADIO_2_FROM = 1.0
#: The 2.0 waits for more data after an OUT of exactly 64 bytes (its endpoint size), so a pair there
#: stays below it: two packets of at most 31 bytes.
CRAZYRADIO_2_MAX_PAIR = 63
MAX_RADIO_PACKET = 32
#: Crazyradio 2.0 firmware from which SET_INLINE_MODE exists: each bulk OUT then carries its own
#: rate, ack flag, channel and address (docs/protocol.md, "Inline mode"). PA firmware versions are
#: 0.x releases and the 99.x development images, so the range below holds only the 2.0.
INLINE_MODE_FROM = 5.1
INLINE_MODE_BELOW = 99.0
INLINE_MODE_ON = 1
#: Bytes of the inline-mode OUT header: total length, rate | ack << 4, channel, 5 address bytes.
INLINE_HEADER = 8
_INLINE_ACK_BIT = 0x10
_INLINE_INVALID_SETTINGS = 0x04
UDEV_RULES_FILE = "99-crazyradio.rules"
_TYPE_VENDOR_OUT = 0x40
_TYPE_VENDOR_IN = 0xC0
_EP_OUT = 0x01
_EP_IN = 0x81
_NOT_FOUND = ("no Crazyradio found (is it plugged in, and are the udev rules for group plugdev "
              "installed? see crazyflie_driver/udev/README.md)")
_IN_USE = ("Crazyradio %d is in use by another program (%s): one program at a time can use a Crazyradio. Stop the "
           "other one (crazyflie_server, a tool, a client), use another Crazyradio (radio://1/...), or go through "
           "the running crazyflie_server (its parameters are on the ROS parameter server, update_params writes them)")
_GONE_ERRNOS = (errno.ENODEV, errno.EIO, errno.ENOENT, errno.ESHUTDOWN)


class RadioAck(NamedTuple):
    """What came back for one radio packet (docs/protocol.md, "Bulk transfers and the status byte")."""

    ack: bool
    power_detector: bool
    retries: int
    data: bytes


class RadioInfo(NamedTuple):
    """A Crazyradio on the bus, as ``list_radios`` reports it."""

    index: int   # type: ignore[assignment]  # the dongle's number: shadows tuple.index, long public
    serial: Optional[str]   # None when the dongle could not be opened (permissions)
    version: float


def _version_of(bcd: int) -> float:
    """bcdDevice as the float drivers use: 0x0053 -> 0.53, 0x0504 -> 5.4, 0x9955 -> 99.55."""
    return float("%x.%x" % (bcd >> 8, bcd & 0xFF))


def inline_frame(channel: int, datarate: int, address: bytes, data: bytes, ack: bool = True) -> bytes:
    """The bulk OUT of one radio packet in the Crazyradio 2.0's inline mode."""
    return bytes((INLINE_HEADER + len(data), datarate | (_INLINE_ACK_BIT if ack else 0), channel)) + address + data


def parse_inline_reply(reply: bytes, arc: int) -> RadioAck:
    """The IN reply of an inline-mode packet (mode 1: [length, status] + ack payload) as a RadioAck.

    A lost packet or settings the radio cannot send (status bit 2) count as unacked after ``arc`` retries.
    """
    if len(reply) < 2 or not reply[1] & 1 or reply[1] & _INLINE_INVALID_SETTINGS:
        return RadioAck(False, False, arc, b"")
    status = reply[1]
    return RadioAck(True, bool(status & 2), status >> 4, bytes(reply[2:reply[0]]))


class _DeviceBulk:
    """Bulk transfers through pyusb's public ``Device.write``/``read``, shaped as a backend's
    ``bulk_write``/``bulk_read`` (what ``bulk_io`` falls back to)."""

    __slots__ = ("_dev",)

    def __init__(self, dev) -> None:
        self._dev = dev

    def bulk_write(self, handle: Any, ep: int, intf: int, data, timeout: int) -> int:
        return self._dev.write(ep, data, timeout)

    def bulk_read(self, handle: Any, ep: int, intf: int, buff, timeout: int) -> int:
        return self._dev.read(ep, buff, timeout)


def bulk_io(dev) -> tuple:
    """``(backend, handle)`` for the bulk transfers of a configured pyusb device whose interface 0 is
    claimed: ``backend.bulk_write(handle, ep, 0, array, timeout_ms)`` and ``bulk_read`` likewise.

    pyusb's ``Device.write``/``read`` look the interface and endpoint up again, re-check the claim and
    build their dispatch table on every call (about 3 us of host CPU per packet, a fifth of a
    setpoint's cost on the fake dongle) and then make exactly this backend call on the device's open
    handle (pyusb 1.0 to 1.2). Where pyusb keeps the handle elsewhere, the public calls.
    """
    ctx = getattr(dev, "_ctx", None)
    backend, handle = getattr(ctx, "backend", None), getattr(ctx, "handle", None)
    if handle is None or not callable(getattr(backend, "bulk_write", None)) \
            or not callable(getattr(backend, "bulk_read", None)):
        return _DeviceBulk(dev), None
    return backend, handle


def _find(backend) -> list:
    try:
        return list(usb.core.find(idVendor=VENDOR_ID, idProduct=PRODUCT_ID, find_all=True,
                                  backend=backend))
    except usb.core.NoBackendError as exc:
        raise RadioNotFound("no Crazyradio found: pyusb has no USB backend (install libusb-1.0, "
                            "e.g. the libusb-1.0-0 package)") from exc


def _is_access_error(exc: usb.core.USBError) -> bool:
    return exc.errno == errno.EACCES or getattr(exc, "backend_error_code", None) == -3


def _access_denied(index: int, exc: usb.core.USBError) -> RadioAccessDenied:
    return RadioAccessDenied(
        "Crazyradio %d: permission denied opening the USB device (%s). Install the udev rules "
        "shipped in crazyflie_driver/udev/%s into /etc/udev/rules.d/, add yourself to group "
        "plugdev, then re-plug the dongle" % (index, exc.strerror or exc, UDEV_RULES_FILE))


def list_radios(backend=None) -> List[RadioInfo]:
    """Every Crazyradio on the bus, in the order ``Crazyradio(index)`` numbers them.

    ``backend``: the pyusb backend (None: pyusb's default, libusb).
    """
    return [RadioInfo(i, serial_number_of(dev), _version_of(dev.bcdDevice)) for i, dev in enumerate(_find(backend))]


def serial_number_of(dev) -> Optional[str]:
    """A USB device's serial number string, None when it has none or cannot be asked; the device's
    resources are released again (a listing must not keep a device it does not open)."""
    try:
        return dev.serial_number
    except (usb.core.USBError, ValueError):
        return None
    finally:
        usb.util.dispose_resources(dev)


class Crazyradio:
    """The ``index``-th Crazyradio (PA or 2.0) on the bus, configured to the firmware defaults.

    ``backend`` is the pyusb backend to find it with (None: pyusb's default, libusb, i.e. real
    hardware); the entry point chooses it (``crazyflie_driver.usb_choice``). Not thread-safe by
    itself: ``shared_radio.SharedRadio`` serialises access.
    """

    def __init__(self, index: int = 0, backend=None, usb_timeout_ms: int = 1000):
        self.index = index
        self.usb_timeout_ms = usb_timeout_ms
        self.control_transfers = 0
        devices = _find(backend)
        if not devices:
            raise RadioNotFound(_NOT_FOUND)
        if index < 0 or index >= len(devices):
            raise RadioNotFound("no Crazyradio with index %d: %d Crazyradio%s plugged in (indexes start at 0)"
                                % (index, len(devices), " is" if len(devices) == 1 else "s are"))
        self._dev = devices[index]
        for other in devices:
            if other is not self._dev:
                usb.util.dispose_resources(other)
        self.version = _version_of(self._dev.bcdDevice)
        if self.version < 0.4:
            raise CrazyflieError("Crazyradio %d has firmware %.2f; at least 0.4 is needed, please update it"
                                 % (index, self.version))
        self._buffer = array.array("B", bytes(64))
        self._channel = -1
        self._address = b""
        self._datarate = -1
        self.arc = 3
        self.ack_enabled = True
        #: True when the firmware can carry the settings in each packet (Crazyradio 2.0 from 5.1).
        self.inline_capable = INLINE_MODE_FROM <= self.version < INLINE_MODE_BELOW
        self._inline = False    # the firmware leaves inline mode on any channel/address/rate/ack request
        try:
            self._dev.set_configuration(1)
            usb.util.claim_interface(self._dev, 0)
        except usb.core.USBError as exc:
            usb.util.dispose_resources(self._dev)
            if _is_access_error(exc):
                raise _access_denied(index, exc) from exc
            if exc.errno == errno.EBUSY:
                raise RadioInUse(_IN_USE % (index, exc.strerror or exc)) from exc
            raise self._usb_error(exc, "opening") from exc
        self._bulk, self._handle = bulk_io(self._dev)
        # Known state whatever the last user left behind (the order cflib uses, ``cflib/drivers/crazyradio.py``).
        self.set_data_rate(DR_2MPS)
        self.set_channel(2)
        self.set_cont_carrier(False)
        self.set_address(DEFAULT_ADDRESS)
        self.set_power(P_0DBM)
        self.set_arc(3)
        self.set_ard_bytes(32)
        self.set_ack_enable(True)

    # -- identity --------------------------------------------------------------------------------
    @property
    def serial(self) -> str:
        """The dongle's serial number string (10 hex digits on a PA)."""
        try:
            return self._dev.serial_number
        except usb.core.USBError as exc:
            raise self._usb_error(exc, "reading the serial number") from exc

    @property
    def device(self):
        """The pyusb Device (for diagnostics)."""
        return self._dev

    # -- vendor requests ---------------------------------------------------------------------------
    def _control(self, request: int, value: int, index: int = 0, data: bytes = b"") -> None:
        self.control_transfers += 1
        if request in (SET_RADIO_CHANNEL, SET_RADIO_ADDRESS, SET_DATA_RATE, ACK_ENABLE):
            self._inline = False
        try:
            self._dev.ctrl_transfer(_TYPE_VENDOR_OUT, request, value, index, data, self.usb_timeout_ms)
        except usb.core.USBError as exc:
            raise self._usb_error(exc, "vendor request 0x%02X" % request) from exc

    def set_channel(self, channel: int) -> None:
        """Radio channel 0-125 (2400 + channel MHz). Skipped when unchanged."""
        if channel != self._channel:
            if not 0 <= channel <= 125:
                raise ValueError("channel %r out of range 0-125" % (channel,))
            self._control(SET_RADIO_CHANNEL, channel)
            self._channel = channel

    def set_address(self, address: bytes) -> None:
        """5-byte radio address, in URI order. Skipped when unchanged."""
        if address != self._address:
            address = bytes(address)
            if len(address) != 5:
                raise ValueError("radio address must be 5 bytes, got %d" % len(address))
            self._control(SET_RADIO_ADDRESS, 0, 0, address)
            self._address = address

    def set_data_rate(self, datarate: int) -> None:
        """0 = 250 kbit/s, 1 = 1 Mbit/s, 2 = 2 Mbit/s. Skipped when unchanged."""
        if datarate != self._datarate:
            if datarate not in (0, 1, 2):
                raise ValueError("data rate must be 0 (250K), 1 (1M) or 2 (2M), got %r" % (datarate,))
            self._control(SET_DATA_RATE, datarate)
            self._datarate = datarate

    def configure(self, channel: int, datarate: int, address: bytes) -> None:
        """Channel, rate and address for the next packet; control transfers only for what changed."""
        if channel != self._channel:
            self.set_channel(channel)
        if datarate != self._datarate:
            self.set_data_rate(datarate)
        if address != self._address:
            self.set_address(address)

    @property
    def channel(self) -> int:
        return self._channel

    @property
    def address(self) -> bytes:
        return self._address

    @property
    def datarate(self) -> int:
        return self._datarate

    def set_power(self, power: int) -> None:
        """Transmit power 0..3 = -18, -12, -6, 0 dBm."""
        if power not in (0, 1, 2, 3):
            raise ValueError("power must be 0..3 (-18, -12, -6, 0 dBm), got %r" % (power,))
        self._control(SET_RADIO_POWER, power)

    def set_arc(self, arc: int) -> None:
        """Automatic retransmissions (0-15) before a packet counts as unacked."""
        if not 0 <= arc <= 15:
            raise ValueError("ARC must be 0..15, got %r" % (arc,))
        self._control(SET_RADIO_ARC, arc)
        self.arc = arc

    def set_ard_time(self, microseconds: int) -> None:
        """Delay before a retransmission: 250..4000 us in steps of 250 us."""
        n = microseconds // 250 - 1
        if microseconds % 250 or not 0 <= n <= 15:
            raise ValueError("ARD time must be 250..4000 us in steps of 250, got %r" % (microseconds,))
        self._control(SET_RADIO_ARD, n)

    def set_ard_bytes(self, nbytes: int) -> None:
        """Delay before a retransmission, chosen by the firmware for an ack payload of nbytes (0-32)."""
        if not 0 <= nbytes <= 32:
            raise ValueError("ARD ack payload length must be 0..32 bytes, got %r" % (nbytes,))
        self._control(SET_RADIO_ARD, 0x80 | nbytes)

    def set_ack_enable(self, enable: bool) -> None:
        """With acks off, packets go out once as no-ack (broadcast) and nothing comes back."""
        self._control(ACK_ENABLE, 1 if enable else 0)
        self.ack_enabled = bool(enable)

    def set_cont_carrier(self, active: bool) -> None:
        """Continuous carrier test (no packets are sent while it is on)."""
        self._control(SET_CONT_CARRIER, 1 if active else 0)

    def scan_channels(self, start: int, stop: int, packet: bytes = b"\xff") -> List[int]:
        """Firmware scan: channels in start..stop that ack ``packet`` (every 2nd channel at 2M on a PA).

        Leaves the radio on the last scanned channel, so the channel cache is invalidated.
        """
        if not 0 <= start <= 125 or not 0 <= stop <= 125:
            raise ValueError("scan range %r..%r outside 0-125" % (start, stop))
        if not packet:
            raise ValueError("scan packet must not be empty")
        self._control(SCAN_CHANNELS, start, stop, bytes(packet))
        self._channel = -1
        self.control_transfers += 1
        try:
            hits = self._dev.ctrl_transfer(_TYPE_VENDOR_IN, SCAN_CHANNELS, 0, 0, 64, self.usb_timeout_ms)
        except usb.core.USBError as exc:
            raise self._usb_error(exc, "reading scan results") from exc
        # Some hosts see 64 bytes for an empty scan (RF issue #9): keep only plausible channels.
        return [c for c in bytes(hits) if start <= c <= stop]

    def set_inline_mode(self, on: bool) -> None:
        """Switch the Crazyradio 2.0's inline mode (``inline_capable`` only)."""
        if on and not self.inline_capable:
            raise CrazyflieError("Crazyradio %d (firmware %.2f) has no inline mode: it needs a Crazyradio 2.0 with "
                                 "firmware %.1f or later" % (self.index, self.version, INLINE_MODE_FROM))
        self._control(SET_INLINE_MODE, INLINE_MODE_ON if on else 0)
        self._inline = bool(on)

    # -- packets ---------------------------------------------------------------------------------
    def send_inline(self, channel: int, datarate: int, address: bytes, data: bytes, ack: bool = True) -> RadioAck:
        """One radio packet to (channel, datarate, address) in inline mode: no control transfer,
        whatever the previous packet's settings (one SET_INLINE_MODE when the mode was off). With
        ``ack`` false (a broadcast) the radio sends it once without waiting for an ack; the firmware
        still answers each OUT, so the reply is read (and says "not acked")."""
        if self._dev is None:
            raise RadioUnplugged("Crazyradio %d is closed" % self.index)
        if not 0 < len(data) <= MAX_RADIO_PACKET:
            raise ValueError("a radio packet has 1-32 bytes, got %d" % len(data))
        if not self._inline:
            self.set_inline_mode(True)
        bulk, handle, timeout = self._bulk, self._handle, self.usb_timeout_ms
        try:
            bulk.bulk_write(handle, _EP_OUT, 0, array.array("B", inline_frame(channel, datarate, address, data, ack)),
                            timeout)
            # The firmware keeps the packet's settings (and its ack flag) once it has taken the OUT.
            self._channel, self._datarate, self._address, self.ack_enabled = channel, datarate, address, ack
            buf = self._buffer
            n = bulk.bulk_read(handle, _EP_IN, 0, buf, timeout)
        except usb.core.USBTimeoutError:
            return RadioAck(False, False, self.arc, b"")
        except usb.core.USBError as exc:
            raise self._usb_error(exc, "sending a packet") from exc
        return parse_inline_reply(buf[:n].tobytes(), self.arc)

    def send_packet(self, data: bytes) -> RadioAck:
        """One radio packet (1-32 bytes) and its ack. A USB timeout counts as an unacked packet."""
        if self._dev is None:
            raise RadioUnplugged("Crazyradio %d is closed" % self.index)
        if not 0 < len(data) <= 32:
            raise ValueError("a radio packet has 1-32 bytes, got %d" % len(data))
        bulk, handle, timeout = self._bulk, self._handle, self.usb_timeout_ms
        try:
            bulk.bulk_write(handle, _EP_OUT, 0, array.array("B", data), timeout)
            if not self.ack_enabled:
                return _NO_ACK
            buf = self._buffer
            n = bulk.bulk_read(handle, _EP_IN, 0, buf, timeout)
        except usb.core.USBTimeoutError:
            return RadioAck(False, False, self.arc, b"")
        except usb.core.USBError as exc:
            raise self._usb_error(exc, "sending a packet") from exc
        status = buf[0] if n else 0
        if status & 1:
            return RadioAck(True, bool(status & 2), status >> 4, buf[1:n].tobytes())
        return RadioAck(False, False, self.arc, b"")

    @property
    def is_crazyradio_2(self) -> bool:
        return CRAZYRADIO_2_FROM <= self.version < INLINE_MODE_BELOW

    @property
    def two_per_transfer(self) -> bool:
        """True when one no-ack transfer may carry two packets of the same length."""
        return self.version >= TWO_PER_TRANSFER_FROM or self.is_crazyradio_2

    @property
    def max_pair_bytes(self) -> int:
        """Longest no-ack transfer of two packets (0: the firmware sends one packet per transfer)."""
        if not self.two_per_transfer:
            return 0
        return CRAZYRADIO_2_MAX_PAIR if self.is_crazyradio_2 else 2 * MAX_RADIO_PACKET

    @property
    def in_inline_mode(self) -> bool:
        """True while the firmware is in inline mode (a unicast packet went last, inline)."""
        return self._inline

    def send_no_ack(self, data: bytes) -> bool:
        """One no-ack transfer (acks are switched off first if they are on): one packet of 1-32 bytes,
        or, where ``two_per_transfer``, two packets of the same length back to back. Nothing comes
        back; False when the USB write timed out."""
        if self._dev is None:
            raise RadioUnplugged("Crazyradio %d is closed" % self.index)
        n = len(data)
        if not (0 < n <= MAX_RADIO_PACKET or (n <= self.max_pair_bytes and n % 2 == 0)):
            raise ValueError("a no-ack transfer has 1-32 bytes%s, got %d" % (
                " or two packets of equal length" if self.two_per_transfer else "", n))
        if self.ack_enabled:
            self.set_ack_enable(False)
        try:
            self._bulk.bulk_write(self._handle, _EP_OUT, 0, array.array("B", data), self.usb_timeout_ms)
        except usb.core.USBTimeoutError:
            return False
        except usb.core.USBError as exc:
            raise self._usb_error(exc, "sending a broadcast") from exc
        return True

    def close(self) -> None:
        """Release the interface and the handle; the dongle can then be opened again."""
        dev, self._dev = self._dev, None
        if dev is not None:
            try:
                usb.util.dispose_resources(dev)
            except usb.core.USBError:
                pass

    def __enter__(self) -> Crazyradio:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _usb_error(self, exc: usb.core.USBError, what: str) -> CrazyflieError:
        if self._dev is None:
            return RadioUnplugged("Crazyradio %d is closed (%s)" % (self.index, what))
        if exc.errno in _GONE_ERRNOS or getattr(exc, "backend_error_code", None) == -4:
            return RadioUnplugged("Crazyradio %d was unplugged (%s: %s)" % (self.index, what, exc.strerror or exc))
        if _is_access_error(exc):
            return _access_denied(self.index, exc)
        return CrazyflieError("Crazyradio %d: USB error while %s: %s" % (self.index, what, exc))


_NO_ACK = RadioAck(False, False, 0, b"")
