"""Argument checks of the packet builders: nothing that overflows a float32 field reaches the packing."""
from __future__ import annotations

import pytest

from crazyflie_driver.errors import CommandValueError
from crazyflie_driver.protocol.checks import finite
from crazyflie_driver.protocol.localization import external_position_packet
from crazyflie_driver.protocol.setpoints import position_packet


@pytest.mark.parametrize("bad", [1e39, -1e39, 10 ** 400, float("nan"), float("inf"), True, "1"])
def test_values_a_float32_cannot_hold_are_refused_by_name(bad):
    with pytest.raises(CommandValueError, match="goal x must be a finite number within the 32-bit float range"):
        finite("goal x", bad)


@pytest.mark.parametrize("build", [lambda v: position_packet(0.0, v, 0.0, 0.0),
                                   lambda v: external_position_packet(v, 0.0, 0.0)])
def test_builders_refuse_huge_values_instead_of_overflowing(build):
    with pytest.raises(CommandValueError):
        build(1e39)
    assert len(build(3.4e38).data) > 0
