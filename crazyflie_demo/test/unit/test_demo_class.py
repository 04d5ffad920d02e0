"""The chapter's ``from demo import Demo``: importable without a ROS master, yaw in radians."""
from __future__ import annotations

import math
import os
import subprocess
import sys

import pytest

from crazyflie_demo.waypoint_demo import Demo, check_goals, follower_for

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPTS = os.path.join(os.path.dirname(os.path.dirname(HERE)), "scripts")
IMPORT_ONLY = "from demo import Demo; d = Demo([[0, 0, 0.5, 0, 2]]); print(type(d).__name__, d.goalIndex)"


def _import_from(directory: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:9")   # nothing listens there
    return subprocess.run([sys.executable, "-c", IMPORT_ONLY], cwd=directory,      # as a user runs it from there
                          env=env, capture_output=True, text=True, timeout=30)


def test_import_and_construct_without_a_master():
    r = _import_from(SCRIPTS)
    assert (r.returncode, r.stdout) == (0, "Demo 0\n"), r.stderr


def _devel_relay_dir():
    for prefix in os.environ.get("CMAKE_PREFIX_PATH", "").split(os.pathsep):
        d = os.path.join(prefix, "lib", "crazyflie_demo")
        if prefix and os.path.isfile(os.path.join(d, "demo.py")):
            return d
    return None


def test_import_through_the_devel_space_relay():
    """rosrun runs demo1.py from devel/lib/crazyflie_demo, where demo.py is catkin's relay file."""
    d = _devel_relay_dir()
    if d is None:
        pytest.skip("no catkin devel space on CMAKE_PREFIX_PATH")
    r = _import_from(d)
    assert (r.returncode, r.stdout) == (0, "Demo 0\n"), r.stderr


def test_yaw_is_in_radians():
    f = follower_for([[0, 0, 0.5, math.pi / 2, 0], [1, 0, 0.5, 0, 0]])
    assert f.update(0.0, (0, 0, 0.5), 0.0).x == 0        # 90° off: not there
    assert f.update(0.1, (0, 0, 0.5), 85.0).x == 1        # within 10° of pi/2


@pytest.mark.parametrize("goals, text", [
    ([], "at least one waypoint"),
    ([[0, 0, 0.5, 0]], "waypoint 1"),
    ([[0, 0, 0.5, 0, 2], [0, "a", 0.5, 0, 2]], "waypoint 2"),
    ([[0, 0, float("nan"), 0, 2]], "finite"),
    ([[0, 0, 0.5, 0, -1]], "negative"),
])
def test_bad_goals_are_named(goals, text):
    with pytest.raises(ValueError, match=text):
        Demo(goals)
    with pytest.raises(ValueError):
        check_goals(goals)
