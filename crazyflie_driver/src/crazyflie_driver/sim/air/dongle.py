"""One fake Crazyradio's own state and firmware: its radio settings, its vendor requests, and the
radio packets it hands to the medium.

The vendor requests and their effects follow the dongle firmware (sources in docs/simulation.md,
"The fake Crazyradio"); USB errors are raised as libusb reports them.
"""
from __future__ import annotations

import array
import errno
import threading
from collections import deque
from typing import Deque, Optional

import usb.core

# The dongle's USB identity and vendor requests are shared with the host driver.
from crazyflie_driver.radio.crazyradio import (
    ACK_ENABLE,
    INLINE_HEADER,
    PRODUCT_ID,
    SCAN_CHANNELS,
    SET_CONT_CARRIER,
    SET_DATA_RATE,
    SET_INLINE_MODE,
    SET_RADIO_ADDRESS,
    SET_RADIO_ARC,
    SET_RADIO_ARD,
    SET_RADIO_CHANNEL,
    SET_RADIO_POWER,
)
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.usb_descriptors import PA_MODELS, DongleModel

BOOTLOADER_PRODUCT_ID = 0x0101
# Requests the host driver does not use
SET_PACKET_LOSS_SIMULATION = 0x30
LAUNCH_BOOTLOADER = 0xFF

MAX_SCAN_HITS = 63
VENDOR_REQUEST_LOG = 10000
MAX_RADIO_PAYLOAD = 32          # bytes of one radio packet


def stall(what: str) -> usb.core.USBError:
    return usb.core.USBError("Pipe error (%s)" % what, -9, errno.EPIPE)


def no_device() -> usb.core.USBError:
    return usb.core.USBError("No such device (it may have been disconnected)", -4, errno.ENODEV)


def usb_timeout() -> usb.core.USBTimeoutError:
    return usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)


class FakeDongle:
    """One emulated dongle: its identity and the radio state shared by every handle opened on it."""

    def __init__(self, ident: int, model: DongleModel, serial: str):
        self.ident = ident
        self.model = model
        self.serial = serial
        self.lock = threading.Lock()
        self.unplugged = False
        self.pulled_by_medium = False    # unplugged because the world says so: back when it says so
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
        """The firmware's power-up radio settings."""
        self.channel = 2
        self.address = b"\xe7\xe7\xe7\xe7\xe7"
        self.datarate = 2
        self.power = 3
        self.ard = 0xA0
        self.arc = 3
        self.ack_enabled = True
        self.cont_carrier = False
        self.scan_hits = b""
        self.inline_mode = 0             # Crazyradio 2.0: 0 off, 1 inline, 2 inline with RSSI

    def pulled_out(self) -> None:
        """The medium reported this dongle unplugged (a world fault): it leaves the bus."""
        self.unplugged = True
        self.pulled_by_medium = True

    @property
    def product_id(self) -> int:
        return BOOTLOADER_PRODUCT_ID if self.in_bootloader else PRODUCT_ID

    def __repr__(self) -> str:
        return "<FakeDongle %d %s serial %s>" % (self.ident, self.model.name, self.serial)


