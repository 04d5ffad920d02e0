"""The C types a Crazyflie's parameter and log tables name: one table for host, server and simulator.

Each type carries its wire format (little-endian ``struct`` format), its size, the range of values
it holds, whether it is a floating type, and the codes the two TOCs use for it (the low nibble of
a parameter TOC type byte; the log TOC / log-block "fetch as" code, which only the eight types a
log block can carry have). Types and codes are listed in docs/protocol.md.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Dict, Optional, Union

Number = Union[int, float]


@dataclass(frozen=True)
class CType:
    """One C type as the TOCs and the wire know it."""

    name: str
    fmt: str                    # struct format, little-endian
    is_float: bool
    param_code: int             # parameter TOC type byte, low nibble (flags excluded)
    log_code: Optional[int]     # log TOC type / log block fetch type (1..8); None: not loggable

    @property
    def size(self) -> int:
        """Bytes one value takes on the wire."""
        return struct.calcsize(self.fmt)

    @property
    def low(self) -> Number:
        """Smallest value the type holds (the most negative finite one for floating types)."""
        return -self.high if self.is_float else (-(1 << (8 * self.size - 1)) if self.signed else 0)

    @property
    def high(self) -> Number:
        """Largest value the type holds (the largest finite one for floating types)."""
        if self.is_float:
            return _FLOAT_MAX[self.fmt]
        bits = 8 * self.size
        return (1 << (bits - 1)) - 1 if self.signed else (1 << bits) - 1

    @property
    def signed(self) -> bool:
        return self.is_float or self.fmt[-1].islower()

    def holds(self, value: Number) -> bool:
        """True when ``value`` is a number this type stores without overflow (finite, in range)."""
        if isinstance(value, float) and not math.isfinite(value):
            return False
        return self.low <= value <= self.high

    def pack(self, value: Number) -> bytes:
        return struct.pack(self.fmt, value)

    def unpack(self, data: bytes, offset: int = 0) -> Number:
        return struct.unpack_from(self.fmt, data, offset)[0]


# Largest finite value of each floating format: IEEE half, single and double precision.
_FLOAT_MAX = {"<e": 65504.0, "<f": struct.unpack("<f", b"\xff\xff\x7f\x7f")[0], "<d": 1.7976931348623157e308}

CTYPES: Dict[str, CType] = {c.name: c for c in (
    CType("uint8_t", "<B", False, 0x08, 1),
    CType("uint16_t", "<H", False, 0x09, 2),
    CType("uint32_t", "<I", False, 0x0A, 3),
    CType("uint64_t", "<Q", False, 0x0B, None),
    CType("int8_t", "<b", False, 0x00, 4),
    CType("int16_t", "<h", False, 0x01, 5),
    CType("int32_t", "<i", False, 0x02, 6),
    CType("int64_t", "<q", False, 0x03, None),
    CType("FP16", "<e", True, 0x05, 8),
    CType("float", "<f", True, 0x06, 7),
    CType("double", "<d", True, 0x07, None),
)}
BY_PARAM_CODE: Dict[int, CType] = {c.param_code: c for c in CTYPES.values()}
BY_LOG_CODE: Dict[int, CType] = {c.log_code: c for c in CTYPES.values() if c.log_code is not None}


def ctype(name: str) -> CType:
    """The C type of that name (``"uint8_t"``, ``"float"``...); KeyError for a name no TOC uses."""
    return CTYPES[name]


def type_size(name: str) -> int:
    """Bytes a value of the named C type takes on the wire."""
    return CTYPES[name].size
