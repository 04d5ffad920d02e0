"""A Linux joystick (/dev/input/jsN) read the way the ROS ``joy`` package reads it, without ROS.

The kernel's joystick API delivers 8-byte ``struct js_event`` records: u32 time (ms), s16 value,
u8 type (0x01 button, 0x02 axis, 0x80 or-ed in for the synthetic "initial state" events sent right
after open) and u8 number. This module keeps the state of every axis and button and decides when a
new state should be published, with the joy package's conventions:

* axes are scaled to -1..1 and *negated* (stick up or left gives a positive value), with a
  deadzone around the centre; outside it the value is rescaled so the full range is still reached;
* the value of an initial axis event is not trusted (some drivers report nonsense before the axis
  first moves), so an axis reads 0 until it moves; initial button states are used;
* a button change is published at once, axis changes are coalesced for ``coalesce_interval``;
* with ``autorepeat_rate`` > 0 the last state is repeated at that rate while nothing changes;
* a missing device is retried (once a second by default) with a log message naming the device and
  the usual cause; a device that disappears (unplug, FIFO writer gone) is closed, reported as a
  neutral state (every axis 0, every button released, so a teleop stops commanding), and reopened.
"""
from __future__ import annotations

import errno
import logging
import os
import select
import struct
import time
from dataclasses import dataclass, field
from typing import Callable, Iterator, List, Optional, Tuple

EVENT_FORMAT = "=IhBB"                 # struct js_event in native byte order
EVENT_SIZE = struct.calcsize(EVENT_FORMAT)
JS_EVENT_BUTTON = 0x01
JS_EVENT_AXIS = 0x02
JS_EVENT_INIT = 0x80
AXIS_FULL_SCALE = 32767.0
MAX_DEADZONE = 0.9

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class JsEvent:
    """One ``struct js_event``."""
    time_ms: int
    value: int
    type: int
    number: int

    @property
    def is_init(self) -> bool:
        return bool(self.type & JS_EVENT_INIT)

    @property
    def kind(self) -> int:
        """JS_EVENT_BUTTON or JS_EVENT_AXIS (init flag removed)."""
        return self.type & ~JS_EVENT_INIT


def pack_event(time_ms: int, value: int, type_: int, number: int) -> bytes:
    """The 8 bytes the kernel would deliver for this event (used by tests and fake devices)."""
    return struct.pack(EVENT_FORMAT, time_ms & 0xFFFFFFFF, value, type_, number)


def parse_events(data: bytes) -> Tuple[List[JsEvent], bytes]:
    """Whole events in ``data`` and the bytes left over (a partial event kept for the next read)."""
    whole = len(data) - len(data) % EVENT_SIZE
    events = [JsEvent(*struct.unpack_from(EVENT_FORMAT, data, off)) for off in range(0, whole, EVENT_SIZE)]
    return events, data[whole:]


def clamp_deadzone(deadzone: float) -> float:
    """joy's rule: a negative deadzone counts by its size, and at most 0.9 is allowed."""
    dz = abs(float(deadzone))
    if dz > MAX_DEADZONE:
        log.warning("deadzone %.3f is too large, using %.1f", dz, MAX_DEADZONE)
        dz = MAX_DEADZONE
    return dz


def scale_axis(raw: int, deadzone: float) -> float:
    """Raw s16 axis value -> -1..1, negated, zero inside the deadzone and rescaled outside it."""
    dead_raw = AXIS_FULL_SCALE * deadzone
    if raw > dead_raw:
        value = raw - dead_raw
    elif raw < -dead_raw:
        value = raw + dead_raw
    else:
        return 0.0
    scaled = -value / ((1.0 - deadzone) * AXIS_FULL_SCALE)
    return max(-1.0, min(1.0, scaled))


@dataclass
class JoyState:
    """What a sensor_msgs/Joy carries: axes in -1..1, buttons 0/1."""
    axes: List[float] = field(default_factory=list)
    buttons: List[int] = field(default_factory=list)

    def copy(self) -> JoyState:
        return JoyState(list(self.axes), list(self.buttons))

    def neutral(self) -> JoyState:
        """Same shape, every axis centred and every button released."""
        return JoyState([0.0] * len(self.axes), [0] * len(self.buttons))


PUBLISH_NONE, PUBLISH_SOON, PUBLISH_NOW = 0, 1, 2


