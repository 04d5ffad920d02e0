"""System commands of the Crazyflie's radio chip (nRF51): reboot and power, without the STM32.

The nRF51 takes them itself, before anything reaches the STM32: a null-header packet
(``0xF3``; the sequence bits may be set) whose first payload byte is ``0xFE`` (the nRF as target)
followed by the command. So they work when the STM32 is off, locked or hung. A reset needs a
``RESET_INIT`` first; its argument chooses what boots (docs/protocol.md, "nRF system commands").
"""
from __future__ import annotations

from typing import Tuple

#: Header byte of a packet for the nRF itself (a null packet: no CRTP port).
NRF_HEADER = 0xF3
#: First payload byte: the command is for the nRF51's own "system" target.
TARGET_NRF = 0xFE
SYS_RESET_INIT = 0xFF      # arms the next SYS_RESET
SYS_RESET = 0xF0           # + one byte: RESET_TO_BOOTLOADER or RESET_TO_FIRMWARE
SYS_ALL_OFF = 0x01         # everything off, as the power button (no radio wakes it)
SYS_STM_OFF = 0x02         # STM32 domain (and decks) off, the nRF stays on the radio
SYS_STM_ON = 0x03          # STM32 domain on: it boots
RESET_TO_BOOTLOADER = 0x00
RESET_TO_FIRMWARE = 0x01


def nrf_command(cmd: int, *args: int) -> bytes:
    """The radio payload of one system command."""
    if not 0 <= cmd <= 0xFF or any(not 0 <= a <= 0xFF for a in args):
        raise ValueError("nRF system command bytes must be 0..255, got %r %r" % (cmd, args))
    return bytes((NRF_HEADER, TARGET_NRF, cmd) + tuple(args))


def is_nrf_command(data: bytes) -> bool:
    """True for a system command packet (any sequence bits in the header)."""
    return len(data) >= 3 and (data[0] & NRF_HEADER) == NRF_HEADER and data[1] == TARGET_NRF


def reboot_packets(bootloader: bool = False) -> Tuple[bytes, bytes]:
    """RESET_INIT, then RESET into the firmware (or the bootloader)."""
    return (nrf_command(SYS_RESET_INIT),
            nrf_command(SYS_RESET, RESET_TO_BOOTLOADER if bootloader else RESET_TO_FIRMWARE))


def stm_power_off_packet() -> bytes:
    return nrf_command(SYS_STM_OFF)


def stm_power_on_packet() -> bytes:
    return nrf_command(SYS_STM_ON)


def all_off_packet() -> bytes:
    return nrf_command(SYS_ALL_OFF)
