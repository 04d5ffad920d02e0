"""The read_config/write_config services' logic without ROS: fields to a checked block and back, and
the URI a Crazyflie answers on after it booted with a new block."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.errors import ConfigBlockError
from crazyflie_driver.server.memory_config import ConfigFields, block_of, fields_of, uri_after_reboot


def test_fields_and_block_round_trip():
    block = cb.ConfigBlock(42, 1, -0.5, 1.5, 0xE7E7E7E7A0)
    fields = fields_of(block)
    assert fields == ConfigFields(42, "1M", "E7E7E7E7A0", -0.5, 1.5)
    assert block_of(fields) == block
    assert block_of(ConfigFields(42, "1m", "0xe7e7e7e7a0", -0.5, 1.5)) == block


@pytest.mark.parametrize("fields,says", [
    (ConfigFields(126, "2M", "E7E7E7E7E7", 0.0, 0.0), "channel 126"),
    (ConfigFields(80, "4M", "E7E7E7E7E7", 0.0, 0.0), "data rate '4M'"),
    (ConfigFields(80, "2M", "E7E7", 0.0, 0.0), "10 hex digits"),
])
def test_a_bad_field_is_named(fields, says):
    with pytest.raises(ConfigBlockError, match=says):
        block_of(fields)


def test_uri_after_reboot_follows_the_radio_settings_and_keeps_the_dongle():
    block = cb.ConfigBlock(90, 0, 0.0, 0.0, 0xE7E7E7E7A0)
    assert uri_after_reboot("radio://1/80/2M/E7E7E7E701", block) == "radio://1/90/250K/E7E7E7E7A0"
    assert uri_after_reboot("usb://0", block) == "usb://0"
