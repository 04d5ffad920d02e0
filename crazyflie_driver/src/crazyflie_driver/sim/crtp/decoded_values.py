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
_PLAIN = frozenset((float, int))


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


def _field_names(cls: type) -> Tuple[str, ...]:
    """The field names of dataclass ``cls``, read once per class."""
    names = _FIELD_NAMES.get(cls)
    if names is None:
        names = _FIELD_NAMES[cls] = tuple(f.name for f in dataclasses.fields(cls))
    return names


class DecodedValues:
    """Extremes of every numeric field decoded so far (since power-on of the simulation).

    A tuple of plain numbers (a port handler's arguments: an RPYT setpoint is four, 100 times a second)
    is kept as it came and counted with the others of its name and length when ``PENDING_TUPLES`` have
    come or ``summary`` is asked: a column of finite numbers then takes a few builtin calls instead of
    a step per value (one with a NaN or an infinity is walked value by value). Counts and extremes do
    not depend on the order, so the summary is the one of walking every value as it came; anything
    else is walked at once.
    """

    #: Tuples kept before they are counted.
    PENDING_TUPLES = 128

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._fields: Dict[str, List[float]] = {}    # name -> [count, non-finite, min, max]
        self._pending: Dict[Tuple[str, int], List[tuple]] = {}   # (name, length) -> tuples not counted yet
        self._pending_count = 0

    def observe(self, name: str, value: Any) -> None:
        """Record ``value`` (a number, or sequences / arrays / dicts / dataclasses of them) under ``name``."""
        with self._lock:
            if type(value) is not tuple or not _PLAIN.issuperset(map(type, value)):
                self._walk(name, value)      # now: anything that could still change is walked as it is
                return
            rows = self._pending.get((name, len(value)))
            if rows is None:
                rows = self._pending[(name, len(value))] = []
            rows.append(value)
            self._pending_count += 1
            if self._pending_count >= self.PENDING_TUPLES:
                self._count_pending()

    def _count_pending(self) -> None:
        pending, self._pending, self._pending_count = self._pending, {}, 0
        for (name, length), rows in pending.items():
            if length:
                for child, column in zip(_children(name, length), zip(*rows)):
                    if not self._column(child, column):
                        for v in column:
                            self._walk(child, v)

    def _column(self, name: str, column: tuple) -> bool:
        """Count a column of plain numbers at once when all are finite (ints of at most 64 bits, as
        decoded from packets); False, with nothing counted, otherwise."""
        total = sum(column)
        if total - total != 0.0:       # a NaN or an infinity in it (or a sum past the float range)
            return False
        entry = self._fields.get(name)
        if entry is None:
            entry = self._fields[name] = [0, 0, math.inf, -math.inf]
        entry[0] += len(column)
        lo, hi = float(min(column)), float(max(column))
        if lo < entry[2]:
            entry[2] = lo
        if hi > entry[3]:
            entry[3] = hi
        return True

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
        else:
            self._walk_other(name, value)

    def _walk_other(self, name: str, value: Any) -> None:
        """The rarer shapes: other numbers (numpy scalars), subclasses of tuple and list (named
        tuples), arrays, dicts and dataclasses; anything else (bool, None, text) is no number."""
        if isinstance(value, numbers.Real) and not isinstance(value, bool):
            self._add(name, float(value))
        elif isinstance(value, (tuple, list)):
            self._walk_items(name, enumerate(value))
        elif isinstance(value, np.ndarray):
            for i, v in enumerate(value.ravel().tolist()):
                self._add(_child(name, i), float(v))
        elif isinstance(value, dict):
            self._walk_items(name, value.items())
        elif dataclasses.is_dataclass(value) and not isinstance(value, type):
            self._walk_items(name, ((f, getattr(value, f)) for f in _field_names(type(value))))

    def _walk_items(self, name: str, items: Iterable[Tuple[Any, Any]]) -> None:
        for key, v in items:
            self._walk(_child(name, key), v)

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
            self._count_pending()
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
