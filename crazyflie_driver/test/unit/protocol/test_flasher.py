"""The flasher against the simulated Crazyflie's bootloaders, radio packet by radio packet."""
from __future__ import annotations

import struct

import pytest

from crazyflie_driver.crtp import bootloader as bl
from crazyflie_driver.errors import FirmwareImageError
from crazyflie_driver.protocol import flasher
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.sim_doubles import FakeVehicle, drain

ADDR = b"\xe7\xe7\xe7\xe7\x01"


def stm32_image(version: bytes, size: int = 12 * 1024 + 100) -> bytes:
    head = struct.pack("<II", 0x20020000, 0x08004000 + 0x201)
    body = bytes((i * 7) & 0xFF for i in range(size - len(head) - len(version) - 1))
    return head + body + version + b"\x00"


def version_of(cf) -> bytes:
    cf.handle_crtp(b"\xd1\x01")          # platform port, version channel, firmware version
    return [r for r in drain(cf) if r[0] == 0xD1][0][2:]


def test_flash_writes_verifies_and_the_firmware_reports_the_new_version():
    cf = SimulatedCrazyflie(ADDR, FakeVehicle())
    drain(cf)
    assert version_of(cf) == b"2026.08"
    image = stm32_image(b"2026.11")
    sent = []

    def exchange(payload: bytes) -> bytes:
        sent.append(payload)
        return cf.handle_radio_packet(payload)
    result = flasher.flash(exchange, bl.TARGET_STM32, image)
    assert result.pages_written == 13 and result.info.start_page == 16
    assert bytes(cf.bootloader.flash[bl.TARGET_STM32][:len(image)]) == image
    assert sum(p[2] == bl.CMD_WRITE_FLASH for p in sent if p[0] == 0xFF) == 2      # 10 pages, then 3
    assert not cf.in_bootloader and cf.powered
    assert version_of(cf) == b"2026.11"
    cf.reboot()
    assert version_of(cf) == b"2026.11"                                              # flash outlives reboots


def test_a_file_that_is_not_a_firmware_is_refused_before_anything_is_written():
    cf = SimulatedCrazyflie(ADDR, FakeVehicle())
    with pytest.raises(FirmwareImageError, match="does not start like a stm32 firmware"):
        flasher.flash(cf.handle_radio_packet, bl.TARGET_STM32, b"\x89PNG\r\n\x1a\n" + bytes(2000))
    assert not cf.bootloader.written[bl.TARGET_STM32]


def test_the_bootloader_itself_writes_whatever_it_is_given():
    cf = SimulatedCrazyflie(ADDR, FakeVehicle())
    cf.reboot(bootloader=True)
    junk = b"not a firmware".ljust(1024, b"!")
    for offset in range(0, 1024, bl.CHUNK):
        cf.handle_radio_packet(bl.load_buffer(bl.TARGET_STM32, 0, offset, junk[offset:offset + bl.CHUNK]))
    answer = cf.handle_radio_packet(bl.write_flash(bl.TARGET_STM32, 0, 16, 1))
    assert bl.parse_flash_answer(answer, bl.TARGET_STM32) == (True, 0)
    assert bytes(cf.bootloader.flash[bl.TARGET_STM32][:1024]) == junk