class JoystickModel:
    """Axis and button state updated from events; tells how urgently the change must go out."""

    def __init__(self, deadzone: float = 0.05) -> None:
        self.deadzone = clamp_deadzone(deadzone)
        self.state = JoyState()

    def reset(self) -> None:
        self.state = JoyState()

    def apply(self, event: JsEvent) -> int:
        """Update the state; PUBLISH_NOW for a real button change, PUBLISH_SOON otherwise."""
        kind = event.kind
        if kind == JS_EVENT_BUTTON:
            _grow(self.state.buttons, event.number, 0)
            self.state.buttons[event.number] = 1 if event.value else 0
            return PUBLISH_SOON if event.is_init else PUBLISH_NOW
        if kind == JS_EVENT_AXIS:
            _grow(self.state.axes, event.number, 0.0)
            if not event.is_init:          # the initial value is not trusted (see module doc)
                self.state.axes[event.number] = scale_axis(event.value, self.deadzone)
            return PUBLISH_SOON
        return PUBLISH_NONE                # unknown event type: ignored


def _grow(values: list, index: int, fill) -> None:
    if index >= len(values):
        values.extend([fill] * (index + 1 - len(values)))


class DeviceGone(Exception):
    """The device went away while open (unplugged, or the FIFO's writer closed it)."""


