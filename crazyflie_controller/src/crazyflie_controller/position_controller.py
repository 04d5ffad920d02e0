"""The position controller's state machine, free of ROS: pose and time in, a cmd_vel-like command out.

States (as in the original): Idle (zero setpoints), TakingOff (open-loop thrust ramp until the
vehicle is ``takeoff_height`` up or the thrust passes ``takeoff_max_thrust``), Automatic (four
PIDs on the goal error expressed in the vehicle's yaw frame) and Landing (goal at start height +
``landing_height``, then Idle).

Differences from the original, each a fix:

* all four PIDs are reset on hand-over (the original never reset Y);
* a pose older than ``pose_timeout`` is never acted on: the output holds level attitude, zero
  yaw rate and the hover thrust (the Z integrator), and if the pose stays missing for
  ``lost_pose_land_timeout`` the vehicle sinks open loop (``lost_pose_thrust_drop`` below the hover
  thrust) for ``lost_pose_descent_time`` and the motors stop; a pose that comes back during that
  descent turns it into a closed-loop landing;
* a pose whose values stay bit-identical for longer than ``frozen_pose_timeout`` while airborne
  (Automatic or Landing) is stale too, however fresh its stamps: real motion capture always
  carries noise, so such a pose comes from a frozen tracker that repeats its last solution; the
  same hold → blind descent → motors off follows, and values that change again end it;
* a goal jump does not kick the D term (derivative on the measured velocity);
* errors are rotated by the yaw only (the original used the full 3-D rotation, so tilt leaked in);
* ``takeoff_handover="smooth"``: at lift-off the setpoint starts at the vehicle's position and
  velocity and glides to the goal, and the Z integrator is preloaded with the hover thrust
  estimated from the lift-off kinematics instead of the (higher) thrust reached when lift-off was
  detected (see ``liftoff``);
* ``goal_change="smooth"``: a new goal in Automatic is not a step; the setpoint glides to it
  (``goal_speed`` / ``goal_accel``), its velocity fed to the Z D term;
* ``z_integration="conditional"``: the Z integrator holds while a goal glide moves the setpoint
  vertically and while the thrust is saturated toward the error (no wind-up on climbs);
* ``tilt_compensation``: thrust / (cos roll · cos pitch) of the commanded attitude, so horizontal
  moves keep the height;
* ``hover_refine_time``: when the take-off glide arrives, the Z integral goes back to the lift-off
  estimate and is then set to the hover thrust fitted over the next ``hover_refine_time`` s
  (``hover_thrust``), so the chapter's slow Z mode is not left ringing after the take-off.

:meth:`ControllerConfig.original` (takeoff_handover "original", derivative "error", goal_change
"step", z_integration "always", no tilt compensation, hover_refine_time 0) reproduces the original.

Sign conventions of the output follow crazyflie_ros' cmd_vel: linear.x = pitch command [deg]
(positive moves the vehicle forward, +x of its body), linear.y = roll [deg] (positive moves it to
−y, hence the negative Y gains), linear.z = thrust [0..60000], angular.z = yaw rate [deg/s]
(positive turns clockwise, hence the negative yaw gains).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Callable, NamedTuple, Optional, Tuple

from crazyflie_driver.mocap.frames import yaw_of

from .hover_thrust import HoverThrustFit
from .liftoff import LiftoffEstimator
from .pid import DERIVATIVE_MODES, PID, PidGains, clamp
from .setpoint_ramp import SetpointRamp

HANDOVER_MODES = ("smooth", "original")
# counts: a hover-thrust fit this far from the lift-off estimate (within ≈ 200 counts in the
# simulator) is taken for a disturbance, not a better estimate
MAX_HOVER_REFINEMENT = 2000.0
GOAL_CHANGE_MODES = ("smooth", "step")
Z_INTEGRATION_MODES = ("conditional", "always")
# ControllerConfig's behaviour switches: (field, parameter name in messages, modes)
_MODE_FIELDS = (("takeoff_handover", "takeoffHandover", HANDOVER_MODES),
                ("derivative", "derivative", DERIVATIVE_MODES),
                ("goal_change", "goalChange", GOAL_CHANGE_MODES),
                ("z_integration", "zIntegration", Z_INTEGRATION_MODES))
# ControllerConfig's fields that must be positive and finite
_POSITIVE_FIELDS = ("takeoff_thrust_rate", "takeoff_height", "takeoff_max_thrust", "pose_timeout",
                    "lost_pose_land_timeout", "lost_pose_descent_time", "handover_speed", "handover_accel",
                    "goal_speed", "goal_accel")


class State(enum.Enum):
    IDLE = "Idle"
    TAKING_OFF = "TakingOff"
    AUTOMATIC = "Automatic"
    LANDING = "Landing"


class Safety(enum.Enum):
    """What the controller does about the pose, published beside the state."""

    OK = "ok"
    NO_POSE = "no pose"                         # idle and no fresh pose: take-off is refused
    HOLDING = "pose stale: holding level"       # airborne, pose older than pose_timeout
    BLIND_DESCENT = "pose lost: descending"     # stale longer than lost_pose_land_timeout
    LANDED_BLIND = "pose lost: motors stopped"  # blind descent over, idle until a new take-off
    EMERGENCY = "emergency stop: restart and re-add the Crazyflie to fly"   # the server's emergency service was called


class Command(NamedTuple):
    """The cmd_vel Twist fields the controller sets."""

    linear_x: float   # pitch [deg]
    linear_y: float   # roll [deg]
    linear_z: float   # thrust [counts]
    angular_z: float  # yaw rate [deg/s]


ZERO = Command(0.0, 0.0, 0.0, 0.0)


class PoseSample(NamedTuple):
    """Vehicle pose in the world frame at ``stamp`` (seconds, same clock as ``now``)."""

    stamp: float
    x: float
    y: float
    z: float
    yaw: float  # rad

    @classmethod
    def from_quaternion(cls, stamp: float, position: Tuple[float, float, float],
                        quaternion: Tuple[float, float, float, float]) -> PoseSample:
        """``quaternion`` is (x, y, z, w), as in ROS messages."""
        return cls(stamp, position[0], position[1], position[2], yaw_from_quaternion(*quaternion))


class Goal(NamedTuple):
    x: float
    y: float
    z: float
    yaw: float  # rad


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rad) of the quaternion (x, y, z, w), as ROS messages order it."""
    return yaw_of((x, y, z, w))


