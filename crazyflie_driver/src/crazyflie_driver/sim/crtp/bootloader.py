"""The simulated Crazyflie's bootloaders (STM32 and nRF51): flash that outlives reboots, a RAM page
buffer, and the bootloader commands (docs/bootloader.md). Like the real bootloaders it writes any bytes
it is given; only the host tool judges whether they are a firmware image.

The firmware version a simulated firmware reports after a new image: the first NUL-terminated release
tag (``YYYY.MM`` or ``YYYY.MM.N``) in the STM32 image, which is how the real firmware's version string
sits in its binary; an image without one leaves the version unknown ("unknown").
"""
from __future__ import annotations

import re
from typing import Dict, Optional

from crazyflie_driver.crtp import bootloader as bl

#: Flash geometry of each chip as its bootloader reports it (docs/bootloader.md, with sources).
GEOMETRY: Dict[int, bl.BootInfo] = {
    bl.TARGET_STM32: bl.BootInfo(page_size=1024, buffer_pages=10, flash_pages=1024, start_page=16,
                                 cpu_id=bytes.fromhex("3f00473133365003a0002d00")),
    bl.TARGET_NRF51: bl.BootInfo(page_size=1024, buffer_pages=1, flash_pages=232, start_page=88,
                                 cpu_id=bytes(12)),
}

_RELEASE_TAG = re.compile(rb"(20\d\d\.\d\d(?:\.\d+)?)\x00")


def image_version(image: bytes) -> str:
    """The release tag inside a firmware image, "unknown" when it has none."""
    found = _RELEASE_TAG.search(image)
    return found.group(1).decode("ascii") if found else "unknown"


class SimBootloader:
    """Both chips' bootloaders: flash contents per target, written and read page by page."""

    def __init__(self) -> None:
        self.flash: Dict[int, bytearray] = {}        # target -> bytes from its start page on
        self._buffer: Dict[int, bytearray] = {
            t: bytearray(b"\xff" * (g.buffer_pages * g.page_size)) for t, g in GEOMETRY.items()}
        self.written: Dict[int, bool] = {t: False for t in GEOMETRY}   # flashed since power-on of the model

    def stm32_image(self) -> Optional[bytes]:
        """The STM32's flash when a host wrote it, else None (the shipped firmware runs)."""
        return bytes(self.flash[bl.TARGET_STM32]) if self.written[bl.TARGET_STM32] else None

    def handle(self, raw: bytes) -> Optional[bytes]:
        """One bootloader packet (header 0xFF first); its answer, or None when it has none."""
        if len(raw) < 3 or raw[0] != bl.BOOT_HEADER or raw[1] not in GEOMETRY:
            return None
        target, cmd, body = raw[1], raw[2], raw[3:]
        geo = GEOMETRY[target]
        flash = self.flash.setdefault(target, bytearray(b"\xff" * geo.firmware_capacity))
        buffer = self._buffer[target]
        if cmd == bl.CMD_GET_INFO:
            return bl.info_answer(target, geo)
        if cmd in (bl.CMD_LOAD_BUFFER, bl.CMD_READ_BUFFER, bl.CMD_READ_FLASH) and len(body) >= 4:
            page, address = int.from_bytes(body[0:2], "little"), int.from_bytes(body[2:4], "little")
            if cmd == bl.CMD_LOAD_BUFFER:
                start = page * geo.page_size + address
                data = body[4:][:max(0, len(buffer) - start)]
                buffer[start:start + len(data)] = data
                return None                                   # the real one does not answer a load
            if cmd == bl.CMD_READ_BUFFER:
                start = page * geo.page_size + address
                return bl.data_answer(target, cmd, page, address, bytes(buffer[start:start + bl.CHUNK]))
            start = (page - geo.start_page) * geo.page_size + address
            chunk = bytes(flash[start:start + bl.CHUNK]) if 0 <= start < len(flash) else b""
            return bl.data_answer(target, cmd, page, address, chunk)
        if cmd == bl.CMD_WRITE_FLASH and len(body) >= 6:
            buffer_page, flash_page, n_pages = (int.from_bytes(body[i:i + 2], "little") for i in (0, 2, 4))
            ok = (buffer_page + n_pages <= geo.buffer_pages and flash_page >= geo.start_page
                  and flash_page + n_pages <= geo.flash_pages)
            if ok:
                src = buffer_page * geo.page_size
                dst = (flash_page - geo.start_page) * geo.page_size
                flash[dst:dst + n_pages * geo.page_size] = buffer[src:src + n_pages * geo.page_size]
                self.written[target] = True
            return bl.flash_answer(target, cmd, ok, 0 if ok else 1)
        if cmd == bl.CMD_FLASH_STATUS:
            return bl.flash_answer(target, cmd, True, 0)
        return None
