"""The EEPROM configuration block on bytes: layout, checksum, versions and the values it refuses."""
from __future__ import annotations

import struct

import pytest

from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.errors import ConfigBlockError

# A block written by hand from the layout: channel 100, 1M, pitch 0.5, roll -2, address E7E7E7E7AB.
BODY = b"0xBC" + bytes([1, 100, 1]) + struct.pack("<ff", 0.5, -2.0) + bytes([0xE7]) + struct.pack("<I", 0xE7E7E7AB)
BLOCK = BODY + bytes([sum(BODY) % 256])


def test_encode_lays_out_the_fields_and_the_byte_sum():
    assert len(BLOCK) == cb.SIZE == 21
    assert cb.encode(cb.ConfigBlock(100, 1, 0.5, -2.0, 0xE7E7E7E7AB)) == BLOCK
    assert cb.decode(BLOCK) == cb.ConfigBlock(100, 1, 0.5, -2.0, 0xE7E7E7E7AB)
    assert cb.decode(BLOCK + b"\xff" * 10).address_bytes == b"\xe7\xe7\xe7\xe7\xab"


def test_version_0_has_no_address_and_decodes_to_the_default_one():
    body = b"0xBC" + bytes([0, 10, 0]) + struct.pack("<ff", 0.0, 0.0)
    assert cb.decode(body + bytes([sum(body) % 256])) == cb.ConfigBlock(10, 0, 0.0, 0.0, cb.DEFAULT_ADDRESS)


@pytest.mark.parametrize("data,words", [
    (b"\xff" * 21, "no configuration block"),
    (b"0xBC\x07" + bytes(16), "version 7"),
    (BLOCK[:20], "needs 21 bytes"),
    (BLOCK[:5] + bytes([101]) + BLOCK[6:], "checksum"),
])
def test_decode_refuses_what_the_firmware_would_replace_by_defaults(data, words):
    with pytest.raises(ConfigBlockError, match=words):
        cb.decode(data)


@pytest.mark.parametrize("block,words", [
    (cb.ConfigBlock(channel=126), "channel 126"),
    (cb.ConfigBlock(datarate=3), "data rate 3"),
    (cb.ConfigBlock(address=1 << 40), "5 bytes"),
    (cb.ConfigBlock(roll_trim=float("nan")), "roll trim"),
])
def test_encode_refuses_values_the_block_cannot_hold(block, words):
    with pytest.raises(ConfigBlockError, match=words):
        cb.encode(block)
