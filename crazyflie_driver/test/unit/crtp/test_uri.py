from __future__ import annotations

import dataclasses

import pytest

from crazyflie_driver.crtp.uri import DEFAULT_ADDRESS, RadioUri, UsbUri, parse_link_uri, parse_uri
from crazyflie_driver.errors import UriError


def test_full_uri():
    uri = parse_uri("radio://0/80/2M/E7E7E7E701")
    assert uri == RadioUri(0, 80, 2, b"\xe7\xe7\xe7\xe7\x01")
    assert str(uri) == "radio://0/80/2M/E7E7E7E701"
    assert uri.datarate_name == "2M"


def test_defaults_and_canonical_form():
    uri = parse_uri("radio://1/100/250K")
    assert (uri.index, uri.channel, uri.datarate, uri.address) == (1, 100, 0, DEFAULT_ADDRESS)
    assert str(uri) == "radio://1/100/250K/E7E7E7E7E7"
    assert parse_uri("radio://0/0/1m/").datarate_name == "1M"


def test_address_left_padded_and_in_string_order():
    assert parse_uri("radio://0/80/2M/1").address == b"\x00\x00\x00\x00\x01"
    assert parse_uri("radio://0/80/2M/0x0102030405").address == b"\x01\x02\x03\x04\x05"
    assert parse_uri("radio://0/80/2M/e7e7e7e702").address == b"\xe7\xe7\xe7\xe7\x02"
    assert parse_uri("  radio://0/125/2M/E7E7E7E7E7 \n").channel == 125


def test_round_trip_through_str():
    for text in ("radio://0/80/2M/E7E7E7E701", "radio://3/0/250K/0000000001", "radio://0/125/1M/FFFFFFFFFF"):
        assert str(parse_uri(text)) == text
        assert parse_uri(str(parse_uri(text))) == parse_uri(text)


def test_frozen():
    uri = parse_uri("radio://0/80/2M")
    with pytest.raises(dataclasses.FrozenInstanceError):
        uri.channel = 3  # type: ignore[misc]


@pytest.mark.parametrize("text, names", [
    ("radio:/0/80/2M", "expected radio://"),
    ("http://0/80/2M", "'http'"),
    ("radio://x/80/2M", "dongle index 'x'"),
    ("radio:///80/2M", "dongle index ''"),
    ("radio://0", "missing channel"),
    ("radio://0//2M", "missing channel"),
    ("radio://0/80", "missing data rate"),
    ("radio://0/ch80/2M", "channel 'ch80'"),
    ("radio://0/-1/2M", "channel '-1'"),
    ("radio://0/126/2M", "channel 126 is out of range"),
    ("radio://0/80/3M", "data rate '3M'"),
    ("radio://0/80/2M/E7E7E7E7E7E7", "'E7E7E7E7E7E7' has 12 hex digits"),
    ("radio://0/80/2M/E7G7", "'E7G7' is not hexadecimal"),
    ("radio://0/80/2M/0x", "empty address"),
    ("radio://0/80/2M/E7E7E7E701/extra", "extra part 'extra'"),
    ("radio://0/80/2M/E7E7E7E701?rate_limit=100", "query options"),
])
def test_malformed_names_the_bad_part(text, names):
    with pytest.raises(UriError) as info:
        parse_uri(text)
    assert names in str(info.value)
    assert isinstance(info.value, ValueError)


def test_usb_uri_refused_where_a_radio_is_needed():
    with pytest.raises(UriError, match="no radio channel, rate or address.*parse_link_uri"):
        parse_uri("usb://0")


def test_link_uri_is_usb_or_radio():
    assert parse_link_uri("usb://0") == UsbUri(0)
    assert parse_link_uri(" USB://12/ ") == UsbUri(12)
    assert str(UsbUri(3)) == "usb://3"
    assert parse_link_uri("radio://0/80/2M/E7E7E7E701") == parse_uri("radio://0/80/2M/E7E7E7E701")
    for bad in ("usb://", "usb://x", "usb://-1", "usb://0/1"):
        with pytest.raises(UriError, match="Crazyflie number"):
            parse_link_uri(bad)
    with pytest.raises(UriError, match="unknown scheme"):
        parse_link_uri("serial://0")


def test_non_string_refused():
    with pytest.raises(UriError, match="must be a string"):
        parse_uri(None)  # type: ignore[arg-type]
