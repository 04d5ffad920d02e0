"""Host side of flashing a Crazyflie: reboot into the bootloader, read the target's geometry, write an
image page buffer by page buffer, read it back, reboot into the firmware (docs/bootloader.md).

It speaks through one narrow callable, ``exchange(payload) -> ack payload`` (a radio packet out, the
ack's payload back), so the same code runs on a Crazyradio and on the simulated one. Pure packet work
is in crtp/bootloader.py; this module only sequences it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

from crazyflie_driver.crtp import bootloader as bl
from crazyflie_driver.crtp.nrf_system import reboot_packets
from crazyflie_driver.errors import FirmwareImageError, LinkTimeout, ProtocolError

Exchange = Callable[[bytes], Optional[bytes]]
#: Times a request is sent again when its answer does not come (lost packet or ack).
RETRIES = 5


@dataclass(frozen=True)
class FlashResult:
    target: int
    info: bl.BootInfo
    bytes_written: int
    pages_written: int


def _ask(exchange: Exchange, request: bytes, is_answer: Callable[[bytes], bool]) -> bytes:
    for _ in range(RETRIES):
        answer = exchange(request)
        if answer and is_answer(answer):
            return answer
    raise LinkTimeout("no bootloader answer to %s after %d tries: is the Crazyflie in its bootloader "
                      "and in range?" % (request[:3].hex(), RETRIES))


def enter_bootloader(exchange: Exchange) -> None:
    """Reboot the running firmware into the bootloaders (the nRF's RESET_INIT then RESET)."""
    for packet in reboot_packets(bootloader=True):
        exchange(packet)


def read_info(exchange: Exchange, target: int) -> bl.BootInfo:
    answer = _ask(exchange, bl.get_info(target), lambda a: bl.is_answer(a, target, bl.CMD_GET_INFO))
    return bl.parse_info(answer, target)


def flash(exchange: Exchange, target: int, image: bytes, reboot_first: bool = True, verify_after: bool = True,
          progress: Optional[Callable[[int, int], None]] = None) -> FlashResult:
    """Write ``image`` to ``target``'s firmware flash, verify it, boot the firmware. Raises
    FirmwareImageError before anything is written when ``image`` is not a firmware for ``target``."""
    if reboot_first:
        enter_bootloader(exchange)
    info = read_info(exchange, target)
    try:
        bl.check_image(image, target, info)
    except FirmwareImageError:
        boot_firmware(exchange, target)              # refused: leave it running its old firmware
        raise
    page, per_buffer = info.page_size, info.page_size * info.buffer_pages
    padded = image + b"\xff" * (-len(image) % page)
    flash_page, done = info.start_page, 0
    while done < len(padded):
        block = padded[done:done + per_buffer]
        for offset in range(0, len(block), bl.CHUNK):
            exchange(bl.load_buffer(target, offset // page, offset % page, block[offset:offset + bl.CHUNK]))
        n_pages = len(block) // page
        answer = _ask(exchange, bl.write_flash(target, 0, flash_page, n_pages),
                      lambda a: bl.is_answer(a, target, bl.CMD_WRITE_FLASH))
        ok, error = bl.parse_flash_answer(answer, target)
        if not ok:
            raise ProtocolError("writing flash pages %d..%d failed (bootloader error %d); flash again"
                                % (flash_page, flash_page + n_pages - 1, error))
        flash_page += n_pages
        done += len(block)
        if progress is not None:
            progress(done, len(padded))
    if verify_after:
        verify(exchange, target, info, padded)
    boot_firmware(exchange, target)
    return FlashResult(target, info, len(image), len(padded) // page)


def boot_firmware(exchange: Exchange, target: int) -> None:
    for packet in (bl.reset_init(target), bl.reset(target, to_firmware=True)):
        exchange(packet)


def verify_only(exchange: Exchange, target: int, image: bytes) -> bl.BootInfo:
    """Reboot into the bootloader, compare the flash with ``image`` (ProtocolError on a difference),
    boot the firmware again."""
    enter_bootloader(exchange)
    info = read_info(exchange, target)
    bl.check_image(image, target, info)
    try:
        verify(exchange, target, info, image + b"\xff" * (-len(image) % info.page_size))
    finally:
        boot_firmware(exchange, target)
    return info


def _data_answer_of(target: int, page: int, address: int) -> Callable[[bytes], bool]:
    def matches(answer: bytes) -> bool:
        return bl.is_answer(answer, target, bl.CMD_READ_FLASH) and answer[3:7] == (
            page.to_bytes(2, "little") + address.to_bytes(2, "little"))
    return matches


def verify(exchange: Exchange, target: int, info: bl.BootInfo, image: bytes) -> None:
    """Read the flash back chunk by chunk and compare with ``image``."""
    page = info.page_size
    for index in range(len(image) // page):
        for address in range(0, page, bl.CHUNK):
            flash_page = info.start_page + index
            answer = _ask(exchange, bl.read_flash(target, flash_page, address),
                          _data_answer_of(target, flash_page, address))
            got = bl.parse_data_answer(answer, target, bl.CMD_READ_FLASH, flash_page, address)
            want = image[index * page + address:index * page + min(address + bl.CHUNK, page)]
            if got[:len(want)] != want:
                raise ProtocolError("verify failed at flash page %d byte %d: the flash does not hold the "
                                    "image; flash again" % (flash_page, address))
