"""Position controller state machine: transitions, take-off, preload, resets, stale pose, signs.

Closed-loop checks fly a small model of our own (controller_test_model), not the project simulator.
"""
import math

import pytest

from controller_support.quad_model import Flight, QuadModel, hover_command
from crazyflie_controller.pid import PidGains
from crazyflie_controller.position_controller import (
    Command,
    ControllerConfig,
    PoseSample,
    PositionController,
    Safety,
    State,
    rotate_to_body,
    wrap_angle,
    yaw_from_quaternion,
)

X = PidGains(40, 20, 2, -10, 10, -0.1, 0.1)
Y = PidGains(-40, -20, -2, -10, 10, -0.1, 0.1)
Z = PidGains(5000, 6000, 3500, 10000, 60000, -1000, 1000)
YAW = PidGains(-200, -20, 0, -200, 200, 0, 0)
DT = 0.02


FROZEN_POSE_TIMEOUT = ControllerConfig(X, Y, Z, YAW).frozen_pose_timeout


def make(original=False, **kw):
    """The poses of ``pose()`` below are exact (no noise), so the frozen-pose check is off unless a test asks."""
    kw.setdefault("frozen_pose_timeout", 0.0)
    cfg = ControllerConfig.original(X, Y, Z, YAW, **kw) if original else ControllerConfig(X, Y, Z, YAW, **kw)
    messages = []
    c = PositionController(cfg, log=lambda level, msg: messages.append((level, msg)))
    c.messages = messages
    return c


def pose(t, x=0.0, y=0.0, z=0.0, yaw=0.0):
    return PoseSample(t, x, y, z, yaw)


def airborne(c, t=0.0, z=0.5, x=0.0, y=0.0, yaw=0.0, goal=(0.0, 0.0, 0.5, 0.0)):
    """Drives a controller through take-off by feeding poses (no dynamics); returns the time reached."""
    c.set_goal(*goal)
    c.update(t, pose(t, x, y, 0.0, yaw))
    assert c.takeoff(t)
    t += DT
    c.update(t, pose(t, x, y, 0.0, yaw))
    t += DT
    c.update(t, pose(t, x, y, z, yaw))        # more than 5 cm up: hand-over
    assert c.state == State.AUTOMATIC
    for _ in range(500):                     # hover at z until the setpoint has settled on the goal
        if not c.ramp_active:
            break
        t += DT
        c.update(t, pose(t, x, y, z, yaw))
    assert not c.ramp_active
    return t


def fly_takeoff(original, seconds=20.0, mass=0.032, **kw):
    kw.setdefault("frozen_pose_timeout", FROZEN_POSE_TIMEOUT)   # the model's mocap is noisy, as a real one
    c = make(original, **kw)
    f = Flight(c, QuadModel(mass=mass))
    f.settle_pose()
    c.set_goal(0.0, 0.0, 0.5, 0.0)
    f.run(0.1)
    assert f.takeoff()
    f.run(seconds)
    return c, f


# ------------------------------------------------------------------ states and take-off
def test_idle_publishes_zero_and_takeoff_needs_a_fresh_pose():
    c = make()
    assert c.update(0.0, None) == Command(0, 0, 0, 0)
    assert c.safety == Safety.NO_POSE
    assert not c.takeoff(0.0)
    assert c.state == State.IDLE
    assert any("takeoff refused" in m for _, m in c.messages)
    c.update(1.0, pose(0.5))                 # 0.5 s old
    assert not c.takeoff(1.0)
    c.update(1.0, pose(0.95))
    assert c.takeoff(1.0) and c.state == State.TAKING_OFF


def test_takeoff_ramps_thrust_at_10000_per_second_with_level_attitude():
    c = make()
    c.set_goal(0, 0, 0.5)
    c.update(0.0, pose(0.0))
    c.takeoff(0.0)
    out = [c.update(k * DT, pose(k * DT)) for k in range(1, 51)]
    assert [o.linear_z for o in out[:3]] == pytest.approx([200, 400, 600])
    assert out[-1].linear_z == pytest.approx(10000)          # 1 s of ramp
    assert all(o.linear_x == 0 and o.linear_y == 0 and o.angular_z == 0 for o in out)
    # uneven ticks: the ramp follows the timestamps, not the tick count
    c.update(1.0 + 0.1, pose(1.1))
    assert c.last_command.linear_z == pytest.approx(11000)


