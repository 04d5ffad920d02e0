"""Physics backend of the simulated world: thrust map, free fall, motor lag, torques, floor."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crazyflie_driver.sim.room.physics import (
    BodyStates,
    RigidBodyBackend,
    VehicleParams,
    euler_from_quat,
    quat_from_euler,
    quat_to_matrix,
)


def bodies(*positions, params=None):
    s = BodyStates()
    for p in positions:
        s.add(params or VehicleParams(), p)
    return s


def test_hover_command_matches_the_computed_forster_figures():
    # docs/simulation.md, "Vehicle physics": 27 g -> 36 344, 32 g -> 40 922, 34 g -> 42 666
    assert VehicleParams().hover_command() == pytest.approx(36344, abs=1)
    assert VehicleParams(mass=0.032).hover_command() == pytest.approx(40922, abs=1)
    assert VehicleParams(mass=0.034).hover_command() == pytest.approx(42666, abs=1)
    p = VehicleParams()
    assert 4 * p.thrust(36344) == pytest.approx(0.027 * 9.81, rel=1e-4)
    assert p.thrust(0) == 0.0


def test_bad_params_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="mass"):
        VehicleParams(mass=0.0)
    with pytest.raises(ValueError, match="motor_tau"):
        VehicleParams(motor_tau=0.0)


def test_free_fall_with_motors_off_follows_half_g_t_squared():
    s = bodies((0.0, 0.0, 10.0), (1.0, 0.0, 20.0))
    backend = RigidBodyBackend()
    for _ in range(1000):
        backend.step(s, np.zeros((2, 4)), 0.001)
    drop = 0.5 * 9.81 * 1.0 ** 2
    assert s.position[:, 2] == pytest.approx([10.0 - drop, 20.0 - drop], abs=1e-6)
    assert s.velocity[:, 2] == pytest.approx([-9.81, -9.81], abs=1e-9)
    assert s.position[:, :2] == pytest.approx(np.array([[0.0, 0.0], [1.0, 0.0]]))
    # in free fall an accelerometer reads nothing
    assert np.abs(s.specific_force).max() < 1e-9


def test_step_with_larger_dt_integrates_in_one_millisecond_substeps():
    a, b = bodies((0, 0, 5.0)), bodies((0, 0, 5.0))
    RigidBodyBackend().step(a, np.zeros((1, 4)), 0.05)
    for _ in range(50):
        RigidBodyBackend().step(b, np.zeros((1, 4)), 0.001)
    assert a.position == pytest.approx(b.position)


def test_motor_lag_reaches_63_percent_after_tau():
    p = VehicleParams(motor_tau=0.06)
    s = bodies((0, 0, 5.0), params=p)
    u = np.full((1, 4), 40000.0)
    for _ in range(60):                       # 60 ms = tau
        RigidBodyBackend().step(s, u, 0.001)
    assert s.thrust[0, 0] / p.thrust(40000) == pytest.approx(1 - math.exp(-1), abs=0.002)
    for _ in range(240):                      # 5 tau
        RigidBodyBackend().step(s, u, 0.001)
    assert s.thrust[0, 0] / p.thrust(40000) == pytest.approx(1.0, abs=0.01)


def test_rests_on_the_floor_and_takes_off_only_above_its_weight():
    p = VehicleParams()
    s = bodies((0, 0, 0.0), (1, 0, 0.0))
    hover = p.hover_command()
    u = np.array([[hover * 0.97] * 4, [hover * 1.05] * 4])
    for _ in range(1000):
        RigidBodyBackend().step(s, u, 0.001)
    assert s.position[0] == pytest.approx([0, 0, 0])
    assert s.on_ground[0] and not s.on_ground[1]
    assert s.specific_force[0] == pytest.approx([0, 0, 9.81])   # the floor carries the weight
    assert s.position[1, 2] > 0.05


def test_does_not_sink_through_the_floor_when_dropped():
    s = bodies((0, 0, 0.5))
    for _ in range(2000):
        RigidBodyBackend().step(s, np.zeros((1, 4)), 0.001)
    assert s.position[0, 2] == 0.0
    assert s.velocity[0] == pytest.approx([0, 0, 0])
    assert s.on_ground[0]


def test_floor_friction_stops_sliding():
    s = bodies((0, 0, 0.0))
    s.velocity[0] = (1.0, 0.5, 0.0)
    RigidBodyBackend().step(s, np.zeros((1, 4)), 0.001)
    assert s.velocity[0] == pytest.approx([0, 0, 0])
    assert s.position[0, :2] == pytest.approx([0.0, 0.0], abs=2e-3)


def spin_up(commands, steps=100):
    """Body rates after ``steps`` ms from rest in the air with the given motor commands."""
    s = bodies((0, 0, 5.0))
    for _ in range(steps):
        RigidBodyBackend().step(s, np.array([commands], dtype=float), 0.001)
    return s


def test_x_layout_torque_signs():
    # M1 front-right, M2 back-right, M3 back-left, M4 front-left (docs/simulation.md, "Vehicle physics")
    left_up = spin_up([30000, 30000, 40000, 40000])          # more thrust on the left: roll right-hand +
    assert left_up.omega[0, 0] > 0.1 and abs(left_up.omega[0, 1]) < 0.02
    nose_up = spin_up([40000, 30000, 30000, 40000])          # more thrust in front: nose up = -pitch
    assert nose_up.omega[0, 1] < -0.1 and abs(nose_up.omega[0, 0]) < 0.02
    m24 = spin_up([30000, 40000, 30000, 40000])              # M2/M4 react +κF: counter-clockwise
    assert m24.omega[0, 2] > 0.1
    m13 = spin_up([40000, 30000, 40000, 30000])
    assert m13.omega[0, 2] < -0.1


def test_roll_torque_magnitude_matches_arm_and_inertia():
    p = VehicleParams(motor_tau=1e-6)                        # instant motors: exact torque
    s = bodies((0, 0, 5.0), params=p)
    RigidBodyBackend().step(s, np.array([[30000, 30000, 40000, 40000]], dtype=float), 0.001)
    d = 0.046 / math.sqrt(2)
    tau_x = d * 2 * (p.thrust(40000) - p.thrust(30000))
    assert s.omega[0, 0] == pytest.approx(tau_x / p.inertia[0] * 0.001, rel=1e-3)


def test_quaternion_helpers_agree():
    q = quat_from_euler(0.1, -0.2, 0.3)
    assert euler_from_quat(q[None])[0] == pytest.approx([0.1, -0.2, 0.3])
    r = quat_to_matrix(q[None])[0]
    assert r @ r.T == pytest.approx(np.eye(3), abs=1e-12)
    # yaw +90°: body x points to world y
    r90 = quat_to_matrix(quat_from_euler(0, 0, math.pi / 2)[None])[0]
    assert r90 @ [1, 0, 0] == pytest.approx([0, 1, 0], abs=1e-12)


def test_actions_shape_is_checked():
    with pytest.raises(ValueError, match="actions"):
        RigidBodyBackend().step(bodies((0, 0, 1)), np.zeros((2, 4)), 0.001)
