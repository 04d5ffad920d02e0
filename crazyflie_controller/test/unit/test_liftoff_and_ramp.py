"""Hover-thrust estimate from the lift-off climb, the gliding setpoint, and the node's parameter parsing."""

import pytest

from crazyflie_controller.liftoff import LiftoffEstimator
from crazyflie_controller.setpoint_ramp import SetpointRamp


def test_liftoff_time_and_thrust_from_a_cubic_climb():
    est = LiftoffEstimator(min_climb=0.005)
    rate, t0, jerk = 10000.0, 4.1, 3.5
    for k in range(0, 250):                       # ramp ticks at 50 Hz from t = 0
        est.record_thrust(k * 0.02, rate * k * 0.02)
    for k in range(0, 460):                       # poses at 100 Hz
        t = k * 0.01
        climb = jerk * (t - t0) ** 3 / 6 if t > t0 else 0.0
        est.record_climb(t, climb)
    assert est.liftoff_time() == pytest.approx(t0, abs=0.01)
    assert est.hover_thrust(fallback=46000.0) == pytest.approx(rate * t0, abs=100)
    assert est.hover_thrust(fallback=46000.0, lag=0.07) == pytest.approx(rate * (t0 - 0.07), abs=100)


def test_liftoff_estimate_falls_back_without_a_climb():
    est = LiftoffEstimator()
    est.record_thrust(0.0, 0.0)
    est.record_climb(1.0, 0.001)                  # noise-sized climbs are ignored
    assert est.liftoff_time() is None
    assert est.hover_thrust(fallback=50200.0) == 50200.0


def test_ramp_glides_to_the_goal_within_its_limits_and_stops_there():
    ramp = SetpointRamp((0, 0, 0.05), (0, 0, 0.35), max_speed=0.2, max_accel=0.3)
    assert ramp.velocity[2] == pytest.approx(0.2)   # initial speed clipped to the limit
    dt, prev_v, t = 0.02, 0.2, 0.0
    while not ramp.arrived and t < 20:
        ramp.step((0, 0, 0.5), dt)
        t += dt
        v = ramp.velocity[2]
        step_limit = (2.0 if ramp.arrived else 1.0) * 0.3 * dt   # settling onto the goal: at most 2 a dt
        assert v <= 0.2 + 1e-9 and abs(v - prev_v) <= step_limit + 1e-9
        assert ramp.position[2] <= 0.5 + 1e-3    # no overshoot of the goal
        prev_v = v
    assert ramp.arrived and ramp.position == (0, 0, 0.5) and ramp.velocity == (0.0, 0.0, 0.0)
    assert 2.0 < t < 3.5                          # 0.45 m at 0.2 m/s with braking
    with pytest.raises(ValueError):
        SetpointRamp((0, 0, 0), (0, 0, 0), max_speed=0.0, max_accel=1.0)


def test_node_parameters_are_checked():
    node = pytest.importorskip("crazyflie_controller.controller_node")
    pids = {a: {"kp": 1, "kd": 0, "ki": 0, "minOutput": -1, "maxOutput": 1, "integratorMin": 0,
                "integratorMax": 0} for a in ("X", "Y", "Z", "Yaw")}
    cfg = node.config_from_params({"PIDs": pids, "poseTimeout": 0.2, "takeoffHandover": "original"})
    assert cfg.pose_timeout == 0.2 and cfg.takeoff_handover == "original"
    with pytest.raises(node.ConfigError, match="PIDs is missing"):
        node.config_from_params({})
    with pytest.raises(node.ConfigError, match="PIDs/Yaw is missing"):
        node.config_from_params({"PIDs": {k: v for k, v in pids.items() if k != "Yaw"}})
    with pytest.raises(node.ConfigError, match="lostPoseLandTimeout must be a number"):
        node.config_from_params({"PIDs": pids, "lostPoseLandTimeout": "soon"})
    with pytest.raises(node.ConfigError, match="takeoffHandover"):
        node.config_from_params({"PIDs": pids, "takeoffHandover": "rocket"})
    cfg = node.config_from_params({"PIDs": pids, "goalChange": "step", "goalSpeed": 0.4, "goalAccel": 2,
                                   "zIntegration": "always", "tiltCompensation": False})
    assert (cfg.goal_change, cfg.goal_speed, cfg.goal_accel, cfg.z_integration, cfg.tilt_compensation) == \
        ("step", 0.4, 2.0, "always", False)
    defaults = node.config_from_params({"PIDs": pids})
    assert (defaults.goal_change, defaults.z_integration, defaults.tilt_compensation) == ("smooth", "conditional", True)
    with pytest.raises(node.ConfigError, match="goalChange"):
        node.config_from_params({"PIDs": pids, "goalChange": "jump"})
    with pytest.raises(node.ConfigError, match="zIntegration"):
        node.config_from_params({"PIDs": pids, "zIntegration": "never"})
    with pytest.raises(node.ConfigError, match="tiltCompensation must be true or false"):
        node.config_from_params({"PIDs": pids, "tiltCompensation": "yes"})
    with pytest.raises(node.ConfigError, match="goal_speed must be a positive number"):
        node.config_from_params({"PIDs": pids, "goalSpeed": 0})


def test_compute_on_pose_takes_the_newest_transform_of_its_frame():
    node = pytest.importorskip("crazyflie_controller.controller_node")
    from geometry_msgs.msg import TransformStamped

    def tf(child, x):
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id, t.transform.translation.x = "world", child, x
        return t
    msgs = [tf("vicon/cf1/cf1", 1.0), tf("vicon/cf2/cf2", 2.0), tf("/vicon/cf1/cf1", 3.0), tf("vicon/cf3/cf3", 4.0)]
    assert node.newest_transform_of(msgs, "vicon/cf1/cf1").transform.translation.x == 3.0
    assert node.newest_transform_of(msgs, "vicon/cf3/cf3").transform.translation.x == 4.0
    assert node.newest_transform_of(msgs, "vicon/cf9/cf9") is None
