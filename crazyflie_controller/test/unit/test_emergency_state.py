"""After the server's emergency stop the controller idles, says so, and refuses to take off until re-added."""
from test_position_controller import DT, airborne, make, pose

from crazyflie_controller.position_controller import ZERO, Safety, State


def test_emergency_in_flight_is_never_automatic_ok():
    c = make()
    t = airborne(c)
    assert c.status_text() == "Automatic: ok"
    c.emergency()
    for _ in range(50):                          # fresh poses keep coming: still not "ok"
        t += DT
        assert c.update(t, pose(t, z=0.5)) == ZERO
    assert (c.state, c.safety) == (State.IDLE, Safety.EMERGENCY)
    assert c.status_text() == "Idle: emergency stop: restart and re-add the Crazyflie to fly"
    assert not c.takeoff(t, pose(t))
    assert any("takeoff refused" in m and "emergency" in m for _, m in c.messages)


def test_re_added_crazyflie_can_take_off_again():
    c = make()
    t = airborne(c)
    c.emergency()
    c.clear_emergency()
    t += DT
    c.update(t, pose(t))
    assert c.status_text() == "Idle: ok"
    assert c.takeoff(t, pose(t))
    assert c.state == State.TAKING_OFF
