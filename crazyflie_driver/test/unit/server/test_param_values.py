"""ROS parameter values converted to a Crazyflie parameter's type, or refused with its name."""
from __future__ import annotations

import pytest

from crazyflie_driver.server.param_values import coerce_param_value


def test_param_coercion():
    assert coerce_param_value("ring.headlightEnable", "uint8_t", True) == 1
    assert coerce_param_value("x.y", "float", "2.5") == 2.5
    assert coerce_param_value("x.y", "int16_t", 3.0) == 3
    with pytest.raises(ValueError, match="outside 0..255"):
        coerce_param_value("x.y", "uint8_t", 300)
    with pytest.raises(ValueError, match="whole number"):
        coerce_param_value("x.y", "uint8_t", 1.5)
    with pytest.raises(ValueError, match="not a number"):
        coerce_param_value("x.y", "float", [1])