def test_takeoff_ends_above_max_thrust_even_without_climbing():
    c = make(original=True)
    c.set_goal(0, 0, 0.5)
    c.update(0.0, pose(0.0))
    c.takeoff(0.0)
    t = 0.0
    while c.state == State.TAKING_OFF and t < 10:
        t += DT
        c.update(t, pose(t))
    assert c.state == State.AUTOMATIC
    assert c.liftoff_thrust == pytest.approx(50200, abs=1)   # first ramp value above 50 000
    assert t == pytest.approx(5.04, abs=1e-6)


def test_original_handover_preloads_the_integrator_with_the_liftoff_thrust_and_resets_all_pids():
    c = make(original=True)
    for axis in ("x", "y", "yaw"):                 # leftovers from an earlier flight
        c.pids[axis].integral = 0.05
    c.pids["y"]._prev_error = 3.0
    airborne(c)
    assert c.liftoff_thrust == pytest.approx(200.0)
    assert c.preload_thrust == c.liftoff_thrust
    assert c.pids["x"].integral == 0.0 and c.pids["yaw"].integral == 0.0
    assert c.pids["y"].integral == 0.0                       # the original never reset Y
    assert c.last_command.linear_y == 0.0                     # no D kick from Y's stale previous error
    assert c.pids["z"].i_term == pytest.approx(200.0)         # zero error at hand-over: preload unchanged


def test_full_cycle_idle_takeoff_automatic_landing_idle():
    c, f = fly_takeoff(original=False, seconds=12.0)
    states = [s[6] for s in f.log]
    assert states[0] == State.IDLE
    assert State.TAKING_OFF in states and states[-1] == State.AUTOMATIC
    assert abs(f.model.p[2] - 0.5) < 0.03
    assert c.land(f.model.t)
    assert c.state == State.LANDING
    f.run(8.0)
    assert c.state == State.IDLE
    assert c.last_command == Command(0, 0, 0, 0)
    assert f.model.p[2] < 0.06
    landing = [s for s in f.log if s[6] == State.LANDING]
    assert max(s[3] for s in landing) < 0.52                   # no climb when landing starts


# ------------------------------------------------------------------ take-off overshoot, before and after
def test_original_takeoff_overshoots_far_and_the_fix_does_not():
    c0, f0 = fly_takeoff(original=True, seconds=10.0)
    c1, f1 = fly_takeoff(original=False, seconds=10.0)
    peak0 = max(s[3] for s in f0.log)
    peak1 = max(s[3] for s in f1.log)
    assert peak0 > 1.0                   # the original's integrator preload and D kick: > 0.5 m past
    assert peak1 < 0.56                  # the fix: within 6 cm
    # same lift-off detection; the fix preloads close to the real hover thrust instead
    assert c0.liftoff_thrust == pytest.approx(c1.liftoff_thrust, abs=400)
    assert c1.preload_thrust == pytest.approx(hover_command(0.032), abs=500)
    assert c0.preload_thrust - hover_command(0.032) > 3000


def test_hover_holds_position_with_small_error():
    c, f = fly_takeoff(original=False, seconds=20.0)
    late = [s for s in f.log if s[0] > f.log[-1][0] - 5.0]
    rms_z = math.sqrt(sum((s[3] - 0.5) ** 2 for s in late) / len(late))
    rms_xy = math.sqrt(sum(s[1] ** 2 + s[2] ** 2 for s in late) / len(late))
    assert rms_z < 0.01 and rms_xy < 0.01


# ------------------------------------------------------------------ stale and lost pose
def test_stale_pose_holds_level_at_the_integrator_thrust_and_reports_it():
    c = make()
    t = airborne(c)
    c.pids["z"].set_i_term(40000.0)          # as after a real lift-off (these poses carry no dynamics)
    for _ in range(10):
        t += DT
        c.update(t, pose(t, z=0.5))
    hover = c.pids["z"].i_term
    stale_from = t
    t += 0.15
    out = c.update(t, pose(stale_from, 0.3, 0.2, 0.1))      # newest pose is 0.15 s old: never used
    assert out == Command(0.0, 0.0, pytest.approx(hover), 0.0)
    assert c.safety == Safety.HOLDING
    assert "holding" in c.status_text()
    assert any(level == "warn" and "old" in m for level, m in c.messages)
    t += DT
    assert c.update(t, None).linear_z == pytest.approx(hover)  # no pose at all: the same
    t += DT
    c.update(t, pose(t, z=0.5))                                # fresh again: back to closed loop
    assert c.safety == Safety.OK and c.state == State.AUTOMATIC


