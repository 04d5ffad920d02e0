"""A ROS parameter value made fit for a Crazyflie parameter of a given C type.

ROS parameters arrive as bool, int, float or text; ``update_params`` must refuse a value the
parameter cannot hold (a fraction for an integer, a number out of range) with a message naming
the parameter, instead of letting it be truncated on the wire.
"""
from __future__ import annotations

import math
from typing import Any

_INTEGER_CTYPES = frozenset(("uint8_t", "int8_t", "uint16_t", "int16_t", "uint32_t", "int32_t",
                             "uint64_t", "int64_t"))


def coerce_param_value(name: str, ctype: str, value: Any) -> Any:
    """A ROS parameter value converted to the Crazyflie parameter's type.

    bool -> 0/1, numeric strings are parsed; integer types refuse fractions and out-of-range
    values. Raises ValueError naming the parameter.
    """
    if isinstance(value, bool):
        value = int(value)
    elif isinstance(value, str):
        text = value.strip()
        try:
            value = int(text, 0)
        except ValueError:
            try:
                value = float(text)
            except ValueError:
                raise ValueError("parameter %s: value %r is not a number" % (name, value)) from None
    if not isinstance(value, (int, float)):
        raise ValueError("parameter %s: value %r of type %s is not a number"
                         % (name, value, type(value).__name__))
    if ctype in _INTEGER_CTYPES:
        if isinstance(value, float):
            if not math.isfinite(value) or value != int(value):
                raise ValueError("parameter %s is %s: value %r is not a whole number"
                                 % (name, ctype, value))
            value = int(value)
        bits = int("".join(c for c in ctype if c.isdigit()))
        lo, hi = (0, 2 ** bits - 1) if ctype.startswith("u") else (-2 ** (bits - 1), 2 ** (bits - 1) - 1)
        if not lo <= value <= hi:
            raise ValueError("parameter %s is %s: value %d is outside %d..%d" % (name, ctype, value, lo, hi))
        return value
    return float(value)
