"""The simulated high-level planner against reference values of the firmware's planner (planner.c and
pptraj.c of crazyflie-firmware 2a18fc29, built for the host in single precision and driven with the
same inputs): relative trajectories with and without relative yaw, reversed and time-scaled, and
go_to (linear and smooth, absolute and relative) whose yaw goal lies more than pi away.

Values per time: position (3), velocity (3), acceleration (3), yaw, body rates (3)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crazyflie_driver.sim.onboard.high_level import HighLevelPlans
from crazyflie_driver.sim.onboard.planner import Evaluation, Piece, normalize_radians

TOL = 1e-4                     # m, m/s, m/s², rad, rad/s

TRAJECTORY = (                 # duration; then x, y, z, yaw coefficients in ascending powers of t
    (2.0, (0.3, 0.5, 0.1, 0, 0, 0, 0, 0), (-0.2, 0.4, 0, -0.05, 0, 0, 0, 0), (1.0, 0, 0.02, 0, 0, 0, 0, 0),
     (0.2, 0.3, 0, 0, 0, 0, 0, 0)),
    (1.5, (1.7, 0.9, 0, 0.02, 0, 0, 0, 0), (0.2, -0.2, 0.1, 0, 0, 0, 0, 0), (1.08, 0.08, 0, 0, 0, 0, 0, 0),
     (0.8, 0.3, -0.1, 0, 0, 0, 0, 0)),
)
START = (1.0, -0.5, 1.2)

# (reversed, relative yaw, timescale, start yaw) -> {time: reference}
TRAJECTORY_REFERENCE = {
    (False, True, 1.0, 1.0): {
        10.0: (1.052483, -0.224134, 1.2, 0.061411, 0.637361, 0.0, 0.139341, 0.143471, 0.04, 1.0,
               0.029843, -0.006051, 0.299938),
        10.7: (1.141912, 0.24522, 1.2098, 0.211675, 0.686583, 0.028, 0.289986, -0.002837, 0.04, 1.21,
               0.02791, -0.012142, 0.29987),
        11.9: (1.666692, 1.006881, 1.2722, 0.714608, 0.53269, 0.076, 0.548234, -0.253651, 0.04, 1.57,
               0.021791, -0.021124, 0.299437),
        12.75: (2.284338, 1.483799, 1.34, 0.686418, 0.634996, 0.08, -0.080768, 0.203903, 0.0, 1.76875,
                0.010079, 0.006925, 0.149963),
        20.0: (2.782313, 2.023446, 1.4, 0, 0, 0, 0, 0, 0, 1.825, 0, 0, 0)},
    (False, True, 1.3, 3.0): {
        10.0: (0.484331, -0.011059, 1.2, -0.465466, -0.161073, 0.0, -0.111506, 0.039644, 0.023669, 3.0,
               0.013608, -0.002759, 0.230753),
        10.7: (0.133801, -0.106743, 1.205799, -0.532313, -0.101801, 0.016568, -0.079486, 0.129706, 0.023669,
               3.161539, 0.012986, -0.004912, 0.230742),
        11.9: (-0.549032, -0.098461, 1.242722, -0.594762, 0.146481, 0.04497, -0.024595, 0.284098, 0.023669,
               3.438462, 0.011141, -0.00827, 0.230672),
        12.75: (-1.059366, 0.136321, 1.289231, -0.607297, 0.360352, 0.061538, -0.047363, -0.108761, 0.0,
                3.633285, 0.004121, 0.003744, 0.213002),
        20.0: (-2.279252, 0.626547, 1.4, 0, 0, 0, 0, 0, 0, 3.825, 0, 0, 0)},
    (True, True, 1.0, 1.0): {          # reversed: shifted, never rotated
        10.0: (1.0, -0.5, 1.2, -1.035, -0.1, -0.08, 0.18, 0.2, 0.0, 1.025, -0.010451, -0.006344, 0.0),
        10.7: (0.31274, -0.521, 1.144, -0.9384, 0.04, -0.08, 0.096, 0.2, 0.0, 0.976, -0.010129, -0.006852,
               -0.139964),
        11.9: (-0.7615, -0.3898, 1.0512, -0.82, -0.016, -0.064, 0.2, -0.48, 0.04, 0.68, -0.023619, 0.019105,
               -0.299583),
        12.75: (-1.38625, -0.546094, 1.01125, -0.65, -0.315625, -0.03, 0.2, -0.225, 0.04, 0.425, -0.027723,
                0.012559, -0.29986),
        20.0: (-1.8175, -0.825, 1.0, 0, 0, 0, 0, 0, 0, 0.2, 0, 0, 0)},
    (False, False, 1.0, 1.0): {
        10.0: (1.0, -0.5, 1.2, 0.5, 0.4, 0.0, 0.2, 0.0, 0.04, 0.2, 0.029843, -0.006051, 0.299938),
        10.7: (1.399, -0.23715, 1.2098, 0.64, 0.3265, 0.028, 0.2, -0.21, 0.04, 0.41, 0.02791, -0.012142, 0.29987),
        11.9: (2.311, -0.08295, 1.2722, 0.88, -0.1415, 0.076, 0.2, -0.57, 0.04, 0.77, 0.021791, -0.021124,
               0.299437),
        12.75: (3.083438, -0.19375, 1.34, 0.93375, -0.05, 0.08, 0.09, 0.2, 0.0, 0.96875, 0.010079, 0.006925,
                0.149963),
        20.0: (3.8175, -0.175, 1.4, 0, 0, 0, 0, 0, 0, 1.025, 0, 0, 0)},
}

# go_to from a moving start with yaw 4 rad (beyond pi) and yaw rate 0.4 rad/s over 2 s from t = 5 s:
# (relative, linear, goal yaw) -> goal offset or goal, {time: reference}
GO_TO_START = Evaluation(np.array([0.2, 0.1, 1.0]), np.array([0.3, -0.1, 0.05]), np.array([0.2, 0.0, -0.1]), 4.0, 0.4)
GO_TO_REFERENCE = {
    (True, True, 3.5): ((0.5, -0.4, 0.3), {
        5.0: (0.2, 0.1, 1.0, 0.25, -0.2, 0.15, 0, 0, 0, -2.283185, 0, 0, -1.391593),
        5.6: (0.35, -0.02, 1.09, 0.25, -0.2, 0.15, 0, 0, 0, -3.118141, 0, 0, -1.391592),
        6.5: (0.575, -0.2, 1.225, 0.25, -0.199998, 0.15, 0, 5e-06, 0, -4.370573, 0, 1e-06, -1.391589),
        7.0: (0.7, -0.299998, 1.3, 0.25, -0.199994, 0.15, 0, 1.5e-05, 3e-06, -5.066366, -1e-06, 3e-06, -1.391583)}),
    (False, True, -2.0): ((0.5, -0.4, 1.3), {
        5.0: (0.2, 0.1, 1.0, 0.15, -0.25, 0.15, 0, 0, 0, -2.283185, 0, 0, 0.141593),
        5.6: (0.29, -0.05, 1.09, 0.15, -0.25, 0.15, 0, 1e-06, 0, -2.19823, 0, 0, 0.141592),
        6.5: (0.425, -0.274999, 1.225, 0.150001, -0.249997, 0.15, 2e-06, 8e-06, 0, -2.070799, 0, -2e-06, 0.141585),
        7.0: (0.500001, -0.399996, 1.3, 0.150003, -0.24999, 0.15, 4e-06, 1.9e-05, 3e-06, -2.00001, 1e-06, -3e-06,
              0.14157)}),
    (True, False, 3.5): ((0.5, -0.4, 0.3), {
        5.0: (0.2, 0.1, 1.0, 0.3, -0.1, 0.05, 0.2, 0, -0.1, -2.283185, 0, 0, 0.399915),
        5.6: (0.41601, 0.004927, 1.050632, 0.407072, -0.278173, 0.190742, 0.048314, -0.48951, 0.491813, -2.455332,
              0.088021, 0.039146, -1.726828),
        6.5: (0.685157, -0.277417, 1.279895, 0.101661, -0.148778, 0.131371, -0.453905, 0.60645, -0.524512,
              -4.847436, 0.087853, -0.045319, -1.422656),
        7.0: (0.700001, -0.299998, 1.3, 1e-06, 8e-06, -4e-06, 2e-06, 1.1e-05, 6e-06, -5.066361, -1e-06, 3e-06,
              3.7e-05)}),
    (False, False, -2.0): ((0.5, -0.4, 1.3), {
        5.0: (0.2, 0.1, 1.0, 0.3, -0.1, 0.05, 0.2, 0, -0.1, -2.283185, 0, 0, 0.399915),
        5.6: (0.390803, -0.007677, 1.050632, 0.277418, -0.343, 0.190742, -0.322126, -0.67473, 0.491813, -2.068859,
              0.082951, -0.015915, 0.258361),
        6.5: (0.499268, -0.37036, 1.279895, 0.009376, -0.194918, 0.131371, -0.084763, 0.791028, -0.524512,
              -1.997425, -0.077705, 0.042307, -0.012458),
        7.0: (0.500002, -0.399995, 1.3, 5e-06, 1.4e-05, -4e-06, 7e-06, 3.1e-05, 6e-06, -2.000011, 2e-06, -6e-06,
              -2.6e-05)}),
}


def flat(ev: Evaluation) -> np.ndarray:
    return np.concatenate([ev.pos, ev.vel, ev.acc, [ev.yaw, ev.omega_xy[0], ev.omega_xy[1], ev.yaw_rate]])


def pieces():
    return [Piece(d, np.array([x, y, z, yaw], dtype=float)) for d, x, y, z, yaw in TRAJECTORY]


@pytest.mark.parametrize("case", sorted(TRAJECTORY_REFERENCE))
def test_relative_trajectory_matches_the_firmware(case):
    reversed_, relative_yaw, timescale, start_yaw = case
    hl = HighLevelPlans()
    hl.append_row()
    start = Evaluation(np.array(START), np.zeros(3), np.zeros(3), start_yaw, 0.0)
    assert hl.start_trajectory(0, start, pieces(), timescale, reversed_, True, relative_yaw, 10.0) == 0
    for t, reference in TRAJECTORY_REFERENCE[case].items():
        assert flat(hl.current(0, t)) == pytest.approx(np.array(reference), abs=TOL), t


def test_relative_yaw_turns_the_plan_by_the_start_yaw():
    """Forward with relative yaw: the plan's velocity is the unrotated one turned by the start yaw minus
    the plan's first yaw (0.8 rad here), about the world z axis."""
    hl = HighLevelPlans()
    hl.append_row()
    hl.start_trajectory(0, Evaluation(np.array(START), np.zeros(3), np.zeros(3), 1.0, 0.0), pieces(), 1.0, False,
                        True, True, 10.0)
    turned, plain = hl.current(0, 10.7), TRAJECTORY_REFERENCE[(False, False, 1.0, 1.0)][10.7]
    c, s = math.cos(0.8), math.sin(0.8)
    assert turned.vel[:2] == pytest.approx((c * plain[3] - s * plain[4], s * plain[3] + c * plain[4]), abs=1e-9)
    assert turned.yaw == pytest.approx(plain[9] + 0.8, abs=1e-9)