def wrap_angle(a: float) -> float:
    """Angle in [−π, π)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def rotate_to_body(x: float, y: float, yaw: float) -> Tuple[float, float]:
    """World-frame horizontal vector expressed in the frame of a vehicle at ``yaw`` (rotation by −yaw)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return c * x + s * y, -s * x + c * y


@dataclass
class ControllerConfig:
    """Gains (``PIDs/<axis>``) and the behaviour parameters; defaults are the original's where it had one."""

    x: PidGains
    y: PidGains
    z: PidGains
    yaw: PidGains
    takeoff_thrust_rate: float = 10000.0   # counts/s
    takeoff_height: float = 0.05           # m above the start height that ends the ramp
    takeoff_max_thrust: float = 50000.0    # the ramp also ends above this thrust
    landing_height: float = 0.05           # m above the start height where landing ends
    pose_timeout: float = 0.1              # s: an older pose is stale
    frozen_pose_timeout: float = 0.1       # s of bit-identical pose values while airborne: frozen, stale (0: off)
    lost_pose_land_timeout: float = 0.5    # s of stale pose before the blind descent starts
    lost_pose_thrust_drop: float = 1500.0  # counts below the hover thrust during the blind descent
    lost_pose_descent_time: float = 2.0    # s of blind descent before the motors stop
    takeoff_handover: str = "smooth"       # or "original"
    derivative: str = "measurement"        # or "error" (the original, kicks on goal jumps)
    handover_speed: float = 0.2            # m/s: max speed of the setpoint after take-off / landing
    handover_accel: float = 0.3            # m/s²
    liftoff_lag: float = 0.07              # s from thrust command to thrust (motor lag + half a tick)
    goal_change: str = "smooth"            # or "step" (the original: a new goal applies at once)
    goal_speed: float = 0.5                # m/s: max speed of the setpoint gliding to a new goal
    goal_accel: float = 1.0                # m/s²
    tilt_compensation: bool = True         # thrust / (cos roll · cos pitch) of the commanded attitude
    z_integration: str = "conditional"     # or "always" (the original: integrate the z error every cycle)
    hover_refine_time: float = 1.5         # s of hover after the take-off glide fitted for the hover thrust (0: off)

    def __post_init__(self) -> None:
        self._check_modes()
        self._check_positive()
        self._check_ranges()

    def _check_modes(self) -> None:
        """Each behaviour switch is one of its modes (ValueError naming the parameter otherwise)."""
        for field, param, modes in _MODE_FIELDS:
            if getattr(self, field) not in modes:
                raise ValueError("%s must be one of %s, got %r" % (param, modes, getattr(self, field)))
        if not isinstance(self.tilt_compensation, bool):
            raise ValueError("tiltCompensation must be true or false, got %r" % (self.tilt_compensation,))

    def _check_positive(self) -> None:
        for name in _POSITIVE_FIELDS:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0 and value != float("inf")):
                raise ValueError("%s must be a positive number, got %r" % (name, value))

    def _check_ranges(self) -> None:
        """The fields that may be 0, each within its range."""
        if not 0 <= self.liftoff_lag < 1.0:
            raise ValueError("liftoff_lag must be in [0, 1) s, got %r" % (self.liftoff_lag,))
        if not (isinstance(self.hover_refine_time, (int, float)) and 0 <= self.hover_refine_time < 60):
            raise ValueError("hover_refine_time must be in [0, 60) s, got %r" % (self.hover_refine_time,))
        if not (isinstance(self.frozen_pose_timeout, (int, float)) and 0 <= self.frozen_pose_timeout < float("inf")):
            raise ValueError("frozen_pose_timeout must be >= 0 s (0: off), got %r" % (self.frozen_pose_timeout,))
        if not self.lost_pose_thrust_drop >= 0:
            raise ValueError("lost_pose_thrust_drop must be >= 0, got %r" % (self.lost_pose_thrust_drop,))

    @classmethod
    def original(cls, x: PidGains, y: PidGains, z: PidGains, yaw: PidGains, **kw) -> ControllerConfig:
        """The original controller's take-off, goal-change, derivative and thrust behaviour (for comparison)."""
        kw.setdefault("takeoff_handover", "original")
        kw.setdefault("derivative", "error")
        kw.setdefault("goal_change", "step")
        kw.setdefault("tilt_compensation", False)
        kw.setdefault("z_integration", "always")
        kw.setdefault("hover_refine_time", 0.0)
        return cls(x, y, z, yaw, **kw)


