"""The arguments of tf's static_transform_publisher, as the chapter's baselink_broadcaster gives them."""
import math

import pytest

from crazyflie_demo.static_frame import parse_args, quaternion_from_ypr


def test_chapter_baselink_broadcaster_args():
    t, q, frame, child = parse_args("0 0 0 0 0 0 1 /vicon/crazyflie/crazyflie /crazyflie/base_link 100".split())
    assert (t, q, frame, child) == ((0, 0, 0), (0, 0, 0, 1), "vicon/crazyflie/crazyflie", "crazyflie/base_link")


def test_yaw_pitch_roll_form():
    t, q, frame, child = parse_args("1 2 3 1.5707963 0 0 world crazyflie1/base_link 100".split())
    assert t == (1, 2, 3) and (frame, child) == ("world", "crazyflie1/base_link")
    assert q == pytest.approx((0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)), abs=1e-6)
    assert quaternion_from_ypr(0, 0, 0) == pytest.approx((0, 0, 0, 1))


@pytest.mark.parametrize("args", ["0 0 0 world child", "0 0 0 0 0 0 0 a b", "a 0 0 0 0 0 1 f c", "0 0 0 0 0 0 1 / c"])
def test_bad_args_show_the_usage(args):
    with pytest.raises(ValueError, match="usage"):
        parse_args(args.split())
