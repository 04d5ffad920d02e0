"""Crazyswarm's scripting objects (``TimeHelper``, ``Crazyflie``, ``CrazyflieServer``) without ROS.

Names, argument names, defaults and units are Crazyswarm's documented ones (``pycrazyswarm``):
heights and positions in metres, durations in seconds, yaw in radians (``goTo``, ``cmdPosition``,
``cmdFullState``), yaw rates in degrees per second (``cmdVelocityWorld``, ``cmdVel``, ``cmdHover``),
body rates in rad/s; ``cmdHover`` (Crazyswarm2's) takes velocities in the Crazyflie's own frame.
Each call checks its arguments, converts what the wire wants (``cmdPosition``'s yaw to the message's
degrees, ``cmdFullState``'s yaw to a quaternion, a ``Trajectory`` to pieces) and hands plain values
to a ``Backend``: the ROS adapter (``ros_backend``) or a test's fake. Nothing is sent
when a check fails; features of Crazyswarm's own firmware fork raise ``NotSupported``.
"""
from __future__ import annotations

import math
import numbers
from typing import Any, Dict, Iterable, List, Mapping, Optional, Protocol, Sequence, Tuple

from crazyflie_driver.errors import CommandValueError, NotSupported
from crazyflie_driver.protocol.checks import finite
from crazyflie_driver.protocol.checks import group_mask as checked_group_mask
from crazyflie_driver.protocol.trajectory import Piece, check_id

Vec3 = Tuple[float, float, float]
ALL_GROUPS = 0


class Backend(Protocol):
    """What the objects need from a running swarm. ``ns`` is a Crazyflie's namespace (``/cf1``),
    or ``""`` for the swarm-wide (broadcast) services."""

    def takeoff(self, ns: str, group_mask: int, height: float, duration: float) -> None: ...
    def land(self, ns: str, group_mask: int, height: float, duration: float) -> None: ...
    def stop(self, ns: str, group_mask: int) -> None: ...
    def go_to(self, ns: str, group_mask: int, relative: bool, goal: Vec3, yaw: float, duration: float) -> None: ...
    def upload_trajectory(self, ns: str, trajectory_id: int, piece_offset: int, pieces: List[Piece]) -> None: ...
    def start_trajectory(self, ns: str, group_mask: int, trajectory_id: int, timescale: float, reverse: bool,
                         relative: bool) -> None: ...
    def set_group_mask(self, ns: str, group_mask: int) -> None: ...
    def notify_setpoints_stop(self, ns: str, group_mask: int, remain_valid_ms: int) -> None: ...
    def emergency(self) -> None: ...
    def set_param(self, name: str, value: Any) -> None: ...
    def get_param(self, name: str) -> Any: ...
    def update_params(self, ns: str, names: List[str]) -> None: ...
    def cmd_full_state(self, ns: str, pos: Vec3, vel: Vec3, acc: Vec3, quaternion: Tuple[float, float, float, float],
                       omega: Vec3) -> None: ...
    def cmd_velocity_world(self, ns: str, vel: Vec3, yaw_rate_deg: float) -> None: ...
    def cmd_hover(self, ns: str, vx: float, vy: float, yaw_rate_deg: float, z_distance: float) -> None: ...
    def cmd_stop(self, ns: str) -> None: ...
    def cmd_vel(self, ns: str, roll_deg: float, pitch_deg: float, yawrate_deg: float, thrust: float) -> None: ...
    def cmd_position(self, ns: str, pos: Vec3, yaw_deg: float) -> None: ...
    def position(self, ns: str) -> Vec3: ...


class Clock(Protocol):
    def time(self) -> float: ...
    def sleep(self, duration: float) -> None: ...
    def sleep_for_rate(self, rate_hz: float) -> None: ...
    def is_shutdown(self) -> bool: ...


# -- checks ------------------------------------------------------------------------------------------
def _vec3(name: str, value: Iterable[float]) -> Vec3:
    try:
        values = [float(v) for v in value]
    except (TypeError, ValueError):
        raise CommandValueError("%s must be 3 numbers [x, y, z], got %r" % (name, value)) from None
    if len(values) != 3:
        raise CommandValueError("%s must be 3 numbers [x, y, z], got %d" % (name, len(values)))
    return tuple(finite("%s %s" % (name, axis), v) for axis, v in zip("xyz", values))


def _duration(value: float) -> float:
    d = finite("duration", value)
    if d <= 0:
        raise CommandValueError("duration must be > 0 s, got %r" % (value,))
    return d


def _mask(value: int) -> int:
    if isinstance(value, bool):
        raise CommandValueError("groupMask must be an integer 0..255, got %r" % (value,))
    return checked_group_mask(value)


