"""Flies a :class:`PositionController` against the project's simulated world in process (tests, benchmarks).

No ROS and no radio: the controller's cmd_vel goes through crazyflie_server's cmd_vel -> RPYT
mapping (``server.setpoint.setpoint_from_twist``) straight into ``Vehicle.set_rpyt``, and the pose
comes from the world's motion-capture model (``sim.room.mocap.MocapModel``: rate, latency, noise;
frames stamped with their capture time, as vicon_bridge does).
"""
from __future__ import annotations

import math
from typing import List, NamedTuple, Optional, Tuple

from crazyflie_controller.position_controller import Command, PoseSample, PositionController, State
from crazyflie_driver.mocap.frames import yaw_of
from crazyflie_driver.server.setpoint import setpoint_from_twist
from crazyflie_driver.sim.room.mocap import MocapModel
from crazyflie_driver.sim.room.world import World


class Sample(NamedTuple):
    t: float
    x: float
    y: float
    z: float
    yaw: float
    command: Command
    state: State
    goal: Optional[Tuple[float, float, float]] = None   # the goal position given to the controller


class WorldFlight:
    """One simulated Crazyflie, a mocap stream and a controller ticking at ``rate`` Hz of world time."""

    def __init__(self, controller: PositionController, world=None, name: str = "cf1", mass: float = 0.032,
                 position=(0.0, 0.0, 0.0), yaw: float = 0.0, rate: float = 50.0, mocap_rate: float = 100.0,
                 mocap_latency: float = 0.01, mocap_noise: float = 0.0005, seed: int = 1) -> None:
        self.world = world if world is not None else World(speed=0.0, seed=seed)
        self.name = name
        self.vehicle = self.world.add_vehicle(name, position=position, yaw=yaw, mass=mass)
        self.controller = controller
        self.period_ticks = max(1, int(round(1000.0 / rate)))
        self.mocap = MocapModel(self.world, rate=mocap_rate, position_noise=mocap_noise, orientation_noise=0.0,
                                latency=mocap_latency, seed=seed).attach()
        self.log: List[Sample] = []

    def pose(self) -> Optional[PoseSample]:
        """The latest motion-capture frame of this Crazyflie, or None before the first one."""
        got = self.mocap.latest_pose(self.name)
        if got is None:
            return None
        p, q, stamp = got
        return PoseSample(stamp, float(p[0]), float(p[1]), float(p[2]), yaw_of(q))

    def true_position(self) -> Tuple[float, float, float]:
        p, _ = self.vehicle.pose()
        return float(p[0]), float(p[1]), float(p[2])

    def true_yaw(self) -> float:
        _, q = self.vehicle.pose()
        return yaw_of(q)

    def run(self, seconds: float) -> None:
        """Controller cycles for ``seconds`` of world time."""
        run_together([self], seconds)

    def _command(self) -> Command:
        cmd = self.controller.update(self.world.time, self.pose())
        sp = setpoint_from_twist(cmd.linear_x, cmd.linear_y, cmd.linear_z, cmd.angular_z)
        self.vehicle.set_rpyt(sp.roll, sp.pitch, sp.yawrate, sp.thrust)
        return cmd

    def _record(self, cmd: Command) -> None:
        x, y, z = self.true_position()
        goal = self.controller.goal
        self.log.append(Sample(self.world.time, x, y, z, self.true_yaw(), cmd, self.controller.state,
                               None if goal is None else (goal.x, goal.y, goal.z)))

    def wait_for_pose(self, timeout: float = 1.0) -> None:
        """Idles (zero setpoints, which also release the thrust lock) until the first mocap frame."""
        end = self.world.time + timeout
        while self.pose() is None:
            if self.world.time >= end:
                raise TimeoutError("no motion-capture frame within %.1f s of world time" % timeout)
            self.run(1.0 / (1000.0 / self.period_ticks))

    def takeoff(self) -> bool:
        return self.controller.takeoff(self.world.time, self.pose())


def run_together(flights: List[WorldFlight], seconds: float) -> None:
    """Cycles flights that share one world in lockstep for ``seconds`` of world time (vehicles in
    sim.room do not interact, so comparing controllers side by side costs one world, not several)."""
    world, period = flights[0].world, flights[0].period_ticks
    if any(f.world is not world or f.period_ticks != period for f in flights):
        raise ValueError("flights run together must share the world and the control rate")
    for _ in range(int(round(seconds * 1000.0 / period))):
        commands = [f._command() for f in flights]
        world.step(period)
        for f, cmd in zip(flights, commands):
            f._record(cmd)


def takeoff_figures(log: List[Sample], goal_z: float, hover_window: Tuple[float, float]) -> dict:
    """Peak height, overshoot past the goal, time from lift-off to within 5 cm for good, hover RMS."""
    auto = [s for s in log if s.state != State.TAKING_OFF and s.state != State.IDLE]
    if not auto:
        return {"lifted_off": False}
    t_liftoff = auto[0].t
    peak = max(s.z for s in log)
    outside = [s.t for s in log if s.t >= t_liftoff and abs(s.z - goal_z) > 0.05]
    settle = (max(outside) - t_liftoff) if outside else 0.0
    window = [s for s in log if hover_window[0] <= s.t - t_liftoff <= hover_window[1]]
    rms_z = math.sqrt(sum((s.z - goal_z) ** 2 for s in window) / len(window)) if window else float("nan")
    rms_xy = math.sqrt(sum(s.x ** 2 + s.y ** 2 for s in window) / len(window)) if window else float("nan")
    return {"lifted_off": True, "t_liftoff": t_liftoff, "peak_z": peak, "overshoot": peak - goal_z,
            "settle_5cm": settle, "hover_rms_z": rms_z, "hover_rms_xy": rms_xy}


