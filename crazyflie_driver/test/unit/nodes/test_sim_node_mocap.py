"""The sim node's motion-capture publishing: one TFMessage per frame, no repeated stamps, wire bytes as genpy's."""
from __future__ import annotations

import io
import time

import numpy as np
import pytest

from crazyflie_driver.sim.node_config import StampGuard, newest_per_body, world_status
from crazyflie_driver.sim.room.mocap import MocapFrame

genpy = pytest.importorskip("genpy")
geometry_msgs = pytest.importorskip("geometry_msgs.msg")
tf2_msgs = pytest.importorskip("tf2_msgs.msg")

from crazyflie_driver.nodes.tf_wire import TransformWire, packed_message_types  # noqa: E402


def frame(name: str, t: float, x: float = 0.0) -> MocapFrame:
    return MocapFrame(name, np.array([x, 0.0, 0.5]), np.array([0.0, 0.0, 0.0, 1.0]), t, t)


def test_a_late_delivery_keeps_only_the_newest_frame_of_each_body():
    frames = [frame("cf1", 0.01, 1.0), frame("cf2", 0.01), frame("cf1", 0.02, 2.0), frame("cf2", 0.02)]
    out = newest_per_body(frames)
    assert [(f.name, f.stamp) for f in out] == [("cf1", 0.02), ("cf2", 0.02)]
    assert out[0].position[0] == 2.0


def test_no_child_frame_gets_the_same_or_an_older_stamp_twice():
    guard = StampGuard()
    assert guard.admit("cf1", 1000)
    assert guard.admit("cf2", 1000)              # other frames are independent
    assert not guard.admit("cf1", 1000)          # what tf2 reports as TF_REPEATED_DATA
    assert not guard.admit("cf1", 999)
    assert guard.admit("cf1", 1001)
    assert guard.refused == 2


def genpy_transform(stamp_ns: int, parent: str, child: str, position, quaternion):
    import rospy
    t = geometry_msgs.TransformStamped()
    t.header.stamp = rospy.Time(*divmod(stamp_ns, 1000000000))
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = position
    t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w = quaternion
    return t


def test_packed_tf_message_has_the_bytes_genpy_writes_and_reads_back():
    packed_tf, packed_transform = packed_message_types()
    stamp = 1700000000123456789
    bodies = [("vicon/cf1/cf1", (1.0, -2.0, 0.5), (0.1, 0.2, 0.3, 0.927)), ("cf2", (0.0, 3.0, 1.25), (0, 0, 0, 1))]
    parts = [TransformWire("world", child).pack(stamp + k, p, q) for k, (child, p, q) in enumerate(bodies)]
    ours, theirs = io.BytesIO(), io.BytesIO()
    packed_tf(parts).serialize(ours)
    tf2_msgs.TFMessage([genpy_transform(stamp + k, "world", c, p, q)
                        for k, (c, p, q) in enumerate(bodies)]).serialize(theirs)
    assert ours.getvalue() == theirs.getvalue()
    back = tf2_msgs.TFMessage().deserialize(ours.getvalue())
    assert [t.child_frame_id for t in back.transforms] == ["vicon/cf1/cf1", "cf2"]
    assert back.transforms[1].header.stamp.to_nsec() == stamp + 1
    assert back.transforms[0].transform.translation.y == -2.0
    # the per-body topic: rospy's sequence number goes into the header
    single = packed_transform(parts[0])
    single.header.seq = 42
    buf = io.BytesIO()
    single.serialize(buf)
    decoded = geometry_msgs.TransformStamped().deserialize(buf.getvalue())
    assert decoded.header.seq == 42 and decoded.child_frame_id == "vicon/cf1/cf1"
    assert decoded.header.stamp.to_nsec() == stamp


def test_world_status_warns_with_the_factor_when_behind():
    ok = world_status(1.0, 1.0, 2, 0, 0, 12.0, 0.95)
    assert ok.level == 0 and dict(ok.values)["real-time factor"] == "1.000"
    behind = world_status(0.61, 1.0, 49, 230, 3, 40.0, 0.95)
    assert behind.level == 1 and "0.61x" in behind.message
    assert dict(behind.values)["ticks behind"] == "230" and dict(behind.values)["vehicles"] == "49"
    assert world_status(25.0, 0.0, 1, 0, 0, 1.0, 0.95).level == 0      # fast mode is never "behind"


def test_world_that_cannot_keep_real_time_warns_with_its_factor(caplog):
    from crazyflie_driver.sim.room.world import World

    w = World(speed=1.0, seed=1)
    w.add_vehicle("cf1")
    w.add_tick_listener(lambda t: time.sleep(0.004), 0.001)    # each 1 ms tick costs >= 4 ms of wall time
    with caplog.at_level("WARNING", logger="crazyflie_driver.sim.room.world"):
        w.start()
        try:
            end = time.monotonic() + 10.0
            while time.monotonic() < end and not any("behind real time" in r.getMessage() for r in caplog.records):
                time.sleep(0.05)
        finally:
            w.stop()
    warnings = [r.getMessage() for r in caplog.records if "behind real time" in r.getMessage()]
    assert len(warnings) == 1, warnings                           # throttled
    assert 0.0 < w.realtime_factor < 0.3
    assert "%.2fx" % w.realtime_factor in warnings[0]


def test_world_status_says_the_speed_mode_the_target_and_the_host_lag():
    from crazyflie_driver.sim.room.pacing import Pacing

    slowed = world_status(0.5, 0.5, 1, 0, 0, 3.0, 0.95, Pacing(True, 1.0), 0.004)
    values = dict(slowed.values)
    assert slowed.level == 0 and "slowed down to 0.50x" in slowed.message
    assert values["speed mode"] == "auto" and values["target speed"] == "1.000" and values["speed"] == "0.500"
    assert values["host run-queue wait [ms]"] == "4.00"
    fixed = dict(world_status(1.0, 1.0, 1, 0, 0, 3.0, 0.95).values)
    assert fixed["speed mode"] == "fixed" and "host run-queue wait [ms]" not in fixed


def test_clock_is_published_at_start_and_every_period_of_world_time_with_the_tick_time():
    """/clock is the world's own time: one message now (0), then one per CLOCK_PERIOD_S of world time."""
    rosgraph_msgs = pytest.importorskip("rosgraph_msgs.msg")
    from crazyflie_driver.nodes.sim_node import CLOCK_PERIOD_S, _publish_clock
    from crazyflie_driver.sim.room.world import World

    class Pub:
        def __init__(self):
            self.sent = []

        def publish(self, msg):
            self.sent.append(msg.clock.to_nsec())

    w = World(speed=0, seed=1)
    w.add_vehicle("cf1")
    pub = Pub()
    _publish_clock(w, pub, rosgraph_msgs.Clock)
    assert pub.sent == [0]
    w.step(100)                                          # 0.1 s of world time
    period_ns = int(round(CLOCK_PERIOD_S * 1e9))
    assert pub.sent == list(range(0, 100000001, period_ns))
    assert pub.sent[-1] == int(round(w.time * 1e9))
