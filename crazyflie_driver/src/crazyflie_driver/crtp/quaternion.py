"""The 32-bit "smallest three" quaternion used by full-state setpoints and packed poses.

Bits 31..30: index (x, y, z, w order) of the component with the largest magnitude, which is made
positive (q and -q are the same rotation) and left out. The other three follow in index order,
10 bits each: a sign bit, then the magnitude scaled so that 1/sqrt(2) (the largest the second
largest component of a unit quaternion can be) maps to 511. Shared by host and simulator.
"""
from __future__ import annotations

import math
from typing import Sequence, Tuple

from crazyflie_driver.errors import CommandValueError

_MAG_MAX = (1 << 9) - 1
_SQRT1_2 = math.sqrt(0.5)


def compress_quaternion(q: Sequence[float]) -> int:
    """(qx, qy, qz, qw), normalised first, as the 32-bit wire word."""
    if len(q) != 4:
        raise CommandValueError("a quaternion has 4 components (x, y, z, w), got %d" % len(q))
    values = [float(c) for c in q]
    norm = math.sqrt(sum(c * c for c in values))
    if not math.isfinite(norm) or norm < 1e-9:
        raise CommandValueError("quaternion %r cannot be normalised (zero or not finite)" % (tuple(q),))
    values = [c / norm for c in values]
    largest = max(range(4), key=lambda i: (abs(values[i]), -i))
    negate = values[largest] < 0
    word = largest
    for i, c in enumerate(values):
        if i == largest:
            continue
        sign = int((c < 0) != negate)
        magnitude = int(_MAG_MAX * (abs(c) / _SQRT1_2) + 0.5)
        word = (word << 10) | (sign << 9) | magnitude
    return word


def decompress_quaternion(word: int) -> Tuple[float, float, float, float]:
    """The wire word back to a unit (qx, qy, qz, qw) with the largest component positive."""
    largest = (word >> 30) & 0x3
    q = [0.0, 0.0, 0.0, 0.0]
    squares = 0.0
    for i in range(3, -1, -1):
        if i == largest:
            continue
        magnitude = (word & _MAG_MAX) * _SQRT1_2 / _MAG_MAX
        q[i] = -magnitude if (word >> 9) & 1 else magnitude
        squares += magnitude * magnitude
        word >>= 10
    q[largest] = math.sqrt(max(0.0, 1.0 - squares))
    return q[0], q[1], q[2], q[3]
