"""The Crazyflie 2.x bootloaders' radio protocol: pure builders and parsers (docs/bootloader.md).

Both bootloaders (the STM32's and the nRF51's) take packets whose header byte is ``0xFF`` (port 15,
channel 3); the first payload byte names the target chip, the second the command. Packets run to the
radio's full 31 payload bytes, so they are built as raw radio payloads (header included), not as
30-byte CRTP packets. Data moves in chunks of ``CHUNK`` bytes: into a RAM page buffer
(LOAD_BUFFER), from the buffer to flash (WRITE_FLASH), back out of flash (READ_FLASH).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Tuple

from crazyflie_driver.errors import FirmwareImageError, ProtocolError

#: Header byte of every bootloader packet (port 15, channel 3).
BOOT_HEADER = 0xFF
TARGET_STM32 = 0xFF
TARGET_NRF51 = 0xFE
TARGETS = {"stm32": TARGET_STM32, "nrf51": TARGET_NRF51}

CMD_GET_INFO = 0x10
CMD_SET_ADDRESS = 0x11
CMD_GET_MAPPING = 0x12
CMD_LOAD_BUFFER = 0x14
CMD_READ_BUFFER = 0x15
CMD_WRITE_FLASH = 0x18
CMD_FLASH_STATUS = 0x19
CMD_READ_FLASH = 0x1C
CMD_RESET_INIT = 0xFF
CMD_RESET = 0xF0
RESET_TO_BOOTLOADER = 0x00
RESET_TO_FIRMWARE = 0x01

#: Image bytes per LOAD_BUFFER / READ_FLASH packet: 31 payload bytes minus 6 of addressing.
CHUNK = 25
#: Bootloader protocol version of the Crazyflie 2.x bootloaders (byte 22 of GET_INFO's answer).
PROTOCOL_CF2 = 0x10
#: Radio channel and address prefix a bootloader listens on after a warm reboot: channel 0, 2 Mbit/s,
#: address 0xB1 followed by four bytes the RESET_INIT answer gives (little-endian on the wire).
BOOT_CHANNEL = 0
BOOT_ADDRESS_PREFIX = 0xB1
#: Channel and address of a bootloader started cold (button held at power-on).
COLD_BOOT_CHANNELS = (110, 0)
COLD_BOOT_ADDRESS = b"\xe7" * 5

_ADDR = struct.Struct("<BBBHH")       # header, target, command, page, address


@dataclass(frozen=True)
class BootInfo:
    """What GET_INFO reports of one target chip: flash geometry in pages and its CPU id."""

    page_size: int          # bytes per flash page
    buffer_pages: int       # pages of RAM buffer LOAD_BUFFER fills
    flash_pages: int        # pages of flash in all
    start_page: int         # first page the firmware may occupy (below it: the bootloader)
    cpu_id: bytes           # 12 bytes
    protocol: int = PROTOCOL_CF2

    @property
    def firmware_capacity(self) -> int:
        """Bytes available to a firmware image."""
        return (self.flash_pages - self.start_page) * self.page_size


def _check_target(target: int) -> None:
    if target not in (TARGET_STM32, TARGET_NRF51):
        raise ValueError("bootloader target must be 0xFF (stm32) or 0xFE (nrf51), got 0x%02X" % target)


def command(target: int, cmd: int, body: bytes = b"") -> bytes:
    _check_target(target)
    packet = bytes((BOOT_HEADER, target, cmd)) + bytes(body)
    if len(packet) > 32:
        raise ValueError("bootloader packet of %d bytes exceeds the radio's 32" % len(packet))
    return packet


def get_info(target: int) -> bytes:
    return command(target, CMD_GET_INFO)


def reset_init(target: int) -> bytes:
    return command(target, CMD_RESET_INIT)


def reset(target: int, to_firmware: bool = True) -> bytes:
    return command(target, CMD_RESET, bytes((RESET_TO_FIRMWARE if to_firmware else RESET_TO_BOOTLOADER,)))


def load_buffer(target: int, page: int, address: int, data: bytes) -> bytes:
    """Put ``data`` (at most CHUNK bytes) into buffer page ``page`` at byte ``address``."""
    if len(data) > CHUNK:
        raise ValueError("LOAD_BUFFER carries at most %d bytes, got %d" % (CHUNK, len(data)))
    return command(target, CMD_LOAD_BUFFER, struct.pack("<HH", page, address) + bytes(data))


def read_buffer(target: int, page: int, address: int) -> bytes:
    return command(target, CMD_READ_BUFFER, struct.pack("<HH", page, address))


def write_flash(target: int, buffer_page: int, flash_page: int, n_pages: int) -> bytes:
    """Copy ``n_pages`` buffer pages from ``buffer_page`` to flash from ``flash_page`` on."""
    return command(target, CMD_WRITE_FLASH, struct.pack("<HHH", buffer_page, flash_page, n_pages))


def flash_status(target: int) -> bytes:
    return command(target, CMD_FLASH_STATUS)


def read_flash(target: int, page: int, address: int) -> bytes:
    return command(target, CMD_READ_FLASH, struct.pack("<HH", page, address))


# --- answers ----------------------------------------------------------------------------------------
def is_answer(raw: bytes, target: int, cmd: int) -> bool:
    """True when ``raw`` (a radio payload, header first) answers ``cmd`` of ``target``."""
    return len(raw) >= 3 and raw[0] == BOOT_HEADER and raw[1] == target and raw[2] == cmd


def info_answer(target: int, info: BootInfo) -> bytes:
    """GET_INFO's answer (the bootloader's side)."""
    if len(info.cpu_id) != 12:
        raise ValueError("a CPU id is 12 bytes, got %d" % len(info.cpu_id))
    return command(target, CMD_GET_INFO, struct.pack("<HHHH", info.page_size, info.buffer_pages,
                                                     info.flash_pages, info.start_page)
                   + bytes(info.cpu_id) + bytes((info.protocol,)))


def parse_info(raw: bytes, target: int) -> BootInfo:
    if not is_answer(raw, target, CMD_GET_INFO) or len(raw) < 3 + 8 + 12:
        raise ProtocolError("not a GET_INFO answer of target 0x%02X: %s" % (target, bytes(raw).hex()))
    page_size, buffer_pages, flash_pages, start_page = struct.unpack_from("<HHHH", raw, 3)
    protocol = raw[23] if len(raw) > 23 else 0xFF
    return BootInfo(page_size, buffer_pages, flash_pages, start_page, bytes(raw[11:23]), protocol)


def flash_answer(target: int, cmd: int, done: bool, error: int) -> bytes:
    """WRITE_FLASH's or FLASH_STATUS's answer: done flag and error code (0: none)."""
    return command(target, cmd, bytes((1 if done else 0, error & 0xFF)))


def parse_flash_answer(raw: bytes, target: int, cmd: int = CMD_WRITE_FLASH) -> Tuple[bool, int]:
    if not is_answer(raw, target, cmd) or len(raw) < 5:
        raise ProtocolError("not a flash answer (0x%02X) of target 0x%02X: %s" % (cmd, target, bytes(raw).hex()))
    return raw[3] == 1, raw[4]


def data_answer(target: int, cmd: int, page: int, address: int, data: bytes) -> bytes:
    """READ_FLASH's or READ_BUFFER's answer: the request's addressing, then the bytes."""
    return command(target, cmd, struct.pack("<HH", page, address) + bytes(data[:CHUNK]))