def test_lost_pose_descends_blind_then_stops_the_motors():
    c, f = fly_takeoff(original=False, seconds=10.0)
    t_lost = f.model.t
    f.pose_blackout = (t_lost, 1e9)
    f.run(0.4)
    assert c.safety == Safety.HOLDING
    hover = c.pids["z"].i_term               # frozen while the pose is stale
    assert hover == pytest.approx(hover_command(0.032), abs=300)
    assert f.log[-1][5] == Command(0.0, 0.0, pytest.approx(hover), 0.0)
    f.run(0.3)                                           # now 0.7 s without pose (> 0.1 + 0.5)
    assert c.safety == Safety.BLIND_DESCENT
    assert f.log[-1][5].linear_z == pytest.approx(hover - c.config.lost_pose_thrust_drop)
    f.run(2.5)
    assert c.state == State.IDLE and c.safety == Safety.LANDED_BLIND
    assert c.last_command == Command(0, 0, 0, 0)
    assert f.model.p[2] == 0.0                            # it came down
    assert max(abs(s[1]) + abs(s[2]) for s in f.log) < 0.1
    assert any(level == "error" and "motors off" in m for level, m in c.messages)
    assert not c.takeoff(f.model.t)                      # still blind: refused


def test_pose_back_during_blind_descent_lands_closed_loop():
    c, f = fly_takeoff(original=False, seconds=10.0)
    f.pose_blackout = (f.model.t, f.model.t + 1.0)
    f.run(0.8)
    assert c.safety == Safety.BLIND_DESCENT
    f.run(0.4)
    assert c.state == State.LANDING and c.safety == Safety.OK
    f.run(8.0)
    assert c.state == State.IDLE and f.model.p[2] < 0.06


def frozen_messages(c):
    return [m for level, m in c.messages if level == "warn" and m.startswith("pose frozen: identical for")]


def test_frozen_pose_while_flying_holds_then_descends_blind_then_stops():
    c, f = fly_takeoff(original=False, seconds=10.0)
    assert c.safety == Safety.OK and not frozen_messages(c)      # a noisy pose is never taken for frozen
    f.pose_freeze = (f.model.t, 1e9)                              # the same values, stamped anew
    f.run(0.3)
    assert c.state == State.AUTOMATIC and c.safety == Safety.HOLDING
    hover = c.pids["z"].i_term
    assert f.log[-1][5] == Command(0.0, 0.0, pytest.approx(hover), 0.0)
    f.run(0.5)                                                    # frozen > 0.1 + 0.5 s
    assert c.safety == Safety.BLIND_DESCENT
    assert f.log[-1][5].linear_z == pytest.approx(hover - c.config.lost_pose_thrust_drop)
    f.run(2.5)
    assert c.state == State.IDLE and c.safety == Safety.LANDED_BLIND
    assert c.last_command == Command(0, 0, 0, 0) and f.model.p[2] == 0.0
    assert len(frozen_messages(c)) == 1                           # logged once, with the reason


def test_frozen_pose_for_a_moment_recovers_when_the_values_change():
    c, f = fly_takeoff(original=False, seconds=10.0)
    f.pose_freeze = (f.model.t, f.model.t + 0.3)
    f.run(0.25)
    assert c.safety == Safety.HOLDING
    f.run(0.5)
    assert c.state == State.AUTOMATIC and c.safety == Safety.OK
    assert any("fresh again" in m for _, m in c.messages)
    f.run(3.0)
    assert abs(f.model.p[2] - 0.5) < 0.05 and c.safety == Safety.OK


def test_frozen_pose_check_off_at_zero_and_refused_below():
    c, f = fly_takeoff(original=False, seconds=10.0, frozen_pose_timeout=0.0)
    f.pose_freeze = (f.model.t, 1e9)
    f.run(1.0)
    assert c.state == State.AUTOMATIC and c.safety == Safety.OK and not frozen_messages(c)
    with pytest.raises(ValueError, match="frozen_pose_timeout"):
        ControllerConfig(X, Y, Z, YAW, frozen_pose_timeout=-0.1)


def test_identical_poses_on_the_ground_and_during_the_ramp_change_nothing():
    c = make(frozen_pose_timeout=FROZEN_POSE_TIMEOUT)
    c.set_goal(0.0, 0.0, 0.5)
    t = 0.0
    for _ in range(100):                                          # 2 s of one pose, fresh stamps, idle
        t += DT
        c.update(t, pose(t, z=0.0))
    assert c.state == State.IDLE and c.safety == Safety.OK
    assert c.takeoff(t)
    for _ in range(50):                                           # 1 s of the take-off ramp, still on the floor
        t += DT
        out = c.update(t, pose(t, z=0.0))
    assert c.state == State.TAKING_OFF and c.safety == Safety.OK
    assert out.linear_z == pytest.approx(c.config.takeoff_thrust_rate * 1.0, rel=0.05)
    assert not frozen_messages(c)


