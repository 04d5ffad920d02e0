"""Finding Crazyflies: a null packet on every data rate and channel, one address.

Uses the Crazyradio directly (no Crazyflie link): a Crazyflie that acks the
null packet is there. ARC is lowered to 1 so that the 378 empty slots of a
full scan do not each cost three retransmissions.
"""
from __future__ import annotations

from typing import Iterable, List, Optional

from crazyflie_driver.crtp.uri import DATARATE_NAMES, DEFAULT_ADDRESS, MAX_CHANNEL, RadioUri
from crazyflie_driver.radio.crazyradio import Crazyradio

SCAN_PACKET = b"\xff"


def parse_address(text: str) -> bytes:
    """Up to 10 hex digits (optionally 0x-prefixed) -> 5 bytes; ValueError naming the text."""
    digits = text.strip()
    if digits[:2] in ("0x", "0X"):
        digits = digits[2:]
    if not digits or len(digits) > 10 or any(c not in "0123456789abcdefABCDEF" for c in digits):
        raise ValueError("address %r is not up to 10 hex digits (e.g. E7E7E7E7E7)" % (text,))
    return bytes.fromhex(digits.rjust(10, "0"))


def scan(radio_index: int = 0, address: bytes = DEFAULT_ADDRESS,
         datarates: Iterable[int] = (0, 1, 2), channels: Optional[Iterable[int]] = None,
         radio: Optional[Crazyradio] = None, backend=None) -> List[RadioUri]:
    """Every (datarate, channel) where something acks a null packet sent to ``address``.

    ``radio``: an already open Crazyradio (left open); otherwise dongle ``radio_index`` is
    opened (and closed) with ``backend`` (None: pyusb's default, libusb).
    """
    if len(address) != 5:
        raise ValueError("a radio address has 5 bytes, got %d" % len(address))
    channel_list = list(range(MAX_CHANNEL + 1) if channels is None else channels)
    own = radio is None
    if radio is None:
        radio = Crazyradio(radio_index, backend=backend)
    found = []
    try:
        radio.set_address(address)
        radio.set_arc(1)
        for rate in datarates:
            if not 0 <= rate < len(DATARATE_NAMES):
                raise ValueError("unknown data rate %r" % (rate,))
            radio.set_data_rate(rate)
            for channel in channel_list:
                radio.set_channel(channel)
                if radio.send_packet(SCAN_PACKET).ack:
                    found.append(RadioUri(radio.index, channel, rate, bytes(address)))
        radio.set_arc(3)
    finally:
        if own:
            radio.close()
    return found
