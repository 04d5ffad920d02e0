"""A stand-in joystick device: a FIFO carrying the kernel's js_event records.

Point joy_node's ``~dev`` at ``FakeJoystick.path`` to drive teleop launch files without hardware
(tests, demos in the simulator). Raw values follow the kernel: -32767 is stick fully up / left.
Closing the writer side looks to the reader like an unplugged joystick; ``plug_in`` again
reconnects and replays the initial-state events, as the kernel does on open.
"""
from __future__ import annotations

import errno
import os
import time
from typing import Optional, Sequence

from crazyflie_demo.joystick import JS_EVENT_AXIS, JS_EVENT_BUTTON, JS_EVENT_INIT, pack_event


class FakeJoystick:
    def __init__(self, path: str, axes: int = 8, buttons: int = 11, create: bool = True) -> None:
        self.path = path
        self.axes = [0] * axes
        self.buttons = [0] * buttons
        self._fd: Optional[int] = None
        self._t0 = time.monotonic()       # the kernel's event times: wall clock, as a real device's
        if create and not os.path.exists(path):
            os.mkfifo(path)

    def _time_ms(self) -> int:
        return int((time.monotonic() - self._t0) * 1000)

    @property
    def plugged_in(self) -> bool:
        return self._fd is not None

    def plug_in(self, timeout: float = 5.0, init_events: bool = True) -> None:
        """Open the writer side once a reader has the FIFO open; then send the initial state."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                self._fd = os.open(self.path, os.O_WRONLY | os.O_NONBLOCK)
                break
            except OSError as exc:
                if exc.errno != errno.ENXIO:            # ENXIO: no reader yet
                    raise
                if time.monotonic() > deadline:
                    raise TimeoutError("no reader opened %s within %.1f s" % (self.path, timeout)) from exc
                time.sleep(0.01)
        if init_events:
            self.send_initial_state()

    def send_initial_state(self) -> None:
        data = b"".join(pack_event(self._time_ms(), v, JS_EVENT_BUTTON | JS_EVENT_INIT, i)
                        for i, v in enumerate(self.buttons))
        data += b"".join(pack_event(self._time_ms(), v, JS_EVENT_AXIS | JS_EVENT_INIT, i)
                         for i, v in enumerate(self.axes))
        self.write(data)

    def unplug(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def write(self, data: bytes) -> None:
        if self._fd is None:
            raise RuntimeError("fake joystick %s is not plugged in" % self.path)
        os.write(self._fd, data)

    def move_axis(self, number: int, raw: int) -> None:
        """Raw kernel value -32767..32767 (negative = up / left)."""
        self.axes[number] = raw
        self.write(pack_event(self._time_ms(), raw, JS_EVENT_AXIS, number))

    def move_axes(self, values: Sequence[tuple]) -> None:
        """Several (number, raw) moves written at once, as one burst."""
        data = b""
        for number, raw in values:
            self.axes[number] = raw
            data += pack_event(self._time_ms(), raw, JS_EVENT_AXIS, number)
        self.write(data)

    def set_button(self, number: int, pressed: bool) -> None:
        self.buttons[number] = 1 if pressed else 0
        self.write(pack_event(self._time_ms(), self.buttons[number], JS_EVENT_BUTTON, number))

    def close(self, remove: bool = True) -> None:
        self.unplug()
        if remove:
            try:
                os.unlink(self.path)
            except OSError:
                pass
