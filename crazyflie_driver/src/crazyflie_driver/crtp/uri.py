"""Crazyflie URIs: ``radio://<dongle>/<channel>/<rate>[/<address>]`` and ``usb://<n>`` (the n-th
Crazyflie on a USB cable; ``parse_link_uri``).

Parsing is strict on purpose: a typo in a launch file should be refused with a
message that names the bad part, not turned into a silent default that makes
the Crazyflie "not answer".
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Union

from crazyflie_driver.errors import UriError

DATARATE_250K = 0
DATARATE_1M = 1
DATARATE_2M = 2
DATARATE_NAMES = ("250K", "1M", "2M")
_DATARATE_BY_NAME = {name: i for i, name in enumerate(DATARATE_NAMES)}

MAX_CHANNEL = 125
DEFAULT_ADDRESS = b"\xe7\xe7\xe7\xe7\xe7"
_HEX_DIGITS = frozenset("0123456789abcdefABCDEF")
_FORMAT = "radio://<dongle>/<channel 0-125>/<250K|1M|2M>[/<address, up to 10 hex digits>]"


@dataclass(frozen=True)
class RadioUri:
    """Where a Crazyflie is: which dongle, and the channel, rate and address it listens on."""

    index: int
    channel: int
    datarate: int
    address: bytes = DEFAULT_ADDRESS

    @property
    def datarate_name(self) -> str:
        return DATARATE_NAMES[self.datarate]

    def __str__(self) -> str:
        return "radio://%d/%d/%s/%s" % (
            self.index, self.channel, DATARATE_NAMES[self.datarate], self.address.hex().upper())


@dataclass(frozen=True)
class UsbUri:
    """A Crazyflie on a USB cable: the ``index``-th one on the bus (CRTP over USB, no radio)."""

    index: int

    def __str__(self) -> str:
        return "usb://%d" % self.index


LinkUri = Union[RadioUri, UsbUri]
_USB_FORMAT = "usb://<n>, n the n-th Crazyflie on a USB cable from 0"


def parse_link_uri(text: str) -> LinkUri:
    """A radio URI (``parse_uri``) or ``usb://<n>``; raises UriError naming the malformed part."""
    if not isinstance(text, str):
        raise UriError("Crazyflie URI must be a string, got %r" % (text,))
    scheme, sep, rest = text.strip().partition("://")
    if scheme.lower() != "usb" or not sep:
        return parse_uri(text)
    rest = rest[:-1] if rest.endswith("/") else rest
    if not _is_decimal(rest):
        raise UriError("URI %r: %r is not a Crazyflie number (%s)" % (text, rest, _USB_FORMAT))
    return UsbUri(int(rest))


def radio_uri_of(text: str) -> Optional[RadioUri]:
    """The radio URI of a link URI, None for a Crazyflie on a USB cable (it takes no radio's time)."""
    uri = parse_link_uri(text)
    return uri if isinstance(uri, RadioUri) else None


def parse_uri(text: str) -> RadioUri:
    """Parse a radio URI; raises UriError naming the malformed part."""
    if not isinstance(text, str):
        raise UriError("Crazyflie URI must be a string, got %r" % (text,))
    parts = _radio_parts(text, _radio_path(text))
    address = _parse_address(text, parts[3]) if len(parts) == 4 else DEFAULT_ADDRESS
    return RadioUri(_parse_index(text, parts[0]), _parse_channel(text, parts[1]),
                    _parse_datarate(text, parts[2]), address)


def _radio_path(text: str) -> str:
    """What follows ``radio://``, without a (harmless) trailing slash; refuses any other scheme."""
    scheme, sep, rest = text.strip().partition("://")
    if not sep:
        raise UriError("malformed Crazyflie URI %r: expected %s" % (text, _FORMAT))
    scheme = scheme.lower()
    if scheme == "usb":
        raise UriError("URI %r: a Crazyflie on a USB cable has no radio channel, rate or address; here a "
                       "Crazyradio URI like radio://0/80/2M/E7E7E7E7E7 is needed (usb:// links are opened "
                       "through parse_link_uri)" % (text,))
    if scheme != "radio":
        raise UriError("URI %r: unknown scheme %r, expected 'radio' (%s)" % (text, scheme, _FORMAT))
    if "?" in rest or "#" in rest:
        raise UriError("URI %r: query options are not supported (%s)" % (text, _FORMAT))
    return rest[:-1] if rest.endswith("/") else rest


def _radio_parts(text: str, path: str) -> List[str]:
    """The path's 3 or 4 parts (dongle, channel, rate[, address]); refuses a missing or extra part."""
    parts = path.split("/")
    if len(parts) > 4:
        raise UriError("URI %r: unexpected extra part %r after the address (%s)"
                       % (text, "/".join(parts[4:]), _FORMAT))
    if len(parts) < 2 or parts[1] == "":
        raise UriError("URI %r: missing channel (%s)" % (text, _FORMAT))
    if len(parts) < 3 or parts[2] == "":
        raise UriError("URI %r: missing data rate, one of 250K, 1M, 2M (%s)" % (text, _FORMAT))
    return parts


def _is_decimal(digits: str) -> bool:
    """ASCII digits only: ``str.isdigit`` alone also takes superscripts and other scripts' digits."""
    return digits.isdigit() and digits.isascii()


def _parse_index(text: str, index_text: str) -> int:
    if not _is_decimal(index_text):
        raise UriError("URI %r: dongle index %r is not a number (the n-th Crazyradio, from 0)"
                       % (text, index_text))
    return int(index_text)


def _parse_channel(text: str, channel_text: str) -> int:
    if not _is_decimal(channel_text):
        raise UriError("URI %r: channel %r is not a number (0-125)" % (text, channel_text))
    channel = int(channel_text)
    if channel > MAX_CHANNEL:
        raise UriError("URI %r: channel %d is out of range 0-125" % (text, channel))
    return channel


def _parse_datarate(text: str, rate_text: str) -> int:
    datarate = _DATARATE_BY_NAME.get(rate_text.upper())
    if datarate is None:
        raise UriError("URI %r: data rate %r is not one of 250K, 1M, 2M" % (text, rate_text))
    return datarate


def _parse_address(text: str, digits: str) -> bytes:
    """Up to 10 hex digits, left-padded with zeros, bytes in string order (E7E7E7E701 -> E7 .. 01)."""
    if digits[:2] in ("0x", "0X"):
        digits = digits[2:]
    if not digits:
        raise UriError("URI %r: empty address (up to 10 hex digits, e.g. E7E7E7E7E7)" % (text,))
    if len(digits) > 10:
        raise UriError("URI %r: address %r has %d hex digits, at most 10 (5 bytes) are allowed"
                       % (text, digits, len(digits)))
    if not all(c in _HEX_DIGITS for c in digits):
        raise UriError("URI %r: address %r is not hexadecimal" % (text, digits))
    return bytes.fromhex(digits.rjust(10, "0"))
