"""cmd_vel -> RPYT setpoint: trims, pitch sign, thrust clamp, angle/rate limits, refusal of NaN/inf."""
from __future__ import annotations

import pytest

from crazyflie_driver.crtp.firmware_limits import MAX_ANGLE_DEG, MAX_RATE_DEG_S, MAX_THRUST
from crazyflie_driver.server.setpoint import Setpoint, SetpointLimits, check_trim, limits_for_modes, setpoint_from_twist


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


@pytest.mark.parametrize("field", range(6))
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_every_non_finite_field_is_refused_by_name(field, bad):
    args = [0.0] * 6
    args[field] = bad
    label = ("linear.x", "linear.y", "linear.z", "angular.z", "roll_trim", "pitch_trim")[field]
    with pytest.raises(ValueError, match=r"cmd_vel %s is %r, not a finite number" % (label.replace(".", r"\."), bad)):
        setpoint_from_twist(*args)


def test_angles_and_rates_beyond_the_firmware_limits_are_held_and_named():
    sp = setpoint_from_twist(linear_x=-1e39, linear_y=1e30, linear_z=1e39, angular_z=-5000.0)
    assert sp == Setpoint(roll=MAX_ANGLE_DEG, pitch=MAX_ANGLE_DEG, yawrate=-MAX_RATE_DEG_S, thrust=MAX_THRUST)
    assert len(sp.notes) == 3
    assert sp.notes[0].startswith("roll (linear.y + roll_trim) 1e+30 deg is outside -90..90 deg")
    assert "yaw rate (angular.z) -5000.0 deg/s" in sp.notes[2]


def test_values_inside_the_limits_pass_unchanged_and_unnoted():
    sp = setpoint_from_twist(linear_x=-89.0, linear_y=90.0, linear_z=0.0, angular_z=2000.0)
    assert (sp.roll, sp.pitch, sp.yawrate, sp.notes) == (90.0, 89.0, 2000.0, ())


def test_trim_counts_towards_the_limit():
    assert setpoint_from_twist(0.0, 85.0, 0.0, 0.0, roll_trim=10.0).roll == MAX_ANGLE_DEG


def test_rate_mode_axes_take_rates_up_to_the_gyro_range():
    limits = limits_for_modes({"flightmode.stabModeRoll": 0, "flightmode.stabModePitch": 1})
    assert limits == SetpointLimits(roll=MAX_RATE_DEG_S, pitch=MAX_ANGLE_DEG, yawrate=MAX_RATE_DEG_S)
    sp = setpoint_from_twist(-500.0, 500.0, 0.0, 0.0, limits=limits)
    assert (sp.roll, sp.pitch) == (500.0, MAX_ANGLE_DEG)
    assert "deg/s" not in sp.notes[0] and len(sp.notes) == 1
    assert limits_for_modes({}) == SetpointLimits()


@pytest.mark.parametrize("value", [float("nan"), float("inf"), 1e9, -90.5, True, "1", None])
def test_bad_trims_are_refused(value):
    with pytest.raises(ValueError, match="roll_trim"):
        check_trim("roll_trim", value)


def test_good_trims_pass():
    assert check_trim("pitch_trim", -2) == -2.0 and check_trim("pitch_trim", 90.0) == 90.0