# ------------------------------------------------------------------ goal jumps, frames, signs
def test_goal_jump_does_not_kick_the_derivative():
    for original, expect_kick in ((False, False), (True, True)):
        c = make(original=original, goal_change="step")   # the jump reaches the PIDs as it is
        t = airborne(c)
        c.pids["z"].set_i_term(40000.0)
        for _ in range(5):
            t += DT
            c.update(t, pose(t, z=0.5))
        c.set_goal(0.0, 0.0, 1.0, 0.0)
        t += DT
        out = c.update(t, pose(t, z=0.5))
        p, i, d = c.pids["z"].last_terms
        if expect_kick:
            assert out.linear_z == 60000 and d > 100000
        else:
            assert d == pytest.approx(0.0, abs=1e-6)
            assert out.linear_z == pytest.approx(p + i) and out.linear_z < 60000


def test_errors_are_rotated_into_the_vehicle_frame_by_yaw():
    assert rotate_to_body(1.0, 0.0, math.pi / 2) == pytest.approx((0.0, -1.0))
    assert rotate_to_body(0.0, 1.0, math.pi / 2) == pytest.approx((1.0, 0.0))
    # vehicle yawed 90°: a goal 0.1 m along world +x is 0.1 m to its right (body −y)
    c = make(goal_change="step")
    t = airborne(c, yaw=math.pi / 2, goal=(0.0, 0.0, 0.5, math.pi / 2))
    c.set_goal(0.1, 0.0, 0.5, math.pi / 2)
    t += DT
    out = c.update(t, pose(t, z=0.5, yaw=math.pi / 2))
    assert out.linear_x == pytest.approx(0.0, abs=1e-6)
    assert out.linear_y == pytest.approx(4.0, rel=0.01)     # Y kp −40 × (−0.1 m): roll right → −y body = +x world


def test_signs_of_each_axis():
    c = make(goal_change="step")
    t = airborne(c)
    c.set_goal(0.1, 0.0, 0.5, 0.0)
    t += DT
    assert c.update(t, pose(t, z=0.5)).linear_x == pytest.approx(4.0, rel=0.01)     # +x error → +pitch cmd
    c.set_goal(0.0, 0.1, 0.5, 0.0)
    t += DT
    assert c.update(t, pose(t, z=0.5)).linear_y < 0                                # +y error → −roll cmd
    c.set_goal(0.0, 0.0, 0.5, 0.1)
    t += DT
    assert c.update(t, pose(t, z=0.5)).angular_z == pytest.approx(-20.0, rel=0.01)  # +yaw error → −yaw rate
    c.set_goal(0.0, 0.0, 0.6, 0.0)
    t += DT
    assert c.update(t, pose(t, z=0.5)).linear_z > c.pids["z"].i_term                # below goal → more thrust


def test_yaw_error_takes_the_short_way_round():
    assert wrap_angle(math.radians(340)) == pytest.approx(math.radians(-20))
    assert yaw_from_quaternion(0, 0, math.sin(0.3), math.cos(0.3)) == pytest.approx(0.6)
    c = make()
    t = airborne(c, yaw=math.radians(-170), goal=(0, 0, 0.5, math.radians(-170)))
    c.set_goal(0, 0, 0.5, math.radians(170))
    t += DT
    out = c.update(t, pose(t, z=0.5, yaw=math.radians(-170)))
    assert out.angular_z == pytest.approx(-200 * math.radians(-20), rel=0.01)    # clockwise, 20° not 340°


def test_closed_loop_flies_to_a_goal_off_axis_while_yawed():
    c = make()
    f = Flight(c, QuadModel(yaw=math.radians(60)))
    f.settle_pose()
    c.set_goal(0.3, -0.2, 0.5, math.radians(60))
    f.run(0.1)
    f.takeoff()
    f.run(15.0)
    assert f.model.p == pytest.approx([0.3, -0.2, 0.5], abs=0.03)
    c.set_goal(0.3, -0.2, 0.5, math.radians(-30))
    f.run(3.0)
    assert wrap_angle(f.model.yaw - math.radians(-30)) == pytest.approx(0.0, abs=0.03)
    assert f.model.p == pytest.approx([0.3, -0.2, 0.5], abs=0.05)