def parse_data_answer(raw: bytes, target: int, cmd: int, page: int, address: int) -> bytes:
    if (not is_answer(raw, target, cmd) or len(raw) < _ADDR.size
            or _ADDR.unpack_from(raw)[3:] != (page, address)):
        raise ProtocolError("not the answer for page %d address %d: %s" % (page, address, bytes(raw).hex()))
    return bytes(raw[_ADDR.size:])


def boot_address(reset_init_answer: bytes, target: int) -> bytes:
    """The 5-byte radio address the bootloader will listen on, from the RESET_INIT answer."""
    if not is_answer(reset_init_answer, target, CMD_RESET_INIT) or len(reset_init_answer) < 7:
        raise ProtocolError("not a RESET_INIT answer: %s" % bytes(reset_init_answer).hex())
    return bytes((BOOT_ADDRESS_PREFIX,)) + bytes(reset_init_answer[3:7][::-1])


# --- images -------------------------------------------------------------------------------------------
#: Where each chip maps its flash and RAM (Cortex-M: word 0 of an image is the initial stack pointer,
#: in RAM; word 1 the reset handler, an odd (Thumb) address inside the image).
FLASH_BASE = {TARGET_STM32: 0x08000000, TARGET_NRF51: 0x00000000}
RAM_RANGE = {TARGET_STM32: (0x20000000, 0x20020000), TARGET_NRF51: (0x20000000, 0x20008000)}


def check_image(image: bytes, target: int, info: BootInfo) -> None:
    """Refuse what is obviously not a firmware image for ``target``: empty, too big for its flash, or
    no Cortex-M vector table at the start whose stack is in the chip's RAM and whose reset handler is
    a Thumb address inside the image where the bootloader would place it."""
    name = "stm32" if target == TARGET_STM32 else "nrf51"
    if len(image) < 8:
        raise FirmwareImageError("the file has %d bytes: not a firmware image; give the .bin of the %s firmware"
                                 % (len(image), name))
    if len(image) > info.firmware_capacity:
        raise FirmwareImageError("the image has %d bytes but the %s has room for %d: wrong file or target?"
                                 % (len(image), name, info.firmware_capacity))
    stack, entry = struct.unpack_from("<II", image)
    low, high = RAM_RANGE[target]
    start = FLASH_BASE[target] + info.start_page * info.page_size
    if not (low < stack <= high and entry & 1 and start <= entry - 1 < start + len(image)):
        raise FirmwareImageError(
            "the file does not start like a %s firmware (stack 0x%08X, reset handler 0x%08X; expected a stack "
            "in 0x%08X..0x%08X and a handler inside 0x%08X + the image): check the file and --target"
            % (name, stack, entry, low, high, start))
