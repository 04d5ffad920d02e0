"""The nRF51's system commands as they go on the air."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp import nrf_system as N


def test_packets_on_the_wire():
    assert N.reboot_packets() == (b"\xf3\xfe\xff", b"\xf3\xfe\xf0\x01")
    assert N.reboot_packets(bootloader=True) == (b"\xf3\xfe\xff", b"\xf3\xfe\xf0\x00")
    assert N.stm_power_off_packet() == b"\xf3\xfe\x02"
    assert N.stm_power_on_packet() == b"\xf3\xfe\x03"
    assert N.all_off_packet() == b"\xf3\xfe\x01"


def test_recognised_with_any_sequence_bits_and_only_for_the_nrf():
    assert N.is_nrf_command(b"\xff\xfe\x02") and N.is_nrf_command(b"\xf7\xfe\x02")
    assert not N.is_nrf_command(b"\xf3\x05\x01")            # safelink: another nRF command family
    assert not N.is_nrf_command(b"\x3c\xfe\x02")            # a CRTP packet on port 3
    assert not N.is_nrf_command(b"\xf3\xfe")


def test_bytes_out_of_range_are_refused():
    with pytest.raises(ValueError):
        N.nrf_command(0x100)
