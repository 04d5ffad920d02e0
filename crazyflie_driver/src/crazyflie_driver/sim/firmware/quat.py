"""The firmware's "smallest three" 32-bit quaternion compression (full-state setpoints, packed poses).

Bits 31..30 name the component with the largest magnitude (order x, y, z, w), which is made
positive and left out; the other three follow in index order, 10 bits each (a sign bit and a 9-bit
magnitude scaled so that 511 means 1/√2), the last index in the lowest bits. See docs/protocol.md.
"""
from __future__ import annotations

import math
from typing import Sequence, Tuple

SMALL_MAX = 1.0 / math.sqrt(2.0)     # largest possible magnitude of a component that is not the largest
MAGNITUDE_MASK = (1 << 9) - 1


def decompress_quat(comp: int) -> Tuple[float, float, float, float]:
    """u32 -> (x, y, z, w), unit length."""
    comp = int(comp) & 0xFFFFFFFF
    largest = comp >> 30
    q = [0.0, 0.0, 0.0, 0.0]
    sum_squares = 0.0
    for i in (3, 2, 1, 0):
        if i == largest:
            continue
        magnitude = comp & MAGNITUDE_MASK
        negative = (comp >> 9) & 1
        comp >>= 10
        value = SMALL_MAX * magnitude / MAGNITUDE_MASK
        q[i] = -value if negative else value
        sum_squares += value * value
    q[largest] = math.sqrt(max(0.0, 1.0 - sum_squares))
    return q[0], q[1], q[2], q[3]


def compress_quat(q: Sequence[float]) -> int:
    """(x, y, z, w) -> u32 (normalised first; q and -q give the same word)."""
    norm = math.sqrt(sum(float(c) * float(c) for c in q))
    if not norm > 0 or not math.isfinite(norm):
        raise ValueError("cannot compress quaternion %r: it has no direction" % (tuple(q),))
    v = [float(c) / norm for c in q]
    largest = max(range(4), key=lambda i: abs(v[i]))
    if v[largest] < 0:
        v = [-c for c in v]
    comp = largest
    for i in range(4):
        if i == largest:
            continue
        magnitude = min(MAGNITUDE_MASK, int(round(abs(v[i]) / SMALL_MAX * MAGNITUDE_MASK)))
        comp = (comp << 10) | ((1 if v[i] < 0 else 0) << 9) | magnitude
    return comp & 0xFFFFFFFF