@pytest.mark.parametrize("case", sorted(GO_TO_REFERENCE))
def test_go_to_matches_the_firmware(case):
    relative, linear, yaw = case
    goal, reference = GO_TO_REFERENCE[case]
    hl = HighLevelPlans()
    hl.append_row()
    assert hl.go_to(0, GO_TO_START, goal, yaw, 2.0, relative, linear, 5.0) == 0
    for t, values in reference.items():
        assert flat(hl.current(0, t)) == pytest.approx(np.array(values), abs=TOL), t


def test_linear_go_to_turns_the_short_way():
    """A relative yaw of 3.5 rad from yaw 4 rad: the goal (7.5 rad) is 2.78 rad the other way round."""
    hl = HighLevelPlans()
    hl.append_row()
    hl.go_to(0, GO_TO_START, (0.0, 0.0, 0.0), 3.5, 2.0, True, True, 5.0)
    end = hl.current(0, 7.0)
    assert end.yaw - normalize_radians(4.0) == pytest.approx(3.5 - 2 * math.pi, abs=TOL)
    assert abs(end.yaw - normalize_radians(4.0)) < math.pi


def test_normalize_radians_keeps_the_sign_of_pi():
    assert normalize_radians(math.pi) == pytest.approx(-math.pi)
    assert normalize_radians(-math.pi) == pytest.approx(math.pi)
    assert normalize_radians(-3 * math.pi + 1e-9) == pytest.approx(-math.pi + 1e-9)
    assert normalize_radians(4.0) == pytest.approx(4.0 - 2 * math.pi)
