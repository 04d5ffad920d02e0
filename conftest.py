"""pytest configuration for the whole source space.

Test nodes that run under rostest (they call ``rostest.rosrun``) need a ROS master and are
started by their ``.test`` launch files, so pytest does not collect them.
"""
import importlib.util
import pathlib

import pytest

_SKIP_DIRS = {".ws", "build", "devel", "bench"}


def pytest_ignore_collect(path, config):  # `path` exists on pytest 4.6 (Noetic) and 7 (Debian 12)
    p = pathlib.Path(str(path))
    try:                            # only the parts inside the checkout: it may itself sit in a "bench" or "build"
        inside = p.resolve().relative_to(pathlib.Path(str(config.rootdir)).resolve()).parts
    except ValueError:
        inside = p.parts
    if _SKIP_DIRS.intersection(inside):
        return True
    if p.suffix == ".py" and p.is_file():
        try:
            text = p.read_text(errors="ignore")
        except OSError:
            return None
        if "rostest.rosrun(" in text or "rostest.unitrun(" in text:
            return True
    return None


# The tests' helper packages come from the PYTHONPATH that the devel space's environment hooks set
# (crazyflie_driver/env-hooks, crazyflie_controller/env-hooks); no test edits sys.path.
_TEST_SUPPORT = ("support", "controller_support")


def pytest_configure(config):
    missing = [m for m in _TEST_SUPPORT if importlib.util.find_spec(m) is None]
    if missing:
        raise pytest.UsageError("the tests' helper packages %s are not importable: run tools/bootstrap.sh, then "
                                "source tools/env.sh (it puts them on PYTHONPATH) and run pytest again"
                                % ", ".join(missing))
