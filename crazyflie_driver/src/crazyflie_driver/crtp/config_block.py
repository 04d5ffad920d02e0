"""The EEPROM configuration block of a Crazyflie 2.x: its layout, checksum, defaults and codec.

The block sits at address 0 of the EEPROM memory (memory type 0x00, 8192 bytes on a Crazyflie
2.x). Version 1, 21 bytes, little endian, packed (docs/protocol.md, "Memories"):

| offset | field | type |
|--------|-------|------|
| 0 | magic "0xBC" | 4 ASCII bytes |
| 4 | version (1) | u8 |
| 5 | radio channel | u8 (0..125) |
| 6 | radio data rate | u8 (0 250K, 1 1M, 2 2M) |
| 7 | pitch trim | f32 (degrees) |
| 11 | roll trim | f32 (degrees) |
| 15 | radio address, upper byte | u8 |
| 16 | radio address, lower 4 bytes | u32 |
| 20 | checksum: sum of bytes 0..19 modulo 256 | u8 |

Version 0 (older Crazyflies) stops after the roll trim (checksum at offset 15, no address). The
firmware reads the block at boot and falls back to the defaults when the magic, version or checksum
is wrong, so radio settings written here take effect at the next boot.
"""
from __future__ import annotations

import struct
from typing import NamedTuple

from crazyflie_driver.crtp.uri import DATARATE_NAMES
from crazyflie_driver.errors import ConfigBlockError

MAGIC = b"0xBC"
VERSION = 1
#: Memory type of the EEPROM (port 4 memory details).
MEMORY_TYPE_EEPROM = 0x00
#: Bytes of the EEPROM of a Crazyflie 2.x (a 64 kbit I2C part).
EEPROM_SIZE = 8192
_V1 = struct.Struct("<4sBBBffBI")
_V0 = struct.Struct("<4sBBBff")
#: Bytes of a version 1 block, checksum included.
SIZE = _V1.size + 1
SIZE_V0 = _V0.size + 1
MAX_CHANNEL = 125
DATARATES = dict(enumerate(DATARATE_NAMES))
#: Factory settings: channel 80, 2 Mbit/s, address 0xE7E7E7E7E7, no trims.
DEFAULT_CHANNEL = 80
DEFAULT_DATARATE = 2
DEFAULT_ADDRESS = 0xE7E7E7E7E7
MAX_ADDRESS = 0xFFFFFFFFFF


class ConfigBlock(NamedTuple):
    """The decoded configuration (address as a 40-bit integer, trims in degrees)."""

    channel: int = DEFAULT_CHANNEL
    datarate: int = DEFAULT_DATARATE
    pitch_trim: float = 0.0
    roll_trim: float = 0.0
    address: int = DEFAULT_ADDRESS

    @property
    def address_bytes(self) -> bytes:
        """The radio address as the 5 bytes a radio URI names (most significant first)."""
        return self.address.to_bytes(5, "big")


def checksum(data: bytes) -> int:
    """Sum of the bytes modulo 256 (the block's last byte)."""
    return sum(bytearray(data)) & 0xFF


def check(block: ConfigBlock) -> None:
    """ConfigBlockError, naming the field and its range, for values the block cannot hold."""
    if not 0 <= block.channel <= MAX_CHANNEL:
        raise ConfigBlockError("radio channel %d is out of range: use 0..%d" % (block.channel, MAX_CHANNEL))
    if block.datarate not in DATARATES:
        raise ConfigBlockError("radio data rate %d is unknown: use 0 (250K), 1 (1M) or 2 (2M)" % block.datarate)
    if not 0 <= block.address <= MAX_ADDRESS:
        raise ConfigBlockError("radio address 0x%X does not fit 5 bytes: use 0..0xFFFFFFFFFF" % block.address)
    for name, value in (("pitch", block.pitch_trim), ("roll", block.roll_trim)):
        if value != value or abs(value) == float("inf"):
            raise ConfigBlockError("%s trim %r is not a finite number of degrees" % (name, value))


def encode(block: ConfigBlock) -> bytes:
    """The 21 bytes of a version 1 block, checksum included."""
    check(block)
    body = _V1.pack(MAGIC, VERSION, block.channel, block.datarate, block.pitch_trim, block.roll_trim,
                    block.address >> 32, block.address & 0xFFFFFFFF)
    return body + bytes([checksum(body)])


def decode(data: bytes) -> ConfigBlock:
    """The configuration in the first bytes of the EEPROM; ConfigBlockError when the magic, version or
    checksum is wrong (the firmware then runs on the defaults)."""
    data = bytes(data)
    if data[:4] != MAGIC:
        raise ConfigBlockError("no configuration block: the EEPROM starts with %s, not %s"
                               % (data[:4].hex(" "), MAGIC.hex(" ")))
    version = data[4] if len(data) > 4 else -1
    size = {0: SIZE_V0, 1: SIZE}.get(version)
    if size is None:
        raise ConfigBlockError("configuration block version %d is unknown (0 and 1 exist)" % version)
    if len(data) < size:
        raise ConfigBlockError("configuration block version %d needs %d bytes, got %d" % (version, size, len(data)))
    if checksum(data[:size - 1]) != data[size - 1]:
        raise ConfigBlockError("configuration block checksum 0x%02X does not match its bytes (0x%02X)"
                               % (data[size - 1], checksum(data[:size - 1])))
    if version == 0:
        _, _, channel, rate, pitch, roll = _V0.unpack_from(data)
        return ConfigBlock(channel, rate, pitch, roll, DEFAULT_ADDRESS)
    _, _, channel, rate, pitch, roll, upper, lower = _V1.unpack_from(data)
    return ConfigBlock(channel, rate, pitch, roll, upper << 32 | lower)


def parse_datarate(text: str) -> int:
    """``"250K"``/``"1M"``/``"2M"`` (any case) -> the block's code 0/1/2."""
    names = [n.upper() for n in DATARATE_NAMES]
    if str(text).strip().upper() not in names:
        raise ConfigBlockError("radio data rate %r is unknown: use one of %s" % (text, ", ".join(DATARATE_NAMES)))
    return names.index(str(text).strip().upper())


def parse_address(text: str) -> int:
    """10 hex digits (``E7E7E7E7E7``, optional 0x) -> the 40-bit address."""
    digits = str(text).strip()
    digits = digits[2:] if digits.lower().startswith("0x") else digits
    try:
        if len(digits) != 10:
            raise ValueError
        return int(digits, 16)
    except ValueError:
        raise ConfigBlockError("radio address %r is not 10 hex digits such as E7E7E7E7E7" % text) from None


def describe(block: ConfigBlock) -> str:
    """One line for people: every field with its unit."""
    return ("channel %d, data rate %s, address %s, pitch trim %g, roll trim %g"
            % (block.channel, DATARATES.get(block.datarate, str(block.datarate)),
               block.address_bytes.hex().upper(), block.pitch_trim, block.roll_trim))
