"""The simulated Mellinger controller (stabilizer.controller 2) against reference outputs of the
firmware's own controller_mellinger.c (crazyflie-firmware 2a18fc29, built for the host in single
precision, CF2 defaults, mass 0.029 kg), both driven tick by tick with the same scripted states
(position, velocity, attitude, gyro) and setpoints, open loop, with a perfect estimate.

Cases: a moving position setpoint at 100 Hz with acceleration, yaw and body-rate feed-forward (as
the high-level commander sends), and each other kind of generic setpoint: velocity-world (its z is 0:
the force points down, the motors stop), manual (roll, pitch absolute, z disabled: attitude and
thrust from the setpoint), zDistance (holds level at the current yaw on the setpoint's z) and hover.

Each reference: roll, pitch, yaw commands (counts, as the mixer takes them) and the thrust command.
The firmware hands the mixer thrusts outside 0…65535 (its mixer then cuts at 0 or lowers all four
motors together, which gives the same motor commands); ours clamps them first, so the references
are compared clamped."""
from __future__ import annotations

import math

import pytest

from crazyflie_driver.sim.onboard.setpoint import MODE_ABS, MODE_DISABLE, MODE_VELOCITY, OnboardSetpoint
from support.open_loop import fly_open_loop

COUNTS = 2.0
ABS, VEL, OFF = MODE_ABS, MODE_VELOCITY, MODE_DISABLE
OMEGA = 2 * math.pi / 4.0


def moving(t):
    """The setpoint of a figure-8-like plan: position, velocity, acceleration, yaw, body rates."""
    w = OMEGA
    return OnboardSetpoint(100, ABS, ABS, ABS, OFF, OFF, ABS, OFF,
                    position=(0.6 * math.sin(w * t), 0.3 * math.sin(2 * w * t), 0.8),
                    velocity=(0.6 * w * math.cos(w * t), 0.6 * w * math.cos(2 * w * t), 0.0),
                    acceleration=(-0.6 * w * w * math.sin(w * t), -1.2 * w * w * math.sin(2 * w * t), 0.0),
                    attitude=(0.0, 0.0, 15 * math.sin(t)),
                    attitude_rate=(20 * math.cos(3 * t), -15 * math.sin(2 * t), 15 * math.cos(t)))


def tracking(t):
    w = OMEGA
    rpy = (4 * math.sin(3 * t), -3 * math.cos(2 * t), 14 * math.sin(t) + 3)
    pos = (0.6 * math.sin(w * t) + 0.02, 0.3 * math.sin(2 * w * t) - 0.01, 0.79 + 0.01 * math.sin(t))
    vel = (0.6 * w * math.cos(w * t) * 0.9, 0.6 * w * math.cos(2 * w * t), 0.01 * math.cos(t))
    gyro = (12 * math.cos(3 * t), 6 * math.sin(2 * t), 14 * math.cos(t) + 2 * math.sin(9 * t))
    return rpy, pos, vel, gyro


def hovering(t):
    rpy = (2 * math.sin(3 * t), 1.5 * math.cos(2 * t), 35.0 + 5 * t)
    pos = (0.1 * t, -0.05, 0.5 + 0.02 * math.sin(t))
    vel = (0.1, 0.0, 0.02 * math.cos(t))
    gyro = (6 * math.cos(3 * t), -3 * math.sin(2 * t), 5.0)
    return rpy, pos, vel, gyro


SCENARIOS = {       # states, setpoint at tick k (or None), ticks
    "tracking": (tracking, lambda k: moving(k / 1000.0) if k % 10 == 0 else None, 1500),
    "velocity_world": (hovering, lambda k: OnboardSetpoint(1, VEL, VEL, VEL, OFF, OFF, VEL, OFF, velocity=(0.2, 0, 0),
                                                    attitude_rate=(0, 0, 10)) if k == 0 else None, 300),
    "manual": (hovering, lambda k: OnboardSetpoint(3, OFF, OFF, OFF, ABS, ABS, VEL, OFF, attitude=(5.0, -4.0, 0),
                                            attitude_rate=(0, 0, 30), thrust=40000.0) if k == 0 else None, 300),
    "z_distance": (hovering, lambda k: OnboardSetpoint(5, OFF, OFF, ABS, ABS, ABS, VEL, OFF, position=(0, 0, 0.7),
                                                attitude=(5.0, -4.0, 0), attitude_rate=(0, 0, 30))
                   if k == 0 else None, 300),
    "hover": (hovering, lambda k: OnboardSetpoint(10, VEL, VEL, ABS, OFF, OFF, VEL, OFF, position=(0, 0, 0.6),
                                           velocity=(0.3, 0.1, 0), attitude_rate=(0, 0, -20), velocity_body=True)
              if k == 0 else None, 300),
}

REFERENCE = {       # tick: roll, pitch, yaw commands, thrust (unclamped, as the firmware's controller gives it)
    "tracking": {
        100: (10182, -6329, 6446, 38508.1),
        500: (25767, 20086, 6530, 38711.2),
        1000: (-12352, 32000, 3981, 37389.6),
        1250: (-32000, 26777, 2811, 37661.3),
        1498: (-32000, 19059, 4332, 38134.4),
    },
    "velocity_world": {
        100: (0, 0, 0, -46316.4),
        298: (0, 0, 0, -46904.0),
    },
    "manual": {
        100: (8767, -6403, -5102, 40000.0),
        298: (7128, -7337, -5030, 40000.0),
    },
    "z_distance": {
        100: (-3426, 3363, -5251, 69280.0),
        298: (-5071, 2427, -5271, 68922.7),
    },
    "hover": {
        100: (-3426, 3363, 5220, 52719.0),
        298: (-5071, 2427, 5200, 52234.8),
    },
}


def fly(states, setpoint_at, ticks):
    return fly_open_loop(states, setpoint_at, ticks, controller=2, read=lambda s: (*s.rate_out[0], s.thrust[0]))


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_mellinger_matches_the_firmware(name):
    ours = fly(*SCENARIOS[name])
    for k, ref in REFERENCE[name].items():
        expected = (*ref[:3], min(max(ref[3], 0.0), 65535.0))
        assert ours[k] == pytest.approx(expected, abs=COUNTS), (k, ours[k])


def test_velocity_world_stops_the_motors_and_z_distance_holds_level():
    assert fly(*SCENARIOS["velocity_world"])[298][3] == 0.0
    level = fly(*SCENARIOS["z_distance"])
    hover = fly(*SCENARIOS["hover"])
    assert level[298][:2] == pytest.approx(hover[298][:2], abs=COUNTS)    # the setpoint's roll/pitch ignored