# ----------------------------------------------------------------------------- waypoint missions
class MissionWaypoint(NamedTuple):
    """``[x, y, z, yaw_deg, hold_s]`` as in crazyflie_demo's demo1.py / demo2.py."""

    x: float
    y: float
    z: float
    yaw_deg: float
    hold: float


# The chapter's demo1.py waypoints (crazyflie_demo/scripts/demo1.py): a 0.5 m move along x at 0.5 m,
# a diagonal move with a 0.2 m climb to 0.7 m, a 0.5 m move with a 90° turn, then back down to 0.5 m.
DEMO1 = (MissionWaypoint(0.0, 0.0, 0.5, 0.0, 2.0), MissionWaypoint(0.5, 0.0, 0.5, 0.0, 2.0),
         MissionWaypoint(0.5, 0.5, 0.7, 0.0, 2.0), MissionWaypoint(0.0, 0.5, 0.7, 90.0, 2.0),
         MissionWaypoint(0.0, 0.0, 0.5, 0.0, 2.0))


def _yaw_error_deg(a: float, b: float) -> float:
    return (a - b + 180.0) % 360.0 - 180.0


def fly_waypoints(flight: WorldFlight, waypoints, tolerance: float = 0.3, yaw_tolerance_deg: float = 10.0,
                  timeout: float = 60.0) -> List[float]:
    """Flies ``waypoints`` with the rule of crazyflie_demo's demo node; returns when each was reached.

    The goal is the current waypoint; the next one follows once the measured pose (what the demo
    node reads from tf, i.e. the motion-capture pose) has stayed within ``tolerance`` on every axis
    and ``yaw_tolerance_deg`` in yaw for the waypoint's hold time. The vehicle must already be
    airborne or taking off. Raises TimeoutError after ``timeout`` s of world time.
    """
    wps = [MissionWaypoint(*w) for w in waypoints]
    period = flight.period_ticks / 1000.0
    end = flight.world.time + timeout
    reached: List[float] = []
    inside_since: Optional[float] = None
    while len(reached) < len(wps):
        w = wps[len(reached)]
        flight.controller.set_goal(w.x, w.y, w.z, math.radians(w.yaw_deg))
        flight.run(period)
        now = flight.world.time
        if now >= end:
            raise TimeoutError("waypoint %d of %d not reached within %.0f s of world time"
                               % (len(reached) + 1, len(wps), timeout))
        p = flight.pose()
        inside = p is not None and (abs(p.x - w.x) < tolerance and abs(p.y - w.y) < tolerance
                                    and abs(p.z - w.z) < tolerance
                                    and abs(_yaw_error_deg(math.degrees(p.yaw), w.yaw_deg)) < yaw_tolerance_deg)
        if not inside:
            inside_since = None
            continue
        if inside_since is None:
            inside_since = now
        if now - inside_since >= w.hold:
            reached.append(now)
            inside_since = None
    return reached


class GoalSegment(NamedTuple):
    """How the vehicle flew from one goal to the next (true positions)."""

    t_start: float           # the goal changed (world time)
    t_end: float             # the next goal change (or the end of the log)
    start: Tuple[float, float, float]   # previous goal
    goal: Tuple[float, float, float]
    overshoot: float         # m past the goal height in the direction of a climb (> 0: beyond), else 0
    sag: float               # m below the goal height at worst while the goal height stays the same
    z_error_max: float       # m, largest |z − goal z| in the segment
    hold_errors: List[float]  # 3-D distances to the goal from first coming within 0.1 m of it
    hold_z_max: float        # m, largest |z − goal z| over the same samples


HOLD_TOLERANCE = 0.1   # m, as crazyflie_demo's mission summary


def goal_segments(log: List[Sample], hold_tolerance: float = HOLD_TOLERANCE) -> List[GoalSegment]:
    """Splits a log at each goal change (the first goal counts from lift-off)."""
    segments: List[GoalSegment] = []
    flying = [s for s in log if s.goal is not None and s.state not in (State.IDLE, State.TAKING_OFF)]
    if not flying:
        return segments
    groups: List[List[Sample]] = [[flying[0]]]
    for s in flying[1:]:
        if s.goal != groups[-1][-1].goal:
            groups.append([])
        groups[-1].append(s)
    prev_goal = (flying[0].x, flying[0].y, flying[0].z)
    for group in groups:
        g = group[0].goal
        zs = [s.z for s in group]
        dz = g[2] - prev_goal[2]
        overshoot = max(0.0, max(zs) - g[2]) if dz > 0.01 else max(0.0, g[2] - min(zs)) if dz < -0.01 else 0.0
        sag = max(0.0, g[2] - min(zs)) if abs(dz) <= 0.01 else 0.0
        holding, errors, hold_z = False, [], 0.0
        for s in group:
            d = math.sqrt((s.x - g[0]) ** 2 + (s.y - g[1]) ** 2 + (s.z - g[2]) ** 2)
            holding = holding or d < hold_tolerance
            if holding:
                errors.append(d)
                hold_z = max(hold_z, abs(s.z - g[2]))
        segments.append(GoalSegment(group[0].t, group[-1].t, prev_goal, g, overshoot, sag,
                                    max(abs(z - g[2]) for z in zs), errors, hold_z))
        prev_goal = g
    return segments


def hold_rms(segments: List[GoalSegment]) -> float:
    """RMS of the hold errors over all segments (the mission summary's "hold RMS")."""
    errors = [e for seg in segments for e in seg.hold_errors]
    return math.sqrt(sum(e * e for e in errors) / len(errors)) if errors else float("nan")
