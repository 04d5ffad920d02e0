"""The one C-type table: sizes, ranges, TOC codes, and that every user of a type sees the same one."""
from __future__ import annotations

import math
import struct

import pytest

from crazyflie_driver.crtp.ctypes import BY_LOG_CODE, BY_PARAM_CODE, CTYPES, ctype, type_size


@pytest.mark.parametrize("name, size, low, high", [
    ("uint8_t", 1, 0, 255), ("int8_t", 1, -128, 127), ("uint16_t", 2, 0, 65535), ("int16_t", 2, -32768, 32767),
    ("uint32_t", 4, 0, 2 ** 32 - 1), ("int32_t", 4, -2 ** 31, 2 ** 31 - 1), ("uint64_t", 8, 0, 2 ** 64 - 1),
    ("int64_t", 8, -2 ** 63, 2 ** 63 - 1), ("FP16", 2, -65504.0, 65504.0),
    ("float", 4, -3.4028234663852886e38, 3.4028234663852886e38), ("double", 8, -1.7976931348623157e308,
                                                                     1.7976931348623157e308),
])
def test_size_and_range(name, size, low, high):
    ct = ctype(name)
    assert (ct.size, type_size(name), ct.low, ct.high) == (size, size, low, high)
    assert ct.unpack(ct.pack(low)) == low and ct.unpack(ct.pack(high)) == high
    assert ct.holds(low) and ct.holds(high)
    if ct.is_float:
        assert not ct.holds(math.nan) and not ct.holds(math.inf) and not ct.holds(high * 1.01)
        if name != "double":    # 1.01 times the largest double is already infinity
            with pytest.raises((OverflowError, struct.error)):
                ct.pack(high * 1.01)
    else:
        assert not ct.holds(low - 1) and not ct.holds(high + 1)
        with pytest.raises(struct.error):
            ct.pack(high + 1)


def test_toc_codes_name_each_type_once():
    assert sorted(c.name for c in BY_PARAM_CODE.values()) == sorted(CTYPES)
    # a log block carries the eight types of 4 bytes or less, codes 1..8
    assert sorted(BY_LOG_CODE) == list(range(1, 9))
    assert all(c.size <= 4 for c in BY_LOG_CODE.values())
    assert BY_PARAM_CODE[0x06].name == "float" and BY_LOG_CODE[7].name == "float"


def test_users_share_the_table():
    from crazyflie_driver.sim.crtp import tables
    assert tables.CTYPES is CTYPES and tables.LOG_TYPES is BY_LOG_CODE
    assert all(tables.CTYPES[e.ctype].size for e in tables.LOG_TABLE + tables.PARAM_TABLE)