class JoystickDevice:
    """The device file, opened non-blocking; reads whole events."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.fd: Optional[int] = None
        self._partial = b""

    def open(self) -> None:
        """Raises OSError (with errno) when the device cannot be opened."""
        self.fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
        self._partial = b""

    def close(self) -> None:
        if self.fd is not None:
            try:
                os.close(self.fd)
            except OSError:
                pass
            self.fd = None

    @property
    def is_open(self) -> bool:
        return self.fd is not None

    def wait_readable(self, timeout: float) -> bool:
        if self.fd is None:
            return False
        readable, _, _ = select.select([self.fd], [], [], max(0.0, timeout))
        return bool(readable)

    def read_events(self) -> List[JsEvent]:
        """Every event available now; raises DeviceGone on end of file or a device error."""
        assert self.fd is not None
        data = b""
        while True:
            try:
                chunk = os.read(self.fd, EVENT_SIZE * 64)
            except BlockingIOError:
                break
            except OSError as exc:
                raise DeviceGone("%s: %s" % (self.path, os.strerror(exc.errno or errno.EIO))) from exc
            if not chunk:
                if data:
                    break                  # deliver what came before the end; report it next time
                raise DeviceGone("%s: end of file (device closed)" % self.path)
            data += chunk
        events, self._partial = parse_events(self._partial + data)
        return events


def open_failure_message(path: str, exc: OSError) -> str:
    """Why the device could not be opened and what to do about it."""
    if exc.errno == errno.ENOENT:
        cause = "no such device (is the joystick plugged in? `ls /dev/input/js*` lists joysticks)"
    elif exc.errno in (errno.EACCES, errno.EPERM):
        cause = ("permission denied (add yourself to the `input` group: "
                 "`sudo usermod -aG input $USER`, then log in again)")
    else:
        cause = os.strerror(exc.errno or errno.EIO)
    return "cannot open joystick %s: %s" % (path, cause)


class Joystick:
    """Reads one joystick and says when a Joy message is due; no thread, the caller polls.

    ``poll(timeout)`` waits at most ``timeout`` seconds and returns the state to publish, or None.
    A device's timing (waits on its file, autorepeat, reopen attempts) is on the wall clock, as the
    kernel's; the messages are stamped with ROS time by the node.
    """

    def __init__(self, dev: str = "/dev/input/js0", deadzone: float = 0.05,
                 autorepeat_rate: float = 0.0, coalesce_interval: float = 0.001,
                 retry_interval: float = 1.0, clock: Callable[[], float] = time.monotonic,
                 logger: Optional[logging.Logger] = None) -> None:
        if autorepeat_rate < 0:
            raise ValueError("autorepeat_rate must be >= 0 (0 disables it), got %r" % autorepeat_rate)
        if coalesce_interval < 0:
            raise ValueError("coalesce_interval must be >= 0 seconds, got %r" % coalesce_interval)
        if retry_interval <= 0:
            raise ValueError("retry_interval must be > 0 seconds, got %r" % retry_interval)
        self.device = JoystickDevice(dev)
        self.model = JoystickModel(deadzone)
        self.autorepeat_rate = float(autorepeat_rate)
        self.autorepeat_interval = 1.0 / autorepeat_rate if autorepeat_rate > 0 else None
        self.coalesce_interval = float(coalesce_interval)
        self.retry_interval = float(retry_interval)
        self._clock = clock
        self._log = logger or log
        self._next_open_attempt = 0.0
        self._pending_since: Optional[float] = None   # when the first unpublished axis change came
        self._last_publish: Optional[float] = None
        self._last_open_error: Optional[str] = None
        self.opens = 0                                # successful opens (reopen count + 1)
        self.events = 0

    @property
    def dev(self) -> str:
        return self.device.path

    @property
    def deadzone(self) -> float:
        return self.model.deadzone

    @property
    def is_open(self) -> bool:
        return self.device.is_open

    def close(self) -> None:
        self.device.close()

    def _try_open(self, now: float) -> bool:
        if now < self._next_open_attempt:
            return False
        try:
            self.device.open()
        except OSError as exc:
            self._next_open_attempt = now + self.retry_interval
            message = open_failure_message(self.dev, exc)
            if message != self._last_open_error:      # say it once, not every second
                self._log.error("%s; retrying every %.1f s", message, self.retry_interval)
                self._last_open_error = message
            return False
        self._last_open_error = None
        self.opens += 1
        self.model.reset()
        self._pending_since = None
        self._log.info("opened joystick %s (deadzone %.3f)", self.dev, self.deadzone)
        return True

    def _deadline(self, now: float, timeout: float) -> float:
        deadline = now + timeout
        if self._pending_since is not None:
            deadline = min(deadline, self._pending_since + self.coalesce_interval)
        if self.autorepeat_interval is not None and self._last_publish is not None:
            deadline = min(deadline, self._last_publish + self.autorepeat_interval)
        return deadline

    def _publish(self, now: float, state: JoyState) -> JoyState:
        self._pending_since = None
        self._last_publish = now
        return state.copy()

    def poll(self, timeout: float = 0.1) -> Optional[JoyState]:
        """Wait up to ``timeout`` s for events; the state to publish now, or None."""
        now = self._clock()
        if not self.device.is_open and not self._try_open(now):
            self._wait_to_reopen(now, timeout)
            return None
        deadline = self._deadline(now, timeout)
        if self.device.wait_readable(deadline - now):
            try:
                events = self.device.read_events()
            except DeviceGone as exc:
                return self._lost(exc)
            state = self._take_events(events)
            if state is not None:
                return state
        return self._due_state(self._clock())

    def _wait_to_reopen(self, now: float, timeout: float) -> None:
        """Sleeps until the next open attempt, at most ``timeout`` s."""
        wait = min(timeout, max(0.0, self._next_open_attempt - now))
        if wait > 0:
            time.sleep(wait)

    def _take_events(self, events: List[JsEvent]) -> Optional[JoyState]:
        """Applies ``events``; the state to publish at once (a button, or no coalescing), or None."""
        urgency = PUBLISH_NONE
        for event in events:
            self.events += 1
            urgency = max(urgency, self.model.apply(event))
        now = self._clock()
        if urgency == PUBLISH_NOW:
            return self._publish(now, self.model.state)
        if urgency == PUBLISH_SOON and self._pending_since is None:
            self._pending_since = now
            if self.coalesce_interval <= 0:
                return self._publish(now, self.model.state)
        return None

    def _due_state(self, now: float) -> Optional[JoyState]:
        """The state whose time has come: coalesced axis changes, or the autorepeat; else None."""
        if self._pending_since is not None and now >= self._pending_since + self.coalesce_interval:
            return self._publish(now, self.model.state)
        if (self.autorepeat_interval is not None and self._last_publish is not None
                and now >= self._last_publish + self.autorepeat_interval):
            return self._publish(now, self.model.state)
        return None

    def _lost(self, exc: DeviceGone) -> JoyState:
        self._log.warning("joystick %s lost (%s); reopening", self.dev, exc)
        neutral = self.model.state.neutral()
        self.device.close()
        self.model.reset()
        self._next_open_attempt = self._clock() + min(self.retry_interval, 0.1)
        return self._publish(self._clock(), neutral)

    def states(self, timeout: float = 0.1, should_stop: Callable[[], bool] = lambda: False
               ) -> Iterator[JoyState]:
        """Every state to publish until ``should_stop()`` is true (checked at least every timeout)."""
        while not should_stop():
            state = self.poll(timeout)
            if state is not None:
                yield state
