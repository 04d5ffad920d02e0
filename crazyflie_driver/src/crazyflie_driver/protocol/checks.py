"""Argument checks shared by the packet builders: a bad value raises ``CommandValueError``
naming the argument, before anything is sent."""
from __future__ import annotations

import numbers

from crazyflie_driver.crtp.ctypes import ctype
from crazyflie_driver.errors import CommandValueError

_FLOAT32 = ctype("float")

#: Largest value of a signed 16-bit wire field (positions in mm: +-32.767 m).
INT16_MAX = 32767
#: Group masks are one byte: bit i = group i, 0 = every Crazyflie.
GROUP_MASK_MAX = 0xFF


def finite(name: str, value) -> float:
    """``value`` as a float; CommandValueError unless it is a finite real number a 32-bit float holds
    (every such value goes into a float32 field or a narrower one)."""
    try:
        ok = not isinstance(value, bool) and isinstance(value, numbers.Real) and _FLOAT32.holds(float(value))
    except OverflowError:
        ok = False
    if not ok:
        raise CommandValueError("%s must be a finite number within the 32-bit float range (|x| <= %.4g), got %r"
                                % (name, _FLOAT32.high, value))
    return float(value)


def non_negative(name: str, value) -> float:
    """A finite number >= 0 (durations, heights of a landing)."""
    number = finite(name, value)
    if number < 0:
        raise CommandValueError("%s must be >= 0, got %r" % (name, value))
    return number


def positive(name: str, value) -> float:
    """A finite number > 0 (time scales)."""
    number = finite(name, value)
    if number <= 0:
        raise CommandValueError("%s must be > 0, got %r" % (name, value))
    return number


def positive_duration(value) -> float:
    """A command's duration in s, finite and > 0 (a zero-length plan jumps: a land ends at once, in the air)."""
    duration = finite("duration", value)
    if duration <= 0:
        raise CommandValueError("duration must be > 0 s, got %r" % (value,))
    return duration


def milli_int16(name: str, value) -> int:
    """A value in base units as a signed 16-bit count of thousandths (m -> mm), truncated
    towards zero as the reference host libraries do; CommandValueError outside +-32.767."""
    scaled = int(finite(name, value) * 1000.0)
    if not -INT16_MAX <= scaled <= INT16_MAX:
        raise CommandValueError("%s = %r does not fit the wire's 16-bit field (|value| <= %.3f)"
                                % (name, value, INT16_MAX / 1000.0))
    return scaled


def byte(name: str, value) -> int:
    """An unsigned byte 0..255 (identifiers, flags)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 0 <= int(value) <= 0xFF:
        raise CommandValueError("%s must be an integer 0..255, got %r" % (name, value))
    return int(value)


def group_mask(value) -> int:
    """A group mask: 0 (all Crazyflies) or a bit set of groups 0..7."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 0 <= int(value) <= GROUP_MASK_MAX:
        raise CommandValueError("group mask must be an integer 0..%d (0 = all Crazyflies, bit i = group i), "
                                "got %r" % (GROUP_MASK_MAX, value))
    return int(value)
