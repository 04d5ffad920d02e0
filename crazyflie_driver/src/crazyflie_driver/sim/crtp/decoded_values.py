"""What a simulated Crazyflie decoded, kept as extremes per field: the firmware's side of a test
that feeds bad input through the host and checks that nothing non-finite or out of range got here.

Every value the port handlers hand to the vehicle (RPYT and generic setpoints, external
positions and poses, high-level commands with their trajectory pieces, parameter writes) is
counted under ``<what>.<field>``: how many values, how many were not finite, and the smallest and
largest finite one. Read-only for clients (the world server's ``state`` control call shows it).
"""
from __future__ import annotations

import dataclasses
import math
import numbers
import threading
from typing import Any, Callable, Dict, Iterable, List, Tuple

import numpy as np

_FIELD_NAMES: Dict[type, Tuple[str, ...]] = {}
_CHILD: Dict[Tuple[str, Any], str] = {}
_CHILDREN: Dict[Tuple[str, int], Tuple[str, ...]] = {}


def _children(name: str, count: int) -> Tuple[str, ...]:
    """``name.0`` .. ``name.<count-1>``, built once per pair."""
    try:
        return _CHILDREN[(name, count)]
    except KeyError:
        names = _CHILDREN[(name, count)] = tuple(_child(name, i) for i in range(count))
        return names


def _child(name: str, key: Any) -> str:
    """``name.key``, built once per pair (the same fields come 100 times a second)."""
    try:
        return _CHILD[(name, key)]
    except KeyError:
        text = _CHILD[(name, key)] = "%s.%s" % (name, key)
        return text


class DecodedValues:
    """Extremes of every numeric field decoded so far (since power-on of the simulation)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._fields: Dict[str, List[float]] = {}    # name -> [count, non-finite, min, max]

    def observe(self, name: str, value: Any) -> None:
        """Record ``value`` (a number, or sequences / arrays / dicts / dataclasses of them) under ``name``."""
        with self._lock:
            self._walk(name, value)

    def _walk(self, name: str, value: Any) -> None:
        kind = type(value)
        if kind is float or kind is int:         # exact types first: a setpoint is a tuple of these
            self._add(name, float(value))
        elif kind is tuple or kind is list:
            add, walk = self._add, self._walk
            for child, v in zip(_children(name, len(value)), value):
                kind = type(v)
                if kind is float or kind is int:
                    add(child, float(v))
                else:
                    walk(child, v)
        elif isinstance(value, numbers.Real) and not isinstance(value, bool):
            self._add(name, float(value))
        elif isinstance(value, (tuple, list)):
            for i, v in enumerate(value):
                self._walk(_child(name, i), v)
        elif isinstance(value, np.ndarray):
            for i, v in enumerate(value.ravel().tolist()):
                self._add(_child(name, i), float(v))
        elif isinstance(value, dict):
            for k, v in value.items():
                self._walk(_child(name, k), v)
        elif dataclasses.is_dataclass(value) and not isinstance(value, type):
            names = _FIELD_NAMES.get(type(value))
            if names is None:
                names = _FIELD_NAMES[type(value)] = tuple(f.name for f in dataclasses.fields(value))
            for f in names:
                self._walk(_child(name, f), getattr(value, f))

    def _add(self, name: str, v: float) -> None:
        entry = self._fields.get(name)
        if entry is None:
            entry = self._fields[name] = [0, 0, math.inf, -math.inf]
        entry[0] += 1
        if v - v != 0.0:            # NaN or infinite
            entry[1] += 1
        else:
            if v < entry[2]:
                entry[2] = v
            if v > entry[3]:
                entry[3] = v

    def summary(self) -> Dict[str, Dict[str, Any]]:
        """``{field: {"count", "non_finite", "min", "max"}}`` (min/max over the finite values; None if none)."""
        with self._lock:
            return {name: {"count": int(c), "non_finite": int(n),
                           "min": lo if math.isfinite(lo) else None, "max": hi if math.isfinite(hi) else None}
                    for name, (c, n, lo, hi) in self._fields.items()}


def trajectory_values(pieces_of: Callable[[int], Any], trajectory_ids: Iterable[int]) -> Dict[str, Dict[str, Any]]:
    """Extremes of the pieces (durations and coefficients) of each defined trajectory as the firmware
    reads them from its memory, under ``trajectory <id>.<piece>``."""
    values = DecodedValues()
    for ident in sorted(trajectory_ids):
        pieces = pieces_of(ident)
        if pieces is not None:
            values.observe("trajectory %d" % ident, pieces)
    return values.summary()