def test_bad_config_and_goal_are_refused_clearly():
    with pytest.raises(ValueError, match="takeoffHandover"):
        ControllerConfig(X, Y, Z, YAW, takeoff_handover="fast")
    with pytest.raises(ValueError, match="pose_timeout"):
        ControllerConfig(X, Y, Z, YAW, pose_timeout=0.0)
    c = make()
    c.set_goal(float("nan"), 0, 0)
    assert c.goal is None and any("goal ignored" in m for _, m in c.messages)


# ------------------------------------------------------------------ goal changes (smooth mode)
def test_new_goal_glides_within_the_limits_with_its_velocity_in_the_z_d_term():
    c = make(goal_speed=0.5, goal_accel=1.0)
    t = airborne(c)
    c.pids["z"].set_i_term(40000.0)
    c.set_goal(0.0, 0.0, 0.7, 0.0)
    setpoints, prev_rate = [], 0.0
    while True:
        t += DT
        out = c.update(t, pose(t, z=0.5))
        sp, rate = c._setpoint[2], (c._ramp.velocity[2] if c.ramp_active else 0.0)
        if not setpoints:                         # first cycle: no jump, no kick
            assert sp == pytest.approx(0.5 + 0.5 * 1.0 * DT * DT, abs=1e-6)
            p, i, d = c.pids["z"].last_terms
            assert d == pytest.approx(6000 * 1.0 * DT)           # kd · setpoint rate (vehicle at rest)
            assert out.linear_z < 40000 + 200
        assert rate <= 0.5 + 1e-9 and abs(rate - prev_rate) <= 2 * 1.0 * DT + 1e-9
        setpoints.append(sp)
        prev_rate = rate
        if not c.ramp_active:
            break
        assert len(setpoints) < 200
    assert setpoints[-1] == 0.7 and max(setpoints) <= 0.7 + 1e-3     # the ramp may cross by < 1 mm
    assert all(abs(b - a) <= 0.5 * DT + 1e-9 for a, b in zip(setpoints, setpoints[1:]))   # never a step
    assert 0.55 < len(setpoints) * DT < 1.0      # 0.2 m at ≤ 1 m/s², braking with a margin


def test_z_integrator_holds_while_gliding_vertically_and_learns_at_rest():
    for mode, frozen in (("conditional", True), ("always", False)):
        c = make(z_integration=mode)
        t = airborne(c)
        c.set_goal(0.0, 0.0, 0.7, 0.0)
        t += DT
        c.update(t, pose(t, z=0.5))
        before = c.pids["z"].integral
        for _ in range(10):                   # vehicle stays at 0.5 m: it lags the rising setpoint
            t += DT
            c.update(t, pose(t, z=0.5))
        assert c.ramp_active
        assert (c.pids["z"].integral == before) == frozen
    c2 = make()                               # horizontal glide: the setpoint rests vertically
    t = airborne(c2)
    c2.set_goal(0.5, 0.0, 0.5, 0.0)
    t += DT
    c2.update(t, pose(t, z=0.49))
    before = c2.pids["z"].integral
    t += DT
    c2.update(t, pose(t, z=0.49))
    assert c2.ramp_active and c2.pids["z"].integral == pytest.approx(before + 0.01 * DT)


def test_tilt_compensation_scales_the_thrust_by_the_commanded_tilt():
    outs = {}
    for tilt in (True, False):
        c = make(goal_change="step", tilt_compensation=tilt)
        t = airborne(c)
        c.pids["z"].set_i_term(40000.0)
        c.set_goal(0.3, -0.3, 0.5, 0.0)       # saturates pitch +10° and roll +10°
        t += DT
        outs[tilt] = c.update(t, pose(t, z=0.5))
    on, off = outs[True], outs[False]
    assert (on.linear_x, on.linear_y) == (10.0, 10.0) == (off.linear_x, off.linear_y)
    assert on.linear_z == pytest.approx(off.linear_z / math.cos(math.radians(10)) ** 2)
    assert on.linear_z > off.linear_z + 1000


def test_original_config_restores_every_original_behaviour():
    cfg = ControllerConfig.original(X, Y, Z, YAW)
    assert (cfg.takeoff_handover, cfg.derivative, cfg.goal_change, cfg.z_integration, cfg.tilt_compensation) == \
        ("original", "error", "step", "always", False)
    with pytest.raises(ValueError, match="goalChange"):
        ControllerConfig(X, Y, Z, YAW, goal_change="teleport")
    with pytest.raises(ValueError, match="goal_accel"):
        ControllerConfig(X, Y, Z, YAW, goal_accel=-1.0)
