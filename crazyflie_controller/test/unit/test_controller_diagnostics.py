"""The controller's /diagnostics entry: state and safety levels, pose age, thrust saturation on a flight."""
from test_position_controller import DT, airborne, fly_takeoff, make, pose

from crazyflie_controller.diagnostics import (
    ERROR,
    OK,
    SATURATION_WARN,
    WARN,
    SaturationWindow,
    controller_entry,
    thrust_saturated,
)
from crazyflie_controller.position_controller import Safety, State


def entry_of(c, t, window):
    p = c.pose
    return controller_entry(c.state, c.safety, None if p is None else t - p.stamp, c.config.pose_timeout,
                            c.last_command[2], window.share(), window.steps)


def step(c, t, window, p):
    cmd = c.update(t, p)
    z = c.pids["z"].gains
    window.record(t, thrust_saturated(c.state, cmd[2], z.min_output, z.max_output))
    return cmd


def test_idle_without_pose_warns():
    c = make()
    w = SaturationWindow()
    step(c, 0.0, w, None)
    level, message, values = entry_of(c, 0.0, w)
    assert (level, message) == (WARN, "Idle: no pose")
    assert dict(values)["pose age [s]"] == "never"


def window_of(c, f):
    """The saturation window fed with a flight's commands (Flight logs every control step)."""
    w = SaturationWindow()
    z = c.pids["z"].gains
    for t, _, _, _, _, cmd, state in f.log:
        w.record(t, thrust_saturated(state, cmd[2], z.min_output, z.max_output))
    return w


def test_hover_is_ok_and_pose_age_is_reported():
    c, f = fly_takeoff(False, seconds=8.0)            # a 32 g quadrotor model, take-off to 0.5 m
    w = window_of(c, f)
    t = f.model.t
    level, message, values = entry_of(c, t, w)
    assert (level, message) == (OK, "Automatic: ok")
    v = dict(values)
    assert 0.0 <= float(v["pose age [s]"]) < 0.05
    assert v["thrust saturated share"] == "0.00"
    assert int(v["control steps in window"]) in (100, 101)    # 2 s of 50 Hz steps


def test_a_vehicle_too_heavy_to_climb_saturates_the_thrust_and_warns():
    c, f = fly_takeoff(False, seconds=15.0, mass=0.070)  # 4 motors at full thrust lift about 56 g: the
    # integrator climbs to the limit within about 13 s on the ground
    w = window_of(c, f)
    level, message, values = entry_of(c, f.model.t, w)
    assert c.state == State.AUTOMATIC
    assert float(dict(values)["thrust saturated share"]) > SATURATION_WARN
    assert level == WARN and "thrust at its limit" in message


def test_stale_pose_warns_and_lost_pose_errors():
    c = make()
    w = SaturationWindow()
    t = airborne(c)
    last = t
    levels = set()
    while t < last + c.config.lost_pose_land_timeout + 0.5:
        t += DT
        step(c, t, w, pose(last, z=0.5))
        levels.add((entry_of(c, t, w)[0], c.safety))
    assert (WARN, Safety.HOLDING) in levels
    assert (ERROR, Safety.BLIND_DESCENT) in levels


def test_saturation_window_forgets_old_steps():
    w = SaturationWindow(1.0)
    assert w.share() is None
    for i in range(10):
        w.record(i * 0.1, True)
    for i in range(10, 30):
        w.record(i * 0.1, False)
    assert w.share() == 0.0 and w.steps == 11
