"""The chapter's controller gains, read from crazyflie_controller/config/crazyflie2.yaml.

Benchmarks take them from the same file the controller node loads, so a figure can never be
measured with gains that drifted from the ones users fly.
"""
from __future__ import annotations

import os
import sys

import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "crazyflie_controller", "src"))

from crazyflie_controller.pid import PidGains  # noqa: E402

CONFIG = os.path.join(HERE, "..", "crazyflie_controller", "config", "crazyflie2.yaml")


def chapter_gains():
    """(X, Y, Z, Yaw) PidGains of config/crazyflie2.yaml."""
    with open(CONFIG) as f:
        pids = yaml.safe_load(f)["PIDs"]
    return tuple(PidGains.from_params(pids[axis], axis) for axis in ("X", "Y", "Z", "Yaw"))
