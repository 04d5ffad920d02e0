"""One Crazyradio shared by several Crazyflies: ``SharedRadio`` time-slices its round trips,
``RadioManager`` opens one per dongle index for the first link that needs it and closes it when the
last one leaves.

The pyusb backend is injected (``RadioManager(backend=...)``); None means pyusb's own choice (libusb,
real hardware). Which backend a process uses is decided by its entry point (``crazyflie_driver.usb_choice``).
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Dict, Optional, TypeVar

from crazyflie_driver.crtp.packet import is_motor_command
from crazyflie_driver.errors import CrazyflieError, RadioUnplugged
from crazyflie_driver.radio.crazyradio import Crazyradio, RadioAck
from crazyflie_driver.radio.fair_lock import FairLock

_log = logging.getLogger(__name__)
_T = TypeVar("_T")

#: Share of a dongle's time that broadcast bursts leave to waiting unicast round trips however many
#: bursts queue (requests such as parameter writes and trajectory uploads, keep-alives); the radio
#: budget plans the motion-capture rate so that this share stays free (docs/diagnostics.md).
UNICAST_RESERVE = 0.25


class SharedRadio:
    """One Crazyradio shared by every link on it; ``round_trip`` and ``run`` are the only ways to use it.

    When the dongle disappears (``RadioUnplugged``) the dead handle is dropped; later round trips
    try to open the dongle again through ``opener`` (at most every ``reopen_interval`` seconds),
    so a dongle that is plugged back in carries on without restarting anything.
    """

    def __init__(self, index: int, radio: Crazyradio,
                 opener: Optional[Callable[[int], Crazyradio]] = None, reopen_interval: float = 0.5):
        self.index = index
        self.radio: Optional[Crazyradio] = radio
        self.lock = FairLock(capped_share=1.0 - UNICAST_RESERVE)
        self.users = 0
        self._opener = opener
        self._reopen_interval = reopen_interval
        self._next_reopen = 0.0
        self._dropped_at = 0.0

    def round_trip(self, channel: int, datarate: int, address: bytes, data: bytes,
                   background: bool = False) -> RadioAck:
        """Send one packet for the Crazyflie at (channel, datarate, address); returns its ack.

        Setpoints and stops go before the other Crazyflies' waiting polls (see ``is_motor_command``);
        ``background`` ones (idle keep-alives) after every other waiting round trip (FairLock).
        """
        # ``run`` written out for the one use every packet makes of it (no closure, no extra call)
        lock = self.lock
        lock.acquire(True, -1, is_motor_command(data), False, background)
        try:
            radio = self.radio
            if radio is None:
                radio = self._reopen()
            try:
                if radio.inline_capable:
                    return radio.send_inline(channel, datarate, address, data)   # settings travel with it
                if channel != radio._channel or datarate != radio._datarate or address != radio._address:
                    radio.configure(channel, datarate, address)
                if not radio.ack_enabled:
                    radio.set_ack_enable(True)   # a broadcast switched acks off
                return radio.send_packet(data)
            except RadioUnplugged:
                self._drop()
                raise
        finally:
            lock.release()

    def run(self, use: Callable[[Crazyradio], _T], urgent: bool = False, capped: bool = False,
            background: bool = False) -> _T:
        """``use(radio)`` holding the dongle for one turn of the FIFO (a broadcast burst), with the
        unplug handling of ``round_trip``; ``urgent`` turns go before the plain ones, ``capped`` urgent
        ones only while they leave ``UNICAST_RESERVE`` of the dongle's time to waiting plain ones (FairLock)."""
        lock = self.lock
        lock.acquire(urgent=urgent, capped=capped, background=background)
        try:
            radio = self.radio
            if radio is None:
                radio = self._reopen()
            try:
                return use(radio)
            except RadioUnplugged:
                self._drop()
                raise
        finally:
            lock.release()

    def _drop(self) -> None:
        radio, self.radio = self.radio, None
        # wall clock: how often the USB device is looked for again is a matter of the host's kernel
        self._dropped_at = time.monotonic()
        self._next_reopen = self._dropped_at + self._reopen_interval
        if radio is not None:
            try:
                radio.close()
            except Exception:  # the handle is dead anyway
                pass

    def _reopen(self) -> Crazyradio:
        if self._opener is None or time.monotonic() < self._next_reopen:
            raise RadioUnplugged("Crazyradio %d is unplugged" % self.index)
        try:
            self.radio = self._opener(self.index)
        except CrazyflieError as exc:
            self._next_reopen = time.monotonic() + self._reopen_interval
            raise RadioUnplugged("Crazyradio %d is unplugged (%s)" % (self.index, exc)) from exc
        _log.info("Crazyradio %d is back (opened again %.1f s after it went away)", self.index,
                  time.monotonic() - self._dropped_at)
        return self.radio

    def close(self) -> None:
        with self.lock:
            if self.radio is not None:
                self.radio.close()
                self.radio = None


class RadioManager:
    """One ``SharedRadio`` per dongle index, reference counted.

    ``backend`` is the pyusb backend for the dongles (None: pyusb's default, libusb);
    ``radio_factory(index)`` replaces how a dongle is opened altogether; ``usb_factory(index)`` opens a
    Crazyflie on a USB cable (None: ``usb_crazyflie.UsbCrazyflie`` on ``backend``).
    """

    def __init__(self, backend=None, radio_factory: Optional[Callable[[int], Crazyradio]] = None,
                 usb_factory: Optional[Callable[[int], Any]] = None):
        self.backend = backend
        self._factory = radio_factory
        self.usb_factory = usb_factory
        self._lock = threading.Lock()
        self._radios: Dict[int, SharedRadio] = {}

    def acquire(self, index: int) -> SharedRadio:
        """The shared radio for dongle ``index``, opened if nobody uses it yet."""
        with self._lock:
            shared = self._radios.get(index)
            if shared is None:
                shared = SharedRadio(index, self._open(index), opener=self._open)
                self._radios[index] = shared
            shared.users += 1
            return shared

    def _open(self, index: int) -> Crazyradio:
        return self._factory(index) if self._factory else Crazyradio(index, backend=self.backend)

    def release(self, shared: SharedRadio) -> None:
        """One user fewer; the dongle is closed when the last one leaves."""
        with self._lock:
            shared.users -= 1
            if shared.users > 0:
                return
            if self._radios.get(shared.index) is shared:
                del self._radios[shared.index]
        shared.close()

    def users(self, index: int) -> int:
        with self._lock:
            shared = self._radios.get(index)
            return shared.users if shared else 0


_default_manager: Optional[RadioManager] = None
_default_lock = threading.Lock()


def default_manager() -> RadioManager:
    """The process-wide manager on pyusb's default backend, so every Crazyflie of a process shares
    its dongles. Entry points that may fly the simulated world use ``usb_choice.radio_manager()``."""
    global _default_manager
    with _default_lock:
        if _default_manager is None:
            _default_manager = RadioManager()
        return _default_manager