Logger = Callable[[str, str], None]  # (level "info" | "warn" | "error", message)


def _no_log(level: str, message: str) -> None:
    pass


class PositionController:
    """Feed it :meth:`update` at the control rate; :meth:`takeoff`, :meth:`land`, :meth:`set_goal` any time."""

    def __init__(self, config: ControllerConfig, log: Logger = _no_log) -> None:
        self.config = config
        self._log = log
        self.pids = {axis: PID(getattr(config, axis), config.derivative, axis.upper() if axis != "yaw" else "Yaw")
                     for axis in ("x", "y", "z", "yaw")}
        self.state = State.IDLE
        self.safety = Safety.NO_POSE
        self.goal: Optional[Goal] = None
        self.thrust = 0.0                 # take-off ramp thrust
        self.start_z = 0.0
        self.liftoff_thrust: Optional[float] = None
        self.preload_thrust: Optional[float] = None
        self.refined_thrust: Optional[float] = None   # hover thrust fitted after the take-off glide
        self.last_command = ZERO
        self._ramp: Optional[SetpointRamp] = None
        self._goal_glide = False          # the ramp glides to a new goal (not the take-off/landing glide)
        self._glide_holds_integral = False   # conditional z integration holds the integral during this glide
        self._takeoff_glide = False       # the ramp is the glide that started at lift-off (maybe redirected)
        self._hover_fit: Optional[HoverThrustFit] = None
        self._ramp_target: Optional[Tuple[float, float, float]] = None   # where the ramp headed last cycle
        self._setpoint: Optional[Tuple[float, float, float]] = None   # where the PIDs aimed last cycle
        self._last_now: Optional[float] = None
        self._liftoff = LiftoffEstimator()
        self._pose: Optional[PoseSample] = None          # newest pose seen
        self._velocity: Optional[Tuple[float, float, float, float]] = None  # vx, vy, vz, yaw rate
        self._values_since: Optional[float] = None      # stamp of the first pose with the newest pose's values
        self._stale_since: Optional[float] = None
        self._blind_since: Optional[float] = None
        self._hold_thrust = 0.0

    # ----------------------------------------------------------------- commands
    def set_goal(self, x: float, y: float, z: float, yaw: float = 0.0) -> None:
        values = (x, y, z, yaw)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            self._log("warn", "goal ignored: not finite numbers %r" % (values,))
            return
        self.goal = Goal(float(x), float(y), float(z), float(yaw))

    def takeoff(self, now: float, pose: Optional[PoseSample] = None) -> bool:
        """Starts the thrust ramp from Idle; refused (False) without a fresh pose or when not idle."""
        if pose is not None:
            self._observe(pose)
        if self.safety == Safety.EMERGENCY:
            self._log("error", "takeoff refused: the Crazyflie was stopped by emergency; restart it (off and "
                      "on), then remove and add it again")
            return False
        if self.state != State.IDLE:
            self._log("warn", "takeoff ignored: state is %s" % self.state.value)
            return False
        if not self._fresh(now):
            self._log("error", "takeoff refused: no pose newer than %.2f s" % self.config.pose_timeout)
            return False
        self.start_z = self._seen_pose().z
        self.thrust = 0.0
        self.liftoff_thrust = self.preload_thrust = self.refined_thrust = None
        self._hover_fit = None
        self._setpoint = None
        self._liftoff = LiftoffEstimator(min_climb=0.1 * self.config.takeoff_height)
        self._liftoff.record_thrust(now, 0.0)
        self._last_now = now
        self._stale_since = self._blind_since = None
        self._set_state(State.TAKING_OFF, Safety.OK)
        return True

    def land(self, now: float) -> bool:
        """Automatic → Landing; during the take-off ramp the motors simply stop (we are < 5 cm up)."""
        if self.state == State.AUTOMATIC:
            self._set_state(State.LANDING, self.safety)
            if self.config.takeoff_handover == "smooth" and self._pose is not None:
                self._start_ramp(self._ramp_origin())
            return True
        if self.state == State.TAKING_OFF:
            self._log("info", "land during take-off ramp: motors off")
            self._set_state(State.IDLE, self.safety)
            return True
        return False

    def emergency(self) -> None:
        """The motors were stopped behind the controller's back: back to Idle, and say so until cleared."""
        if self.safety != Safety.EMERGENCY:
            self._log("warn", "emergency stop reported: %s -> Idle" % self.state.value)
        self._drop_ramp()
        self._hover_fit = None
        self._stale_since = self._blind_since = None
        self._set_state(State.IDLE, Safety.EMERGENCY)

    def clear_emergency(self) -> None:
        """The Crazyflie was added again: take-off is possible once a pose comes in."""
        if self.safety == Safety.EMERGENCY:
            self.safety = Safety.NO_POSE

    # ----------------------------------------------------------------- main step
    def update(self, now: float, pose: Optional[PoseSample]) -> Command:
        """One control cycle at time ``now``; ``pose`` is the newest pose known (or None)."""
        if pose is not None:
            self._observe(pose)
        dt = 0.0 if self._last_now is None else max(0.0, now - self._last_now)
        self._last_now = now
        if self.state != State.AUTOMATIC:
            self._hover_fit = None
        if self.state == State.IDLE:
            return self._emit(self._idle(now))
        command = self._untrusted_pose(now)
        if command is None:
            command = self._takeoff_ramp(now, dt)
        if command is None:
            command = self._closed_loop(now, dt)
        return self._emit(command)

    def _idle(self, now: float) -> Command:
        """Idle: zero setpoints; the safety says whether a take-off would have a pose (unless a blind
        landing or an emergency stop put it there)."""
        if self.safety not in (Safety.LANDED_BLIND, Safety.EMERGENCY):
            self.safety = Safety.OK if self._fresh(now) else Safety.NO_POSE
        return ZERO

    def _untrusted_pose(self, now: float) -> Optional[Command]:
        """Airborne: the command while the pose cannot be trusted (old, or frozen), or zero when a pose
        that came back finds the vehicle landed blind; None: closed-loop control may go on."""
        if not self._fresh(now):
            return self._stale_action(now, self._stale_reason(now))
        if self._frozen():
            return self._stale_action(now, "pose frozen: identical for %.2f s (limit %.2f s)" % (
                self._seen_pose().stamp - self._values_since_frozen(), self.config.frozen_pose_timeout))
        if self._stale_since is not None:
            self._recover(now)
            if self.state == State.IDLE:
                return ZERO
        return None

    def _takeoff_ramp(self, now: float, dt: float) -> Optional[Command]:
        """Taking off: the open-loop thrust ramp until lift-off, then the hand-over (None: closed loop
        from this cycle on, as in every other state)."""
        if self.state != State.TAKING_OFF:
            return None
        if not self._lifted_off():
            self.thrust += self.config.takeoff_thrust_rate * dt
            self._liftoff.record_thrust(now, self.thrust)
            return Command(0.0, 0.0, self.thrust, 0.0)
        self._handover(now)
        return None

    @property
    def pose(self) -> Optional[PoseSample]:
        """The newest pose seen (None before the first)."""
        return self._pose

    @property
    def ramp_active(self) -> bool:
        """True while the setpoint is still gliding to the goal (after take-off, during landing)."""
        return self._ramp is not None

    def status_text(self) -> str:
        return "%s: %s" % (self.state.value, self.safety.value)

    # ----------------------------------------------------------------- internals
    def _emit(self, command: Command) -> Command:
        self.last_command = command
        return command

    def _set_state(self, state: State, safety: Safety) -> None:
        if state != self.state:
            self._log("info", "state %s -> %s" % (self.state.value, state.value))
        self.state, self.safety = state, safety

    def _observe(self, pose: PoseSample) -> None:
        """Keeps the newest pose and the velocity from the last two distinct stamps."""
        prev = self._pose
        if prev is not None and pose.stamp <= prev.stamp:
            return
        self._pose = pose
        if prev is None or (pose.x, pose.y, pose.z, pose.yaw) != (prev.x, prev.y, prev.z, prev.yaw):
            self._values_since = pose.stamp
        if self.state == State.TAKING_OFF:
            self._liftoff.record_climb(pose.stamp, pose.z - self.start_z)
        if self._hover_fit is not None:
            self._hover_fit.record_height(pose.stamp, pose.z)
        if prev is None:
            return
        gap = pose.stamp - prev.stamp
        if gap > self.config.pose_timeout:
            self._velocity = None
            return
        self._velocity = ((pose.x - prev.x) / gap, (pose.y - prev.y) / gap, (pose.z - prev.z) / gap,
                          wrap_angle(pose.yaw - prev.yaw) / gap)

    def _seen_pose(self) -> PoseSample:
        """The newest pose, for the states that are entered only once a fresh pose was seen."""
        assert self._pose is not None, "no pose seen yet"
        return self._pose

    def _values_since_frozen(self) -> float:
        assert self._values_since is not None, "pose not frozen"
        return self._values_since

    def _fresh(self, now: float) -> bool:
        return self._pose is not None and now - self._pose.stamp <= self.config.pose_timeout

    def _frozen(self) -> bool:
        """Airborne and the pose values unchanged for longer than ``frozen_pose_timeout`` (stamps aside).
        Not on the ground nor during the take-off ramp: a vehicle standing still may be seen without
        noise (the simulator's mocap has none by default), and the ramp's lift-off is its own check."""
        limit = self.config.frozen_pose_timeout
        return (limit > 0 and self.state in (State.AUTOMATIC, State.LANDING) and self._pose is not None
                and self._values_since is not None and self._pose.stamp - self._values_since > limit)

    def _stale_reason(self, now: float) -> str:
        age = float("inf") if self._pose is None else now - self._pose.stamp
        return "pose is %.2f s old (limit %.2f s)" % (age, self.config.pose_timeout)

    def _lifted_off(self) -> bool:
        return (self._seen_pose().z > self.start_z + self.config.takeoff_height
                or self.thrust > self.config.takeoff_max_thrust)

    def _handover(self, now: float) -> None:
        self.liftoff_thrust = self.thrust
        for pid in self.pids.values():
            pid.reset(now)
        if self.config.takeoff_handover == "smooth":
            self.preload_thrust = self._liftoff.hover_thrust(self.liftoff_thrust, self.config.liftoff_lag)
            self._start_ramp(self._vehicle_state())
            self._takeoff_glide = True
        else:
            self.preload_thrust = self.liftoff_thrust
            self._drop_ramp()
        self._setpoint = None   # the first closed-loop cycle aims at the ramp or, without one, the goal
        self.pids["z"].set_i_term(self.preload_thrust)
        if self.goal is None:
            p = self._seen_pose()
            self.goal = Goal(p.x, p.y, p.z, p.yaw)
            self._log("warn", "no goal received: holding the lift-off position")
        self._log("info", "lift-off at thrust %.0f, z integrator preloaded with %.0f"
                  % (self.liftoff_thrust, self.preload_thrust))
        self._set_state(State.AUTOMATIC, Safety.OK)

    def _vehicle_state(self):
        p, v = self._pose, self._velocity or (0.0, 0.0, 0.0, 0.0)
        return (p.x, p.y, p.z), (v[0], v[1], v[2])

    def _ramp_origin(self):
        if self._ramp is not None:
            return self._ramp.position, self._ramp.velocity
        return self._vehicle_state()

    def _drop_ramp(self) -> None:
        self._ramp, self._goal_glide, self._ramp_target = None, False, None
        self._glide_holds_integral = self._takeoff_glide = False

    def _start_ramp(self, origin) -> None:
        position, velocity = origin
        self._ramp = SetpointRamp(position, velocity, self.config.handover_speed, self.config.handover_accel)
        self._goal_glide, self._ramp_target, self._glide_holds_integral = False, None, False
        self._takeoff_glide = False

    def _target(self) -> Goal:
        goal = self.goal
        assert goal is not None, "flying without a goal"   # takeoff sets one
        if self.state == State.LANDING:
            goal = Goal(goal.x, goal.y, self.start_z + self.config.landing_height, goal.yaw)
        return goal

    def _closed_loop(self, now: float, dt: float) -> Command:
        pose = self._seen_pose()
        goal = self._target()
        if self.state == State.LANDING and pose.z <= goal.z:
            self._set_state(State.IDLE, Safety.OK)
            self._drop_ramp()
            return ZERO
        target = (goal.x, goal.y, goal.z)
        setpoint, setpoint_rate = target, (0.0, 0.0, 0.0)
        if self._glides_to(target):
            self._start_goal_glide()
        if self._ramp is not None:
            self._ramp.step(target, dt)
            setpoint, setpoint_rate = self._ramp.position, self._ramp.velocity
            self._ramp_target = target
            if self._ramp.arrived:
                after_takeoff = self._takeoff_glide and self.state == State.AUTOMATIC
                self._drop_ramp()
                if after_takeoff:
                    self._start_hover_fit(now)
        self._setpoint = setpoint
        vel = self._velocity
        if vel is None:
            for pid in self.pids.values():
                pid.forget_derivative()
        yaw = pose.yaw
        target_b = rotate_to_body(setpoint[0], setpoint[1], yaw)
        pos_b = rotate_to_body(pose.x, pose.y, yaw)
        vel_b = rotate_to_body(vel[0], vel[1], yaw) if vel is not None else (None, None)
        # The setpoint's velocity feeds the Z D term only: with the attitude loop's lag (≈ 0.17 s), a
        # velocity reference in the X/Y D terms makes the vehicle overshoot the end of a glide
        # (13 cm instead of 3 cm on a 0.5 m move, bench/bench_goal_steps.py); X/Y damp the measured
        # velocity alone.
        x = self.pids["x"].update(target_b[0], pos_b[0], now, 0.0, vel_b[0])
        y = self.pids["y"].update(target_b[1], pos_b[1], now, 0.0, vel_b[1])
        z = self.pids["z"].update(setpoint[2], pose.z, now, setpoint_rate[2], vel[2] if vel is not None else None,
                                  integrate=self._z_integrates(setpoint[2] - pose.z, setpoint_rate[2]))
        if self._hover_fit is not None:
            self._refine_hover_thrust(self._hover_fit, now, z)
        if self.config.tilt_compensation:
            z = self._tilt_compensated(z, x, y)
        yaw_target = yaw + wrap_angle(goal.yaw - yaw)
        r = self.pids["yaw"].update(yaw_target, yaw, now, 0.0, vel[3] if vel is not None else None)
        return Command(x, y, z, r)

    def _start_hover_fit(self, now: float) -> None:
        """The take-off glide has arrived. While the setpoint climbed, the integrator absorbed the
        hand-over's tracking error (the vehicle leaves the floor faster than the glide and runs ahead
        of it, ≈ 250 counts for 32 g), which is not a hover-thrust error: the integral goes back to
        the lift-off estimate, then the next ``hover_refine_time`` s of flight are fitted for the
        hover thrust (``hover_thrust``)."""
        cfg = self.config
        if cfg.hover_refine_time <= 0 or self.preload_thrust is None:
            return
        self.pids["z"].set_i_term(self.preload_thrust)
        gain = self._liftoff.thrust_gain(cfg.takeoff_thrust_rate)
        if gain is not None:
            self._hover_fit = HoverThrustFit(now, gain, cfg.liftoff_lag)

    def _refine_hover_thrust(self, fit: HoverThrustFit, now: float, thrust: float) -> None:
        preload = self.preload_thrust
        assert preload is not None, "hover fit without a lift-off estimate"   # _start_hover_fit checks
        fit.record_command(now, thrust)
        if now - fit.start < self.config.hover_refine_time:
            return
        self._hover_fit = None
        estimate = fit.estimate()
        z = self.pids["z"]
        if estimate is None or not z.gains.min_output < estimate < z.gains.max_output \
                or abs(estimate - preload) > MAX_HOVER_REFINEMENT:
            # e.g. the vehicle was pushed or grabbed during the window: keep what the integrator has
            self._log("warn", "hover thrust fit rejected (%s, lift-off estimate %.0f): the z integrator keeps %.0f"
                      % ("none" if estimate is None else "%.0f" % estimate, preload, z.i_term))
            return
        self.refined_thrust = estimate
        self._log("info", "hover thrust fitted: %.0f (lift-off estimate %.0f, integrator %.0f)"
                  % (estimate, preload, z.i_term))
        z.set_i_term(estimate)

    def _glides_to(self, target: Tuple[float, float, float]) -> bool:
        """A new goal in Automatic (smooth goal change) starts a goal glide, from rest at the last
        setpoint or, during the take-off glide, from where that glide is."""
        if self.config.goal_change != "smooth" or self.state != State.AUTOMATIC or self._goal_glide:
            return False
        previous = self._ramp_target if self._ramp is not None else self._setpoint
        if previous is None:
            return False
        return max(abs(target[i] - previous[i]) for i in range(3)) > 1e-4

    def _start_goal_glide(self) -> None:
        cfg = self.config
        if self._ramp is None:
            assert self._setpoint is not None   # _glides_to starts a glide only from a setpoint
            self._ramp = SetpointRamp(self._setpoint, (0.0, 0.0, 0.0), cfg.goal_speed, cfg.goal_accel)
            self._glide_holds_integral = True
        else:   # the take-off glide goes on toward the new goal, at the goal glide's limits, and
            # keeps correcting the preload estimate (see _z_integrates)
            self._ramp.max_speed, self._ramp.max_accel = cfg.goal_speed, cfg.goal_accel
        self._goal_glide = True

    def _z_integrates(self, error: float, setpoint_rate_z: float) -> bool:
        """Anti-windup (``conditional``): the z integral is the hover thrust, so it does not integrate
        while the thrust is saturated toward the error, nor while the setpoint glides up or down to a
        new goal: the lag behind a moving setpoint is not a hover-thrust error, and integrating it
        overshoots once the setpoint stops (0.2 m step: 5 cm past instead of 3 cm). The take-off
        glide keeps integrating: its preload is only an estimate (within a few hundred counts) that
        the climb corrects (frozen, the take-off overshoot grows from 1 to 4 cm), also when a new goal
        arrives during it."""
        if self.config.z_integration == "always":
            return True
        pid = self.pids["z"]
        if (pid.last_output >= pid.gains.max_output and error > 0) or \
                (pid.last_output <= pid.gains.min_output and error < 0):
            return False
        return not (self._glide_holds_integral and self._ramp is not None and abs(setpoint_rate_z) > 1e-6)

    def _tilt_compensated(self, thrust: float, pitch_deg: float, roll_deg: float) -> float:
        """Tilting by the commanded roll and pitch leaves cos(roll)·cos(pitch) of the thrust vertical;
        scale it back up so that horizontal moves do not cost height (within the Z output limit)."""
        vertical = math.cos(math.radians(pitch_deg)) * math.cos(math.radians(roll_deg))
        return min(thrust / vertical, self.pids["z"].gains.max_output)

    def _stale_action(self, now: float, reason: str) -> Command:
        """Never act on a stale (old or frozen) pose: hold level at hover thrust, then sink blind, then stop;
        ``reason`` is logged once, when the spell starts."""
        cfg = self.config
        self._hover_fit = None   # the fit needs every pose of its window
        if self._stale_since is None:
            self._stale_since = now
            if self.state == State.TAKING_OFF:
                self._hold_thrust = self.thrust
            else:
                z = self.pids["z"]
                self._hold_thrust = clamp(z.i_term, z.gains.min_output, z.gains.max_output)
            self._log("warn", "%s: holding level at thrust %.0f" % (reason, self._hold_thrust))
            self.safety = Safety.HOLDING
        if now - self._stale_since < cfg.lost_pose_land_timeout:
            return Command(0.0, 0.0, self._hold_thrust, 0.0)
        if self._blind_since is None:
            self._blind_since = now
            self.safety = Safety.BLIND_DESCENT
            self._log("error", "pose lost for %.2f s: descending blind at thrust %.0f for %.1f s, then motors off"
                      % (now - self._stale_since, self._hold_thrust - cfg.lost_pose_thrust_drop,
                         cfg.lost_pose_descent_time))
        if now - self._blind_since < cfg.lost_pose_descent_time:
            return Command(0.0, 0.0, max(0.0, self._hold_thrust - cfg.lost_pose_thrust_drop), 0.0)
        self._log("error", "blind descent over: motors off")
        self._drop_ramp()
        self._stale_since = self._blind_since = None
        self._set_state(State.IDLE, Safety.LANDED_BLIND)
        return ZERO

    def _recover(self, now: float) -> None:
        """A fresh pose after a stale spell: resume, or land closed loop after a blind descent."""
        blind = self._blind_since is not None
        stale_for = now - self._stale_since if self._stale_since is not None else 0.0
        self._log("warn", "pose fresh again after %.2f s" % stale_for)
        self._stale_since = self._blind_since = None
        for pid in self.pids.values():
            pid.forget_derivative()
        self.safety = Safety.OK
        if self.state == State.TAKING_OFF:
            self.thrust = self._hold_thrust
            if blind:  # still near the ground: stop rather than resume the ramp
                self._set_state(State.IDLE, Safety.OK)
        elif blind:
            self._set_state(State.LANDING, Safety.OK)
            if self.config.takeoff_handover == "smooth":
                self._start_ramp(self._vehicle_state())