class DongleFirmware:
    """What the dongle's firmware does with vendor requests and bulk OUT packets: radio settings,
    channel scans, the packet-loss request, and one radio packet per bulk OUT sent into ``medium``.

    ``clock`` needs ``time()`` and ``sleep(s)``; the time a radio packet takes comes from ``timing``.
    The caller holds the dongle's lock.
    """

    def __init__(self, medium, timing: DongleTiming, clock, fault_request: bool = True) -> None:
        self.medium = medium
        self.timing = timing
        self.clock = clock
        self.fault_request = fault_request

    def vendor_out(self, d: FakeDongle, req: int, wValue: int, wIndex: int, data: bytes) -> int:
        """One vendor OUT request; the bytes taken. A request the firmware does not know stalls."""
        handler = self._VENDOR_OUT.get(req)
        if handler is None or not handler(self, d, wValue, wIndex, data):
            raise stall("unknown vendor request 0x%02X" % req)
        return len(data)

    # Each handler returns False where the firmware treats the request as unknown (it stalls).
    def _set_channel(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        if wValue <= 125:
            d.channel = wValue
        d.inline_mode = 0            # the 2.0 leaves inline mode on channel, address, rate, ack
        return True

    def _set_address(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        if d.model.is_crazyradio_2:
            if len(data) == 5:
                d.address = data
                d.inline_mode = 0
        elif 3 <= len(data) <= 5:
            d.address = data + d.address[len(data):]
        else:
            raise stall("SET_RADIO_ADDRESS with %d bytes" % len(data))
        return True

    def _set_data_rate(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        if wValue < 3:
            d.datarate = wValue
            d.inline_mode = 0
        return True

    def _set_inline_mode(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        if wValue > d.model.inline_modes:
            return False
        d.inline_mode = wValue
        return True

    def _set_power(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        d.power = min(wValue, 3) if d.model.is_crazyradio_2 else wValue & 3
        return True

    def _set_ard(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        if not d.model.is_crazyradio_2:
            d.ard = wValue & 0xFF
        return True

    def _set_arc(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        d.arc = wValue & 0x0F
        return True

    def _ack_enable(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        d.ack_enabled = wValue != 0
        d.inline_mode = 0
        return True

    def _cont_carrier(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        d.cont_carrier = wValue != 0
        return True

    def _scan_channels(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        if not data:
            raise stall("START_SCAN_CHANNELS without a packet")
        self.scan(d, wValue, min(wIndex, 125), data)
        return True

    def _packet_loss(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        if not (d.model.is_crazyradio_2 or self.fault_request):
            return False
        if len(data) != 2 or data[0] > 100 or data[1] > 100:
            raise stall("SET_PACKET_LOSS_SIMULATION needs 2 bytes of percent (0-100)")
        self.medium.set_dongle_faults(d.ident, packet_loss=float(data[0]), ack_loss=float(data[1]))
        return True

    def _launch_bootloader(self, d: FakeDongle, wValue: int, wIndex: int, data: bytes) -> bool:
        d.bootloader_requested = True
        return True

    _VENDOR_OUT = {SET_RADIO_CHANNEL: _set_channel, SET_RADIO_ADDRESS: _set_address, SET_DATA_RATE: _set_data_rate,
                   SET_INLINE_MODE: _set_inline_mode, SET_RADIO_POWER: _set_power, SET_RADIO_ARD: _set_ard,
                   SET_RADIO_ARC: _set_arc, ACK_ENABLE: _ack_enable, SET_CONT_CARRIER: _cont_carrier,
                   SCAN_CHANNELS: _scan_channels, SET_PACKET_LOSS_SIMULATION: _packet_loss,
                   LAUNCH_BOOTLOADER: _launch_bootloader}

    def vendor_in(self, d: FakeDongle, req: int, wValue: int, wIndex: int, data) -> int:
        if req == SCAN_CHANNELS:
            return fill(data, d.scan_hits)
        raise stall("unknown vendor IN request 0x%02X" % req)

    def scan(self, d: FakeDongle, start: int, stop: int, packet: bytes) -> None:
        """Firmware scan: send the packet on start..stop (every 2nd channel at 2M on the PA)."""
        step = 2 if (d.datarate == 2 and d.model in PA_MODELS) else 1
        hits = bytearray()
        spent = 0.0
        channel = start
        for channel in range(start, stop + 1, step):
            if not self.radio_allowed(d, channel):
                continue
            reply = self.medium.transmit(d.ident, channel, d.datarate, d.address,
                                         packet[:MAX_RADIO_PAYLOAD], True, d.arc)
            if reply.unplugged:
                d.pulled_out()
                raise no_device()
            spent += self.air_time(d, reply)
            if reply.acked and len(hits) < MAX_SCAN_HITS:
                hits.append(channel)
        if start <= stop:
            d.channel = channel
        d.scan_hits = bytes(hits)
        if spent:
            self.clock.sleep(spent)

    def radio_allowed(self, d: FakeDongle, channel: int) -> bool:
        if d.model.is_crazyradio_2:
            return d.datarate != 0 and channel <= 100
        return True

    def air_time(self, d: FakeDongle, reply) -> float:
        t = self.timing
        retries = reply.retries if reply.acked else d.arc
        return t.bulk_round_trip_s + retries * t.retransmission_s + reply.latency_s

    def send_packet(self, d: FakeDongle, data, start: float) -> None:
        """One bulk OUT (``data``, an array of at least one byte, sent at ``start``): its radio packet
        on the air, the IN reply left in ``d.reply`` (none when acks are off), ready at ``d.reply_ready_at``."""
        if d.inline_mode:
            self.send_inline(d, data, start)
            return
        packet = data[:MAX_RADIO_PAYLOAD].tobytes() if len(data) > MAX_RADIO_PAYLOAD else data.tobytes()
        if not self.radio_allowed(d, d.channel):
            d.reply = b"\x00"  # Crazyradio 2.0: invalid settings, nothing sent, "no ack"
            d.reply_ready_at = start + self.timing.bulk_round_trip_s
            return
        if not d.ack_enabled:
            self.send_no_ack(d, data, packet)
            return
        reply = self.medium.transmit(d.ident, d.channel, d.datarate, d.address, packet,
                                     d.ack_enabled, d.arc)
        if reply.unplugged:
            d.pulled_out()
            raise no_device()
        if reply.acked:
            payload = reply.payload
            if len(payload) > MAX_RADIO_PAYLOAD:
                payload = payload[:MAX_RADIO_PAYLOAD]
            status = 1 | (0x02 if reply.power_detector else 0) | ((reply.retries & 0x0F) << 4)
            d.reply = bytes((status,)) + payload
        else:
            d.reply = b"\x00"
        d.reply_ready_at = start + self.air_time(d, reply)

    def send_no_ack(self, d: FakeDongle, data, packet: bytes) -> None:
        """A bulk OUT with acks off on the legacy path: no IN reply, no ack wait. The firmware takes the
        next OUT while its radio sends (the PA re-arms its OUT endpoint before sending, the 2.0 queues
        OUTs), so each radio packet holds the dongle for its air time. A PA with the 99.55 image and
        every 2.0 send an OUT longer than 32 bytes as two packets of half its length each."""
        if d.model.splits_long_no_ack and len(data) > MAX_RADIO_PAYLOAD:
            half = len(data) // 2
            packets = [data[:half].tobytes(), data[half:2 * half].tobytes()]
        else:
            packets = [packet]
        busy = 0.0
        for one in packets:
            reply = self.medium.transmit(d.ident, d.channel, d.datarate, d.address, one, False, d.arc)
            if reply.unplugged:
                d.pulled_out()
                raise no_device()
            busy += self.timing.no_ack_packet_s + reply.latency_s
        if busy > 0:
            self.clock.sleep(busy)

    def send_inline(self, d: FakeDongle, data, start: float) -> None:
        """One bulk OUT in the 2.0's inline mode: an 8-byte header [total length, rate | ack << 4,
        channel, 5 address bytes] then the payload. The settings stay in force afterwards, and an
        IN reply [total length, status] (+ the ack's RSSI in mode 2) + ack payload always follows,
        acks on or off; status bit 2 flags settings the radio cannot send (250K, channel > 100)."""
        raw = data.tobytes()
        if len(raw) < INLINE_HEADER:
            raise stall("inline-mode OUT of %d bytes, shorter than its %d-byte header" % (len(raw), INLINE_HEADER))
        end = min(max(raw[0], INLINE_HEADER), len(raw))
        d.datarate = raw[1] & 0x03
        d.ack_enabled = bool(raw[1] & 0x10)
        d.channel = raw[2]
        d.address = raw[3:INLINE_HEADER]
        packet = raw[INLINE_HEADER:end][:MAX_RADIO_PAYLOAD]
        head = 3 if d.inline_mode == 2 else 2
        if not self.radio_allowed(d, d.channel):
            d.reply = bytes((head, 0x04)) + (b"\x00" if head == 3 else b"")
            d.reply_ready_at = start + self.timing.bulk_round_trip_s
            return
        reply = self.medium.transmit(d.ident, d.channel, d.datarate, d.address, packet, d.ack_enabled, d.arc)
        if reply.unplugged:
            d.pulled_out()
            raise no_device()
        status, payload = 0, b""
        if d.ack_enabled and reply.acked:
            payload = reply.payload[:MAX_RADIO_PAYLOAD]
            status = 1 | (0x02 if reply.power_detector else 0) | ((reply.retries & 0x0F) << 4)
        elif d.ack_enabled:
            status = (d.arc & 0x0F) << 4    # the 2.0 reports the retries it spent on a lost packet
        rssi = (b"\x28" if reply.power_detector else b"\x50") if head == 3 else b""
        d.reply = bytes((head + len(payload), status)) + rssi + payload
        busy = self.air_time(d, reply) if d.ack_enabled else self.timing.inline_no_ack_s + reply.latency_s
        d.reply_ready_at = start + busy


def fill(buff, raw: bytes) -> int:
    """Copy an IN data stage into pyusb's buffer in place, as the libusb1 backend does."""
    n = min(len(buff), len(raw))
    if n:
        buff[:n] = array.array("B", raw[:n])
    return n
