"""The simulated PID controller (stabilizer.controller 1: position, velocity, attitude and rate PIDs)
against reference outputs of the firmware's own controller (controller_pid.c,
position_controller_pid.c, attitude_pid_controller.c, pid.c of crazyflie-firmware 2a18fc29 built for
the host in single precision, CF2 defaults), both driven tick by tick with the same scripted states
(position, velocity, attitude, gyro) and setpoints, open loop, with a perfect estimate.

Cases: a velocity-world stream followed by a position setpoint arriving between two attitude steps
(the firmware re-initialises every PID on the mode change and takes the current attitude as the
desired roll and pitch until its next position step); a fast yaw (400 deg/s) while holding a position
0.3 m off (x/y rotated with the current yaw); a 1 m climb (thrust above the RPYT commander's 60000).

Each reference: roll, pitch, yaw commands of the rate PIDs (counts, as the mixer takes them), thrust
(counts), desired roll, pitch (legacy sign) and yaw (deg)."""
from __future__ import annotations

import math

import pytest

from crazyflie_driver.sim.onboard.setpoint import MODE_ABS, MODE_DISABLE, MODE_VELOCITY, OnboardSetpoint
from support.open_loop import fly_open_loop

COUNTS = 2.0                   # the firmware truncates its float outputs to int16
DEGREES = 0.05

VEL, ABS, OFF = MODE_VELOCITY, MODE_ABS, MODE_DISABLE


def position(p, yaw):
    return OnboardSetpoint(7, ABS, ABS, ABS, OFF, OFF, ABS, OFF, position=p, attitude=(0.0, 0.0, yaw))


def velocity_world(v, yaw_rate):
    return OnboardSetpoint(1, VEL, VEL, VEL, OFF, OFF, VEL, OFF, velocity=v, attitude_rate=(0.0, 0.0, yaw_rate))


def drifting(t):
    """Drifting, gently rocking, yawing at about 30 deg/s: standard roll, pitch, yaw (deg), position,
    velocity, gyro (deg/s)."""
    rpy = (3 * math.sin(2 * t), 2 * math.cos(3 * t), 30.0 * t + 5 * math.sin(1.3 * t))
    pos = (0.25 * t, -0.15 * t, 0.5 + 0.08 * t)
    vel = (0.25 + 0.02 * math.sin(t), -0.15, 0.08 + 0.01 * math.cos(2 * t))
    gyro = (5 * math.sin(7 * t), -4 * math.cos(5 * t), 30 + 3 * math.sin(4 * t))
    return rpy, pos, vel, gyro


def fast_yaw(t):
    rpy = (1.5 * math.sin(5 * t), -1.0 * math.cos(4 * t), 400.0 * t)
    pos = (0.3 + 0.02 * math.sin(3 * t), -0.2, 1.0 + 0.01 * math.sin(2 * t))
    vel = (0.06 * math.cos(3 * t), 0.01, 0.02 * math.cos(2 * t))
    gyro = (7 * math.cos(5 * t), 4 * math.sin(4 * t), 400.0)
    return rpy, pos, vel, gyro


def climbing(t):
    rpy = (0.5 * math.sin(3 * t), 0.3, 10.0)
    pos = (0.01, -0.02, 0.5 + 0.05 * t * t)
    vel = (0.0, 0.0, 0.1 * t)
    gyro = (1.5 * math.cos(3 * t), 0.0, 0.0)
    return rpy, pos, vel, gyro


SCENARIOS = {       # states, setpoints by the tick they arrive before, ticks run
    "velocity_then_position": (drifting, {0: velocity_world((0.3, -0.2, 0.1), 40.0),
                                          1003: position((0.4, -0.1, 0.6), 20.0)}, 1500),
    "fast_yaw": (fast_yaw, {0: position((0.0, 0.0, 1.0), 0.0)}, 600),
    "climb": (climbing, {0: position((0.0, 0.0, 0.5), 10.0), 200: position((0.0, 0.0, 1.5), 10.0)}, 700),
}

