"""The read_config / write_config services decided without ROS: request fields to a configuration
block, the block to answer fields, and the URI a Crazyflie is reached on after it rebooted with it.

The worker reads and writes the block on its link (``protocol.memory``); the node only registers the
services. The firmware takes new radio settings at its next boot, so a write answers with the URI to
use after the ``reboot`` service.
"""
from __future__ import annotations

from typing import NamedTuple

from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.crtp.uri import RadioUri, parse_link_uri

READ_CONFIG_SERVICE = "read_config"
WRITE_CONFIG_SERVICE = "write_config"


class ConfigFields(NamedTuple):
    """The services' fields: rate and address as text, as people write them in URIs."""

    channel: int
    datarate: str
    address: str
    pitch_trim: float
    roll_trim: float


def fields_of(block: cb.ConfigBlock) -> ConfigFields:
    return ConfigFields(block.channel, cb.DATARATES.get(block.datarate, str(block.datarate)),
                        block.address_bytes.hex().upper(), block.pitch_trim, block.roll_trim)


def block_of(fields: ConfigFields) -> cb.ConfigBlock:
    """A checked block; ConfigBlockError naming the field and its allowed values."""
    block = cb.ConfigBlock(int(fields.channel), cb.parse_datarate(fields.datarate), float(fields.pitch_trim),
                           float(fields.roll_trim), cb.parse_address(fields.address))
    cb.check(block)
    return block


def uri_after_reboot(uri: str, block: cb.ConfigBlock) -> str:
    """Where the Crazyflie on ``uri`` answers once it booted with ``block`` (a USB cable stays a cable)."""
    link = parse_link_uri(uri)
    if not isinstance(link, RadioUri):
        return str(link)
    return str(RadioUri(link.index, block.channel, block.datarate, block.address_bytes))
