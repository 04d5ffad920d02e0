"""crazyflie_ros HEAD's demo scripts without ROS running: the forwarders' parameter updates and
messages, Hover.py's and Position.py's flight plans, execute_trajectory's setpoints, and
``import crazyflie`` next to the scripts."""
from __future__ import annotations

import math
import os
import subprocess
import sys

import pytest
import rospy
from geometry_msgs.msg import PointStamped, PoseStamped, TransformStamped

from crazyflie_demo import external_position_node as fwd
from crazyflie_demo import hover_demo, position_demo
from crazyflie_demo.crazyflie_wrapper import trajectory_pieces
from crazyflie_demo.execute_trajectory import full_state
from crazyflie_driver.msg import FullState
from uav_trajectory import Trajectory

HERE = os.path.dirname(os.path.abspath(__file__))
PACKAGE = os.path.dirname(os.path.dirname(HERE))
SCRIPTS = os.path.join(PACKAGE, "scripts")


def _transform(x, y, z, q=(0.0, 0.0, 0.0, 1.0)):
    t = TransformStamped()
    t.header.frame_id = "world"
    t.header.stamp = rospy.Time(12, 5)
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
    r = t.transform.rotation
    r.x, r.y, r.z, r.w = q
    return t


def _pose(x, y, z):
    p = PoseStamped()
    p.header.frame_id = "world"
    p.pose.position.x, p.pose.position.y, p.pose.position.z = x, y, z
    p.pose.orientation.w = 1.0
    return p


class Recorder:
    def __init__(self, refuse=0):
        self.updates, self.params, self.sent, self.refuse = [], {}, [], refuse
        self.t = 0.0

    def update(self, names):
        self.updates.append(list(names))
        if self.refuse:
            self.refuse -= 1
            raise rospy.ServiceException("not connected")

    def forwarder(self, make=fwd.position_msg, estimator=fwd.KALMAN_ESTIMATOR):
        return fwd.ExternalPositionForwarder(self.update, self.sent.append, make, estimator,
                                             set_param=self.params.__setitem__, now=lambda: self.t)


def test_first_pose_sets_the_kalman_estimator_then_places_and_resets_the_filter():
    r = Recorder()
    f = r.forwarder()
    f.on_pose(_transform(0.7, -0.4, 0.01))
    assert r.updates == [["stabilizer/estimator"], ["kalman/initialX", "kalman/initialY", "kalman/initialZ"],
                         ["kalman/resetEstimation"]]
    assert r.params == {"stabilizer/estimator": 2, "kalman/initialX": 0.7, "kalman/initialY": -0.4,
                        "kalman/initialZ": 0.01, "kalman/resetEstimation": 1}
    assert r.sent == [] and f.seeded          # HEAD forwards from the second pose on
    f.on_pose(_transform(0.8, -0.3, 0.02))
    assert len(r.updates) == 3
    (msg,) = r.sent
    assert isinstance(msg, PointStamped)
    assert (msg.point.x, msg.point.y, msg.point.z) == (0.8, -0.3, 0.02)
    assert (msg.header.seq, msg.header.frame_id, msg.header.stamp) == (1, "world", rospy.Time(12, 5))


def test_a_negative_estimator_leaves_the_firmwares_choice_as_heads_scripts_did():
    r = Recorder()
    r.forwarder(estimator=-1).on_pose(_transform(1, 2, 3))
    assert ["stabilizer/estimator"] not in r.updates and "stabilizer/estimator" not in r.params
    assert r.updates[-1] == ["kalman/resetEstimation"]


def test_a_refused_update_forwards_anyway_and_retries_after_a_second():
    r = Recorder(refuse=1)
    f = r.forwarder()
    f.on_pose(_transform(1, 2, 3))
    assert not f.seeded and r.updates == [["stabilizer/estimator"]]
    r.t = 0.5
    f.on_pose(_transform(1, 2, 3))              # too soon to retry: forwarded only
    assert len(r.updates) == 1 and len(r.sent) == 1
    r.t = 1.0 + 1e-9
    f.on_pose(_transform(1, 2, 3))
    assert f.seeded and len(r.updates) == 4 and len(r.sent) == 2


def test_pose_forwarding_keeps_the_orientation_and_vrpn_poses_are_read():
    r = Recorder()
    f = r.forwarder(make=fwd.pose_msg)
    q = (0.0, 0.0, math.sin(0.3), math.cos(0.3))
    f.on_pose(_transform(0, 0, 0, q))
    f.on_pose(_transform(0.1, 0.2, 0.3, q))
    (msg,) = r.sent
    assert isinstance(msg, PoseStamped)
    o = msg.pose.orientation
    assert (o.x, o.y, o.z, o.w) == q and msg.pose.position.z == 0.3
    assert fwd.pose_of(_pose(1.0, 2.0, 3.0)) == ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))


