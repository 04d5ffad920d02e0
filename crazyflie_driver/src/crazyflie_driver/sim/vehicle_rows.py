"""Per-vehicle state kept as a structure of numpy arrays (one row per vehicle).

Every model of the simulated world (physics, onboard firmware, sensors, battery) keeps its state
this way so that one numpy expression advances all vehicles; adding or removing a vehicle adds or
deletes one row in every array.
"""
from __future__ import annotations

from typing import Any, Dict, Sequence, Tuple, Union

import numpy as np

# A short vector (a position, a polynomial's boundary values) as the models take it: numbers in a
# sequence, numpy scalars among them, or an array.
Vector = Union[Sequence[Union[float, "np.floating[Any]"]], np.ndarray]

class Rows:
    """Named arrays sharing their first axis. Subclasses list ``FIELDS = {name: (tail shape, dtype)}``."""

    FIELDS: Dict[str, Tuple[Tuple[int, ...], Any]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        # The columns are set with setattr, so the type checker sees them only through the
        # subclass's annotations: a field without one would escape it.
        super().__init_subclass__(**kwargs)
        declared = {name for klass in cls.__mro__ for name in getattr(klass, "__annotations__", {})}
        undeclared = sorted(set(cls.FIELDS) - declared)
        if undeclared:
            raise TypeError("%s: declare the field(s) %s as 'name: np.ndarray' beside FIELDS"
                            % (cls.__name__, ", ".join(undeclared)))

    def __init__(self) -> None:
        for name, (tail, dtype) in self.FIELDS.items():
            setattr(self, name, np.zeros((0,) + tuple(tail), dtype=dtype))

    def __len__(self) -> int:
        return int(getattr(self, next(iter(self.FIELDS))).shape[0])

    def append_row(self, **values: Any) -> int:
        """Add one vehicle; fields not given start at zero. Returns its row index."""
        unknown = set(values) - set(self.FIELDS)
        if unknown:
            raise KeyError("unknown state field(s): %s" % ", ".join(sorted(unknown)))
        for name, (tail, dtype) in self.FIELDS.items():
            row = np.zeros((1,) + tuple(tail), dtype=dtype)
            if name in values:
                row[0] = values[name]
            setattr(self, name, np.concatenate([getattr(self, name), row]))
        return len(self) - 1

    def delete_row(self, index: int) -> None:
        for name in self.FIELDS:
            setattr(self, name, np.delete(getattr(self, name), index, axis=0))

    def row(self, index: int) -> Dict[str, Any]:
        """A copy of one vehicle's values (for inspection and tests)."""
        return {name: np.array(getattr(self, name)[index]) for name in self.FIELDS}


# Matrix forms of small functions, so that one numpy product applies them to every row at once.

def quadratic_form(fn, size: int) -> np.ndarray:
    """(size², out) matrix A with fn(q) = (q ⊗ q).ravel() @ A for a function fn homogeneous of degree 2."""
    basis = np.eye(size)
    value = [[None] * size for _ in range(size)]
    for i in range(size):
        for j in range(size):
            if i == j:
                value[i][j] = fn(basis[i])
            else:
                value[i][j] = 0.5 * (fn(basis[i] + basis[j]) - fn(basis[i]) - fn(basis[j]))
    return np.array([value[i][j] for i in range(size) for j in range(size)])


def bilinear_form(fn, size_a: int, size_b: int) -> np.ndarray:
    """(size_a·size_b, out) matrix B with fn(a, b) = (a ⊗ b).ravel() @ B for fn bilinear in a and b."""
    ea, eb = np.eye(size_a), np.eye(size_b)
    return np.array([fn(ea[i], eb[j]) for i in range(size_a) for j in range(size_b)])
