"""The onboard ``pose`` topic (crazyflie_ros HEAD's): the estimator's pose from one log block, without ROS.

Position ``stateEstimate.x/y/z`` (float, m) and the attitude ``stateEstimateZ.quat`` (the firmware's
compressed quaternion, one 32-bit word): 16 bytes, so one log packet carries the whole pose.
"""
from __future__ import annotations

from typing import Sequence, Tuple

from crazyflie_driver.crtp.quaternion import decompress_quaternion
from crazyflie_driver.server.log_plan import LogBlockSpec

POSE_TOPIC = "pose"
POSE_VARIABLES = ("stateEstimate.x", "stateEstimate.y", "stateEstimate.z", "stateEstimateZ.quat")


def pose_block(period_ms: int) -> LogBlockSpec:
    return LogBlockSpec(POSE_TOPIC, int(period_ms), POSE_VARIABLES)


def is_pose_block(spec: LogBlockSpec) -> bool:
    return spec.topic_name == POSE_TOPIC and tuple(spec.variables) == POSE_VARIABLES


def pose_from_log(values: Sequence[float]) -> Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]:
    """(position m, quaternion x, y, z, w) from one packet of the pose block."""
    return (float(values[0]), float(values[1]), float(values[2])), decompress_quaternion(int(values[3]))