def test_hover_plan_is_heads_takeoff_move_and_a_landing_that_stops():
    up = hover_demo.takeoff_steps(0.4)
    assert len(up) == 11 + 20 and up[0][2] == 0.0 and up[10][2] == pytest.approx(0.4) and up[-1] == (0, 0, 0.4)
    move = hover_demo.goto_steps(0.4, 0.1, 0.4, 0.2)
    assert len(move) == 40                                   # 4 s at 10 Hz: the x axis at 0.1 m/s
    dt = 1.0 / hover_demo.RATE_HZ
    assert sum(s[0] for s in move) * dt == pytest.approx(0.4)
    assert sum(s[1] for s in move) * dt == pytest.approx(0.1)
    assert move[-1][2] == pytest.approx(0.2) and all(0.2 - 1e-9 <= s[2] <= 0.4 for s in move)
    down = hover_demo.land_steps(0.2)
    assert len(down) == 10 and down[-1][2] == pytest.approx(0.0)
    assert all(a[2] > b[2] for a, b in zip(down, down[1:]))
    assert hover_demo.goto_steps(0.0, 0.0, 0.3, 0.3) == []


def test_position_takeoff_is_heads_ramp_then_hold():
    t = position_demo.takeoff_targets()
    assert len(t) == 30 and t[9][2] == pytest.approx(0.36) and t[10:] == [(0.0, 0.0, 0.4)] * 20


def test_execute_trajectory_setpoints_come_from_the_file():
    traj = Trajectory().loadcsv(os.path.join(PACKAGE, "trajectories", "takeoff.csv"))
    e = traj.eval(1.0)
    msg = full_state(e, FullState())
    assert (msg.pose.position.x, msg.pose.position.y, msg.pose.position.z) == pytest.approx(tuple(e.pos))
    assert (msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z) == pytest.approx(tuple(e.vel))
    assert (msg.acc.x, msg.acc.y, msg.acc.z) == pytest.approx(tuple(e.acc))
    q = msg.pose.orientation
    assert 2.0 * math.atan2(q.z, q.w) == pytest.approx(float(e.yaw)) and (q.x, q.y) == (0.0, 0.0)


def test_the_wrapper_uploads_our_trajectories_and_those_of_heads_module():
    ours = Trajectory().loadcsv(os.path.join(PACKAGE, "trajectories", "takeoff.csv"))

    class Poly:                                   # HEAD's uav_trajectory: Polynomial4D with px.p ... arrays
        def __init__(self, piece):
            self.duration = piece.duration
            for axis, p in (("px", piece.px), ("py", piece.py), ("pz", piece.pz), ("pyaw", piece.pyaw)):
                setattr(self, axis, type("P", (), {"p": p.p})())

    class Heads:
        polynomials = [Poly(p) for p in ours.polynomials]

    assert trajectory_pieces(Heads()) == trajectory_pieces(ours) == ours.pieces()


def _import_crazyflie_from(directory: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:9")   # nothing listens there
    code = ("import crazyflie; p = crazyflie.arrayToGeometryPoint([1, 2, 3]); "
            "print(crazyflie.Crazyflie.__name__, p.x, p.y, p.z)")
    return subprocess.run([sys.executable, "-c", code], cwd=directory,      # as a user runs a script from there
                          env=env, capture_output=True, text=True, timeout=30)


def test_import_crazyflie_next_to_the_scripts():
    r = _import_crazyflie_from(SCRIPTS)
    assert (r.returncode, r.stdout) == (0, "Crazyflie 1.0 2.0 3.0\n"), r.stderr


def test_import_crazyflie_through_the_devel_space_relay():
    """rosrun runs user scripts from devel/lib/crazyflie_demo, where crazyflie.py is catkin's relay file."""
    prefixes = os.environ.get("CMAKE_PREFIX_PATH", "").split(os.pathsep)
    relays = [os.path.join(p, "lib", "crazyflie_demo") for p in prefixes
              if p and os.path.isfile(os.path.join(p, "lib", "crazyflie_demo", "crazyflie.py"))]
    if not relays:
        pytest.skip("no catkin devel space with crazyflie.py on CMAKE_PREFIX_PATH")
    r = _import_crazyflie_from(relays[0])
    assert (r.returncode, r.stdout) == (0, "Crazyflie 1.0 2.0 3.0\n"), r.stderr
