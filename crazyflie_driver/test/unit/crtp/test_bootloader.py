"""The bootloader packets byte for byte (the layout cflib's bootloader client sends and parses)."""
from __future__ import annotations

import struct

import pytest

from crazyflie_driver.crtp import bootloader as bl
from crazyflie_driver.errors import FirmwareImageError, ProtocolError

STM = bl.BootInfo(1024, 10, 1024, 16, bytes(range(12)))


def test_requests_are_header_target_command_then_little_endian_fields():
    assert bl.get_info(bl.TARGET_STM32) == b"\xff\xff\x10"
    assert bl.reset_init(bl.TARGET_NRF51) == b"\xff\xfe\xff"
    assert bl.reset(bl.TARGET_NRF51) == b"\xff\xfe\xf0\x01"
    assert bl.reset(bl.TARGET_NRF51, to_firmware=False) == b"\xff\xfe\xf0\x00"
    assert bl.load_buffer(bl.TARGET_STM32, 2, 50, b"\xaa" * 25) == b"\xff\xff\x14\x02\x00\x32\x00" + b"\xaa" * 25
    assert bl.write_flash(bl.TARGET_STM32, 0, 16, 10) == b"\xff\xff\x18\x00\x00\x10\x00\x0a\x00"
    assert bl.read_flash(bl.TARGET_STM32, 300, 25) == b"\xff\xff\x1c\x2c\x01\x19\x00"
    assert bl.flash_status(bl.TARGET_STM32) == b"\xff\xff\x19"
    assert len(bl.load_buffer(bl.TARGET_STM32, 0, 0, bytes(bl.CHUNK))) == 32


def test_bad_requests_are_refused():
    with pytest.raises(ValueError, match="at most 25"):
        bl.load_buffer(bl.TARGET_STM32, 0, 0, bytes(26))
    with pytest.raises(ValueError, match="0xFF \\(stm32\\)"):
        bl.get_info(0x01)


def test_info_round_trip_and_the_offsets_cflib_reads():
    raw = bl.info_answer(bl.TARGET_STM32, STM)
    assert struct.unpack("<BBBHHHH", raw[:11])[3:] == (1024, 10, 1024, 16)
    assert raw[11:23] == bytes(range(12)) and raw[23] == bl.PROTOCOL_CF2
    assert bl.parse_info(raw, bl.TARGET_STM32) == STM
    assert STM.firmware_capacity == 1008 * 1024
    with pytest.raises(ProtocolError):
        bl.parse_info(raw, bl.TARGET_NRF51)


def test_flash_and_data_answers():
    assert bl.parse_flash_answer(bl.flash_answer(bl.TARGET_STM32, bl.CMD_WRITE_FLASH, True, 0),
                                 bl.TARGET_STM32) == (True, 0)
    raw = bl.data_answer(bl.TARGET_STM32, bl.CMD_READ_FLASH, 20, 50, b"xyz")
    assert bl.parse_data_answer(raw, bl.TARGET_STM32, bl.CMD_READ_FLASH, 20, 50) == b"xyz"
    with pytest.raises(ProtocolError, match="page 20 address 75"):
        bl.parse_data_answer(raw, bl.TARGET_STM32, bl.CMD_READ_FLASH, 20, 75)


def test_boot_address_is_b1_then_the_four_bytes_reversed():
    assert bl.boot_address(b"\xff\xfe\xff\x01\x02\x03\x04", bl.TARGET_NRF51) == b"\xb1\x04\x03\x02\x01"


def _image(stack, entry, size=4096):
    return struct.pack("<II", stack, entry) + bytes(size - 8)


def test_image_check_takes_a_vector_table_and_refuses_the_obvious_mistakes():
    bl.check_image(_image(0x20020000, 0x08004001 + 0x200), bl.TARGET_STM32, STM)
    with pytest.raises(FirmwareImageError, match="not a firmware image"):
        bl.check_image(b"", bl.TARGET_STM32, STM)
    with pytest.raises(FirmwareImageError, match="does not start like a stm32 firmware"):
        bl.check_image(b"PK\x03\x04" + bytes(4092), bl.TARGET_STM32, STM)       # a zip file
    with pytest.raises(FirmwareImageError, match="nrf51"):                       # an STM image for the nRF
        bl.check_image(_image(0x20020000, 0x08004201), bl.TARGET_NRF51, bl.BootInfo(1024, 1, 256, 88, bytes(12)))
    with pytest.raises(FirmwareImageError, match="room for"):
        bl.check_image(_image(0x20020000, 0x08004001, 2 * 1024 * 1024), bl.TARGET_STM32, STM)
