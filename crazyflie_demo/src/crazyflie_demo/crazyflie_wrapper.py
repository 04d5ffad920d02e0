"""crazyflie_ros HEAD's ``crazyflie.py``: ``Crazyflie(prefix, tf)``, one Crazyflie's high-level
services and parameters by its namespace, for scripts written against HEAD's demo.

Same constructor, method names, arguments and defaults as HEAD's class (units: m, s, yaw in rad).
Where HEAD's class could not run, this one does what its names say: ``position()`` reads tf
``world -> <prefix>`` (HEAD read ``/cf<id>`` with an ``id`` it never set), ``setParams`` takes any
mapping (HEAD's used Python 2's ``iteritems``) and ``arrayToGeometryPoint`` builds a Point (HEAD's
module did not import ``geometry_msgs``). A refused service call raises ``rospy.ServiceException``
with the server's reason, as a ServiceProxy does.
"""
from __future__ import annotations

from typing import Any, List, Mapping, Optional, Sequence

import numpy as np
import rospy
from geometry_msgs.msg import Point

from crazyflie_driver.protocol.trajectory import Piece, make_piece
from crazyflie_driver.srv import (
    GoTo,
    Land,
    SetGroupMask,
    StartTrajectory,
    Stop,
    Takeoff,
    UpdateParams,
    UploadTrajectory,
)
from pycrazyswarm.ros_backend import pieces_msg

#: s ``position()`` waits for the transform, as HEAD's ``waitForTransform`` did.
POSITION_WAIT_S = 10.0
WORLD_FRAME = "world"
SERVICES = (("set_group_mask", SetGroupMask), ("takeoff", Takeoff), ("land", Land), ("stop", Stop),
            ("go_to", GoTo), ("upload_trajectory", UploadTrajectory), ("start_trajectory", StartTrajectory),
            ("update_params", UpdateParams))


def trajectory_pieces(trajectory: Any) -> List[Piece]:
    """The checked pieces of a ``uav_trajectory.Trajectory``: ours (``pieces()``) or one of HEAD's or
    Crazyswarm's own module (``polynomials``, each with ``duration`` and ``px/py/pz/pyaw.p``), which a
    script's directory may put first on the path."""
    if hasattr(trajectory, "pieces"):
        return trajectory.pieces()
    return [make_piece(p.duration, list(p.px.p), list(p.py.p), list(p.pz.p), list(p.pyaw.p), index=i)
            for i, p in enumerate(trajectory.polynomials)]


def arrayToGeometryPoint(a: Sequence[float]) -> Point:  # noqa: N802 (HEAD's name)
    return Point(float(a[0]), float(a[1]), float(a[2]))


class Crazyflie:
    """One Crazyflie served under ``prefix`` (e.g. ``/crazyflie``); ``tf`` is a tf listener (or None
    when ``position()`` is not used). Waits for every service first, as HEAD's class does."""

    def __init__(self, prefix: str, tf: Optional[Any]) -> None:
        self.prefix = prefix
        self.tf = tf
        proxies = {}
        for name, kind in SERVICES:
            rospy.wait_for_service(prefix + "/" + name)
            proxies[name] = rospy.ServiceProxy(prefix + "/" + name, kind)
        self.setGroupMaskService = proxies["set_group_mask"]
        self.takeoffService = proxies["takeoff"]
        self.landService = proxies["land"]
        self.stopService = proxies["stop"]
        self.goToService = proxies["go_to"]
        self.uploadTrajectoryService = proxies["upload_trajectory"]
        self.startTrajectoryService = proxies["start_trajectory"]
        self.updateParamsService = proxies["update_params"]

    def setGroupMask(self, groupMask: int) -> None:  # noqa: N802,N803
        self.setGroupMaskService(groupMask)

    def takeoff(self, targetHeight: float, duration: float, groupMask: int = 0) -> None:  # noqa: N803
        self.takeoffService(groupMask, targetHeight, rospy.Duration.from_sec(duration))

    def land(self, targetHeight: float, duration: float, groupMask: int = 0) -> None:  # noqa: N803
        self.landService(groupMask, targetHeight, rospy.Duration.from_sec(duration))

    def stop(self, groupMask: int = 0) -> None:  # noqa: N803
        self.stopService(groupMask)

    def goTo(self, goal: Sequence[float], yaw: float, duration: float, relative: bool = False,  # noqa: N802
             groupMask: int = 0) -> None:  # noqa: N803
        self.goToService(groupMask, relative, arrayToGeometryPoint(goal), yaw, rospy.Duration.from_sec(duration))

    def uploadTrajectory(self, trajectoryId: int, pieceOffset: int, trajectory: Any) -> None:  # noqa: N802,N803
        """``trajectory``: a ``uav_trajectory.Trajectory`` (its pieces are checked before sending)."""
        self.uploadTrajectoryService(trajectoryId, pieceOffset, pieces_msg(trajectory_pieces(trajectory)))

    def startTrajectory(self, trajectoryId: int, timescale: float = 1.0, reverse: bool = False,  # noqa: N802,N803
                        relative: bool = True, groupMask: int = 0) -> None:  # noqa: N803
        self.startTrajectoryService(groupMask, trajectoryId, timescale, reverse, relative)

    def position(self) -> np.ndarray:
        """The latest tf position of frame ``<prefix>`` in ``world`` (m)."""
        frame = self.prefix.strip("/")
        self.tf.waitForTransform(WORLD_FRAME, frame, rospy.Time(0), rospy.Duration(POSITION_WAIT_S))
        position, _ = self.tf.lookupTransform(WORLD_FRAME, frame, rospy.Time(0))
        return np.array(position)

    def getParam(self, name: str) -> Any:  # noqa: N802
        return rospy.get_param(self.prefix + "/" + name)

    def setParam(self, name: str, value: Any) -> None:  # noqa: N802
        rospy.set_param(self.prefix + "/" + name, value)
        self.updateParamsService([name])

    def setParams(self, params: Mapping[str, Any]) -> None:  # noqa: N802
        for name, value in params.items():
            rospy.set_param(self.prefix + "/" + name, value)
        self.updateParamsService(list(params.keys()))
