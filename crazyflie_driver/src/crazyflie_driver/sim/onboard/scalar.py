"""Float helpers with numpy's semantics, for the per-vehicle (scalar) twins of the world's numpy stages.

With one or a few vehicles, numpy's per-call cost dominates: a step of a controller in Python floats
is several times cheaper than the same step in numpy calls on 3-vectors. The twins must give the
numbers the numpy stages give, so NaN and infinities behave here as they do in numpy (where the
math module would raise).
"""
from __future__ import annotations

import math

NAN = math.nan


def clamp(x: float, lo: float, hi: float) -> float:
    """``np.minimum(np.maximum(x, lo), hi)`` for floats: NaN in any argument gives NaN."""
    y = x if x >= lo else (lo if lo > x else NAN)
    return y if y <= hi else (hi if hi < y else NAN)


def maximum(a: float, b: float) -> float:
    """``np.maximum`` for floats (NaN wins)."""
    return a if a >= b else (b if b > a else NAN)


def safe_sin(x: float) -> float:
    """``np.sin``: NaN for infinities instead of an error."""
    return math.sin(x) if math.isfinite(x) else NAN


def safe_cos(x: float) -> float:
    """``np.cos``: NaN for infinities instead of an error."""
    return math.cos(x) if math.isfinite(x) else NAN
