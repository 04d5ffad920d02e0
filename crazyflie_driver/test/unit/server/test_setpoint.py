"""cmd_vel -> RPYT setpoint: trims, pitch sign, thrust clamp, refusal of NaN."""
from __future__ import annotations

import pytest

from crazyflie_driver.server.setpoint import Setpoint, setpoint_from_twist


def test_cmd_vel_mapping_with_trims_and_pitch_sign():
    sp = setpoint_from_twist(linear_x=5.0, linear_y=-3.0, linear_z=42000.7, angular_z=20.0,
                             roll_trim=1.5, pitch_trim=-0.5)
    assert sp == Setpoint(roll=-1.5, pitch=-4.5, yawrate=20.0, thrust=42000)


@pytest.mark.parametrize("z,thrust", [(-5.0, 0), (0.0, 0), (59999.9, 59999), (70000.0, 60000)])
def test_thrust_is_clamped(z, thrust):
    assert setpoint_from_twist(0, 0, z, 0).thrust == thrust


def test_nan_setpoint_is_refused():
    with pytest.raises(ValueError, match="linear.z"):
        setpoint_from_twist(0, 0, float("nan"), 0)