REFERENCE = {       # tick: roll, pitch, yaw commands, thrust, desired roll, pitch, yaw
    "velocity_then_position": {
        500: (-1520, 782, 4187, 36453.7, 1.5298, -0.5925, 20.0800),
        998: (-5253, -4776, 1102, 36830.2, 1.5597, -0.0014, 40.0002),
        1004: (-5083, -1819, 14757, 36838.4, 2.7204, 1.9824, 20.0000),
        1006: (-919, -365, 15474, 36838.4, 2.7204, 1.9824, 20.0000),
        1008: (-926, -378, 15525, 36838.4, 2.7204, 1.9824, 20.0000),
        1010: (-12226, -9734, 15576, 35065.4, -4.7707, -4.2155, 20.0000),
        1020: (-12712, -9980, 15832, 35026.4, -4.8845, -4.1829, 20.0000),
        1100: (-16567, -11902, 17899, 34701.8, -5.8149, -3.9698, 20.0000),
        1498: (-32767, -18845, 28767, 32761.2, -10.6901, -4.1092, 20.0000),
    },
    "fast_yaw": {
        100: (-32767, 13476, 32767, 35373.2, -18.2856, 6.6003, 0.0000),
        200: (-32767, -5576, 32767, 35265.6, -18.3803, -6.6343, 0.0000),
        300: (-32767, -24541, 32767, 35178.5, -9.7975, -16.8028, 0.0000),
        402: (-17123, -32767, 32767, 35115.2, 3.3208, -18.8926, 0.0000),
        598: (16160, -15088, -17993, 35067.9, 18.3509, -0.8462, 0.0000),
    },
    "climb": {
        100: (-2714, 1172, 0, 35715.9, -1.0763, 0.3202, 10.0000),
        200: (-3451, 1421, 0, 63129.8, -1.0806, 0.3214, 10.0000),
        202: (-3466, 1426, 0, 63129.8, -1.0806, 0.3214, 10.0000),
        210: (-3525, 1446, 0, 63266.6, -1.0811, 0.3216, 10.0000),
        300: (-4179, 1679, 0, 64491.5, -1.0849, 0.3227, 10.0000),
        500: (-5521, 2226, 0, 65535.0, -1.0935, 0.3253, 10.0000),
        698: (-6615, 2806, 0, 65535.0, -1.1016, 0.3277, 10.0000),
    },
}


def fly(states, setpoints, ticks):
    """Our controller driven open loop by the scripted states: {tick: outputs as in REFERENCE}."""
    return fly_open_loop(states, setpoints.get, ticks, controller=1,
                         read=lambda s: (*s.rate_out[0], s.thrust[0], *s.attitude_desired[0]))


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_pid_controller_matches_the_firmware(name):
    ours = fly(*SCENARIOS[name])
    for k, ref in REFERENCE[name].items():
        got = ours[k]
        assert got[:4] == pytest.approx(ref[:4], abs=COUNTS), (k, got[:4])
        wrapped = [(g - r + 180.0) % 360.0 - 180.0 for g, r in zip(got[4:], ref[4:])]
        assert wrapped == pytest.approx([0.0, 0.0, 0.0], abs=DEGREES), (k, got[4:])


def test_a_mode_change_resets_the_attitude_and_rate_integrals():
    """Without the reset, the yaw rate integral built during the velocity stream would still be in the
    yaw command after the switch (the firmware's is 14757 counts at tick 1004, see REFERENCE)."""
    ours = fly(*SCENARIOS["velocity_then_position"])
    assert ours[1004][2] == pytest.approx(14757, abs=COUNTS)
    assert ours[1004][4:6] == pytest.approx((2.7204, 1.9824), abs=DEGREES)     # desired = current attitude


def test_position_control_thrust_is_not_capped_at_60000():
    assert fly(*SCENARIOS["climb"])[500][3] == 65535.0