def yaw_quaternion(yaw: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` rad about z."""
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


def trajectory_pieces(trajectory: Any) -> List[Piece]:
    """The pieces of a ``uav_trajectory.Trajectory`` (ours or any object with Crazyswarm's
    ``polynomials[i].duration/px.p/py.p/pz.p/pyaw.p``)."""
    from crazyflie_driver.protocol.trajectory import make_piece

    if hasattr(trajectory, "pieces") and callable(trajectory.pieces):
        return trajectory.pieces()
    polys = getattr(trajectory, "polynomials", None)
    if not polys:
        raise CommandValueError("uploadTrajectory needs a uav_trajectory.Trajectory with pieces (loadcsv a file), "
                                "got %r" % (trajectory,))
    return [make_piece(p.duration, list(p.px.p), list(p.py.p), list(p.pz.p), list(p.pyaw.p), index=i)
            for i, p in enumerate(polys)]


def _param_name(name: str) -> str:
    """Crazyswarm writes parameters as ``group/name``; ``group.name`` is accepted too."""
    n = str(name).strip("/").replace(".", "/")
    if n.count("/") != 1 or not all(n.split("/")):
        raise CommandValueError("parameter %r: give it as group/name (e.g. ring/effect)" % (name,))
    return n


# -- the objects -------------------------------------------------------------------------------------
class TimeHelper:
    """Time for scripts: ``time()`` (s), ``sleep(duration)``, ``sleepForRate(rateHz)``, ``isShutdown()``.
    On ROS time against a running swarm; on the simulated world's time with ``--sim``."""

    def __init__(self, clock: Clock) -> None:
        self._clock = clock
        self.visualizer = _NoVisualizer()

    def time(self) -> float:
        return self._clock.time()

    def sleep(self, duration: float) -> None:
        self._clock.sleep(finite("duration", duration))

    def sleepForRate(self, rateHz: float) -> None:
        rate = finite("rateHz", rateHz)
        if rate <= 0:
            raise CommandValueError("rateHz must be > 0, got %r" % (rateHz,))
        self._clock.sleep_for_rate(rate)

    def isShutdown(self) -> bool:
        return self._clock.is_shutdown()


class _NoVisualizer:
    """Crazyswarm's scripts may draw into ``timeHelper.visualizer``; there is none here."""

    def __getattr__(self, name: str):
        return lambda *args, **kwargs: None


class Crazyflie:
    """One Crazyflie: ``id`` (its radio address's last byte), ``prefix`` (its namespace, ``/cf<id>``),
    ``initialPosition`` (m, from the YAML)."""

    def __init__(self, id: int, initialPosition: Sequence[float], backend: Backend, prefix: Optional[str] = None):
        import numpy as np
        self.id = id
        self.prefix = prefix if prefix is not None else "/cf%d" % id
        self.initialPosition = np.array(initialPosition, dtype=float)
        self._backend = backend

    def __repr__(self) -> str:
        return "Crazyflie(id=%d, prefix=%r)" % (self.id, self.prefix)

    # -- high-level commander (onboard planner) --
    def setGroupMask(self, groupMask: int) -> None:
        """Membership in up to 8 groups (bit i = group i) for group-masked commands."""
        self._backend.set_group_mask(self.prefix, _mask(groupMask))

    def enableCollisionAvoidance(self, others, ellipsoidRadii, *args, **kwargs) -> None:
        raise NotSupported("enableCollisionAvoidance needs the collision avoidance (buffered Voronoi cells, colAv.* "
                           "parameters) of Crazyswarm's own firmware fork; Bitcraze's firmware, which the simulated "
                           "and real Crazyflies here run, has none. Keep the Crazyflies apart in the plan instead")

    def disableCollisionAvoidance(self) -> None:
        raise NotSupported("disableCollisionAvoidance: Bitcraze's firmware has no onboard collision avoidance to "
                           "disable (it belongs to Crazyswarm's firmware fork)")

    def takeoff(self, targetHeight: float, duration: float, groupMask: int = ALL_GROUPS) -> None:
        """Straight up to ``targetHeight`` (m, absolute z) in ``duration`` s, then hover. Returns at once."""
        self._backend.takeoff(self.prefix, _mask(groupMask), finite("targetHeight", targetHeight), _duration(duration))

    def land(self, targetHeight: float, duration: float, groupMask: int = ALL_GROUPS) -> None:
        """Straight down to ``targetHeight`` (m; a few cm above the floor) in ``duration`` s, motors off after."""
        self._backend.land(self.prefix, _mask(groupMask), finite("targetHeight", targetHeight), _duration(duration))

    def stop(self, groupMask: int = ALL_GROUPS) -> None:
        """Motors off now (not an emergency: later commands start them again)."""
        self._backend.stop(self.prefix, _mask(groupMask))

    def goTo(self, goal: Sequence[float], yaw: float, duration: float, relative: bool = False,
             groupMask: int = ALL_GROUPS) -> None:
        """Smoothly to ``goal`` (m; an offset when ``relative``) and ``yaw`` (rad) in ``duration`` s."""
        self._backend.go_to(self.prefix, _mask(groupMask), bool(relative), _vec3("goal", goal), finite("yaw", yaw),
                            _duration(duration))

    def uploadTrajectory(self, trajectoryId: int, pieceOffset: int, trajectory) -> None:
        """Write ``trajectory`` (a ``uav_trajectory.Trajectory``) into the Crazyflie's trajectory memory,
        starting at piece ``pieceOffset``, as trajectory ``trajectoryId`` (0..30)."""
        if isinstance(pieceOffset, bool) or not isinstance(pieceOffset, int) or pieceOffset < 0:
            raise CommandValueError("pieceOffset must be an integer >= 0 (the first piece's slot), got %r"
                                    % (pieceOffset,))
        self._backend.upload_trajectory(self.prefix, check_id(trajectoryId), pieceOffset, trajectory_pieces(trajectory))

    def startTrajectory(self, trajectoryId: int, timescale: float = 1.0, reverse: bool = False, relative: bool = True,
                        groupMask: int = ALL_GROUPS) -> None:
        """Fly an uploaded trajectory (``timescale`` > 1 is slower); ``relative``: from the current setpoint."""
        self._backend.start_trajectory(self.prefix, _mask(groupMask), check_id(trajectoryId),
                                       _positive("timescale", timescale), bool(reverse), bool(relative))

    def notifySetpointsStop(self, remainValidMillisecs: int = 100, groupMask: int = ALL_GROUPS) -> None:
        """Hand control back to the high-level commander after streaming setpoints (the last one
        stays valid ``remainValidMillisecs`` ms)."""
        if isinstance(remainValidMillisecs, bool) or not isinstance(remainValidMillisecs, int) \
                or not 0 <= remainValidMillisecs <= 0xFFFFFFFF:
            raise CommandValueError("remainValidMillisecs must be an integer >= 0 (ms), got %r"
                                    % (remainValidMillisecs,))
        self._backend.notify_setpoints_stop(self.prefix, _mask(groupMask), remainValidMillisecs)

    # -- state and parameters --
    def position(self):
        """The latest position (m) from motion capture (tf world -> this Crazyflie) where something
        publishes it, else the onboard estimate's ``pose`` topic; waits for the first one."""
        import numpy as np
        return np.array(self._backend.position(self.prefix))

    def getParam(self, name: str) -> Any:
        """The value last written through this API or the server (the ROS parameter ``<prefix>/group/name``)."""
        return self._backend.get_param("%s/%s" % (self.prefix, _param_name(name)))

    def setParam(self, name: str, value: Any) -> None:
        self.setParams({name: value})

    def setParams(self, params: Mapping[str, Any]) -> None:
        names = [_param_name(n) for n in params]
        for n, value in zip(names, params.values()):
            self._backend.set_param("%s/%s" % (self.prefix, n), _param_value(n, value))
        self._backend.update_params(self.prefix, names)

    def setLEDColor(self, r: float, g: float, b: float) -> None:
        """The LED ring deck's solid colour, each component 0..1 (needs ``ring/effect`` 7 and the deck)."""
        values = {}
        for name, v in (("ring/solidRed", r), ("ring/solidGreen", g), ("ring/solidBlue", b)):
            v = finite(name, v)
            if not 0.0 <= v <= 1.0:
                raise CommandValueError("%s: colour components are 0..1, got %r" % (name, v))
            values[name] = int(v * 255)
        self.setParams(values)

    # -- streaming setpoints (low level: they take priority over the high-level commander) --
    def cmdFullState(self, pos, vel, acc, yaw: float, omega) -> None:
        """Position (m), velocity (m/s), acceleration (m/s²), yaw (rad), body rates (rad/s)."""
        self._backend.cmd_full_state(self.prefix, _vec3("pos", pos), _vec3("vel", vel), _vec3("acc", acc),
                                     yaw_quaternion(finite("yaw", yaw)), _vec3("omega", omega))

    def cmdVelocityWorld(self, vel, yawRate: float) -> None:
        """Velocity in the world frame (m/s) and yaw rate (deg/s)."""
        self._backend.cmd_velocity_world(self.prefix, _vec3("vel", vel), finite("yawRate", yawRate))

    def cmdHover(self, vx: float, vy: float, yawRate: float, zDistance: float) -> None:
        """Crazyswarm2's hover setpoint: velocities in the Crazyflie's own frame (m/s: ``vx`` forward,
        ``vy`` left, turning with it), yaw rate (deg/s, counterclockwise positive) and height (m,
        absolute). The firmware's Mellinger controller flies no velocities (it holds the height
        only): set ``stabilizer/controller`` 1 (PID) for the body velocities to act."""
        self._backend.cmd_hover(self.prefix, finite("vx", vx), finite("vy", vy), finite("yawRate", yawRate),
                                finite("zDistance", zDistance))

    def cmdStop(self) -> None:
        """Motors off (a stop setpoint); later setpoints or commands start them again."""
        self._backend.cmd_stop(self.prefix)

    def cmdVel(self, roll: float, pitch: float, yawrate: float, thrust: float) -> None:
        """Roll and pitch (deg), yaw rate (deg/s), thrust (0..65535): the chapter's cmd_vel."""
        t = finite("thrust", thrust)
        if not 0 <= t <= 0xFFFF:
            raise CommandValueError("thrust must be 0..65535, got %r" % (thrust,))
        self._backend.cmd_vel(self.prefix, finite("roll", roll), finite("pitch", pitch), finite("yawrate", yawrate), t)

    def cmdPosition(self, pos, yaw: float = 0) -> None:
        """Position (m) and yaw (rad, as Crazyswarm documents it; the message carries degrees)."""
        self._backend.cmd_position(self.prefix, _vec3("pos", pos), math.degrees(finite("yaw", yaw)))


class CrazyflieServer:
    """Every Crazyflie of the YAML (``crazyflies``, ``crazyfliesById``) and the swarm-wide
    (broadcast) commands."""

    def __init__(self, crazyflies: List[Crazyflie], backend: Backend) -> None:
        self._backend = backend
        self.crazyflies = list(crazyflies)
        self.crazyfliesById: Dict[int, Crazyflie] = {cf.id: cf for cf in self.crazyflies}

    def emergency(self) -> None:
        """Motors off for every Crazyflie, for good: they ignore everything until restarted."""
        self._backend.emergency()

    def takeoff(self, targetHeight: float, duration: float, groupMask: int = ALL_GROUPS) -> None:
        self._backend.takeoff("", _mask(groupMask), finite("targetHeight", targetHeight), _duration(duration))

    def land(self, targetHeight: float, duration: float, groupMask: int = ALL_GROUPS) -> None:
        self._backend.land("", _mask(groupMask), finite("targetHeight", targetHeight), _duration(duration))

    def stop(self, groupMask: int = ALL_GROUPS) -> None:
        """Motors off for the group (Crazyswarm's simulator has it; its server left it out)."""
        self._backend.stop("", _mask(groupMask))

    def goTo(self, goal, yaw: float, duration: float, groupMask: int = ALL_GROUPS) -> None:
        """Every Crazyflie of the group moves by ``goal`` (an offset, m) and turns to ``yaw`` (rad):
        a broadcast goTo is always relative, one absolute goal would send all to one point."""
        self._backend.go_to("", _mask(groupMask), True, _vec3("goal", goal), finite("yaw", yaw), _duration(duration))

    def startTrajectory(self, trajectoryId: int, timescale: float = 1.0, reverse: bool = False, relative: bool = True,
                        groupMask: int = ALL_GROUPS) -> None:
        """Each Crazyflie of the group flies its own uploaded trajectory ``trajectoryId``, from where it is."""
        if not relative:
            raise NotSupported("startTrajectory(relative=False) on the whole swarm: the broadcast start is always "
                               "relative (Crazyswarm's server ignored the flag too, so every Crazyflie would fly the "
                               "same absolute path). Call each Crazyflie's startTrajectory(..., relative=False)")
        self._backend.start_trajectory("", _mask(groupMask), check_id(trajectoryId), _positive("timescale", timescale),
                                       bool(reverse), True)

    def setParam(self, name: str, value: Any) -> None:
        """One parameter for every Crazyflie (``/allcfs/group/name``, then ``/update_params``)."""
        n = _param_name(name)
        self._backend.set_param("/allcfs/" + n, _param_value(n, value))
        self._backend.update_params("", [n])


def _positive(name: str, value: float) -> float:
    v = finite(name, value)
    if v <= 0:
        raise CommandValueError("%s must be > 0, got %r" % (name, value))
    return v


def _param_value(name: str, value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real) and math.isfinite(value):
        return float(value)
    raise CommandValueError("parameter %s: the value must be a finite number, got %r" % (name, value))
