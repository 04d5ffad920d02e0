"""VrpnClient against the VRPN test server over loopback (ephemeral ports): poses of several
trackers, names, Y-up conversion, staleness, reconnection, garbage on the stream."""
from __future__ import annotations

import logging
import math
import socket
import threading
import time

import pytest

from crazyflie_driver.mocap import vrpn_protocol as vp
from crazyflie_driver.mocap.vrpn_bridge import VrpnBridge, config_from_params
from crazyflie_driver.mocap.vrpn_client import VrpnClient
from crazyflie_driver.mocap.vrpn_server import GARBAGE_KINDS, VrpnTestServer
from support.ports import free_port


def wait_until(cond, timeout=5.0, period=0.01):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = cond()
        if v:
            return v
        time.sleep(period)
    return cond()


class Recorder:
    def __init__(self):
        self.lock = threading.Lock()
        self.poses = []
        self.twists = []
        self.logs = []

    def pose(self, r):
        with self.lock:
            self.poses.append(r)

    def twist(self, r):
        with self.lock:
            self.twists.append(r)

    def log(self, level, text):
        with self.lock:
            self.logs.append((level, text))

    def of(self, name):
        with self.lock:
            return [p for p in self.poses if p.tracker == name]

    def count(self):
        with self.lock:
            return len(self.poses)


@pytest.fixture
def rec():
    return Recorder()


def make_client(server_port, rec, **kw):
    kw.setdefault("retry_min", 0.1)
    kw.setdefault("retry_max", 0.4)
    return VrpnClient("127.0.0.1", server_port, on_pose=rec.pose, on_twist=rec.twist, log=rec.log, **kw)


def test_poses_of_several_trackers_arrive_exactly(rec):
    s = math.sqrt(0.5)
    with VrpnTestServer(["crazyflie1", "crazyflie2", "Rigid Body 3"], rate=200) as server:
        server.set_pose("crazyflie1", (0.125, -1.5, 0.75), (0.0, 0.0, s, s))
        server.set_pose("crazyflie2", (2.0, 3.0, 0.25), (0.5, 0.5, 0.5, 0.5))
        with make_client(server.port, rec) as client:
            assert client.wait_connected(3.0)
            assert wait_until(lambda: all(len(rec.of(n)) >= 20 for n in server.trackers))
            assert client.server_version == "07.38"
            assert client.session.trackers() == ["crazyflie1", "crazyflie2", "Rigid Body 3"]
            p1, p2, p3 = rec.of("crazyflie1")[-1], rec.of("crazyflie2")[-1], rec.of("Rigid Body 3")[-1]
    assert (p1.position, p1.orientation) == ((0.125, -1.5, 0.75), (0.0, 0.0, s, s))
    assert (p2.position, p2.orientation) == ((2.0, 3.0, 0.25), (0.5, 0.5, 0.5, 0.5))
    assert p3.position == (2.0, 0.0, 0.0)               # default pose of the third tracker
    assert abs(p1.server_sec + p1.server_usec * 1e-6 - time.time()) < 5.0
    assert client.session.stats.undescribed == 0 and client.session.stats.malformed == 0


def test_rate_is_kept_and_nothing_is_lost(rec):
    with VrpnTestServer(["a", "b"], rate=100) as server:
        with make_client(server.port, rec) as client:
            assert client.wait_connected(3.0)
            time.sleep(1.0)
            sent = server.poses_sent
            assert wait_until(lambda: rec.count() >= sent, timeout=2.0)
    assert 150 <= sent <= 230                           # ~100 Hz x 2 trackers x 1 s
    assert rec.count() >= sent


def test_stream_cut_into_small_pieces_is_reassembled(rec):
    with VrpnTestServer(["cf1"], rate=100, velocity=True, fragment=True) as server:
        server.set_pose("cf1", (1.0, 2.0, 3.0))
        with make_client(server.port, rec):
            assert wait_until(lambda: len(rec.of("cf1")) >= 20 and len(rec.twists) >= 20)
    assert rec.of("cf1")[-1].position == (1.0, 2.0, 3.0)


def test_trackers_list_filters_and_late_trackers_are_discovered(rec):
    found = []
    with VrpnTestServer(["cf1", "cf2"], rate=100) as server:
        with make_client(server.port, rec, trackers=["cf2", "cf3"], on_tracker=found.append) as client:
            assert wait_until(lambda: len(rec.of("cf2")) >= 10)
            server.add_tracker("cf3")                   # described on the fly
            assert wait_until(lambda: len(rec.of("cf3")) >= 10)
            assert rec.of("cf1") == []
            assert found == ["cf1", "cf2", "cf3"]
            assert client.session.stats.ignored > 0


def test_velocity_reports_and_y_up_conversion_end_to_end(rec):
    """The server streams Y-up (as Motive does); the bridge with y_up gives back the Z-up truth."""
    yaw = math.radians(30)
    truth_q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    with VrpnTestServer(["cf1"], rate=100, velocity=True, y_up=True) as server:
        server.set_pose("cf1", (0.5, -0.25, 1.25), truth_q)
        server.set_velocity("cf1", (0.1, 0.2, 0.3), (0.0, 0.0, math.sin(0.005), math.cos(0.005)), 0.01)
        with make_client(server.port, rec):
            assert wait_until(lambda: len(rec.of("cf1")) >= 5 and len(rec.twists) >= 5)
    raw = rec.of("cf1")[-1]
    assert raw.position == (0.5, 1.25, 0.25)            # on the wire: X, Y = up, Z = -y
    bridge = VrpnBridge(config_from_params({"y_up": True, "trackers": ["cf1"]}))
    out = bridge.pose(raw)
    assert out.position == (0.5, -0.25, 1.25)
    assert out.orientation == pytest.approx(truth_q, abs=1e-15)
    tw = bridge.twist(rec.twists[-1])
    assert tw.linear == pytest.approx((0.1, 0.2, 0.3))
    assert tw.angular == pytest.approx((0.0, 0.0, 1.0))     # 0.01 rad in 0.01 s about +z


def test_staleness_of_a_hidden_tracker(rec):
    bridge = VrpnBridge(config_from_params({"refresh_tracker_frequency": 1.0, "stale_timeout": 0.1}))
    with VrpnTestServer(["cf1", "cf2"], rate=100) as server:
        with VrpnClient("127.0.0.1", server.port, on_pose=bridge.pose, log=rec.log):
            assert wait_until(lambda: bridge.staleness.names() == ["cf1", "cf2"])
            time.sleep(0.1)
            assert bridge.staleness.check(time.monotonic()) == []
            server.hide("cf2")
            time.sleep(0.25)
            events = bridge.staleness.check(time.monotonic())
            assert [(e.name, e.kind) for e in events] == [("cf2", "stale")]
            assert bridge.staleness.age("cf2", time.monotonic()) > 0.2
            assert bridge.staleness.age("cf1", time.monotonic()) < 0.1
            server.hide("cf2", False)
            assert wait_until(lambda: bridge.staleness.age("cf2", time.monotonic()) < 0.05)
            assert [(e.name, e.kind) for e in bridge.staleness.check(time.monotonic())] == [("cf2", "fresh")]


def test_server_absent_then_started_with_backoff_log(rec):
    port = free_port()
    client = make_client(port, rec, retry_min=0.05, retry_max=0.2).start()
    try:
        assert wait_until(lambda: client.failures >= 4, timeout=3.0)
        assert not client.connected
        with rec.lock:
            lines = [t for lvl, t in rec.logs if lvl == logging.WARNING]
        assert "connection refused" in lines[0] and "127.0.0.1:%d" % port in lines[0]
        delays = [float(t.rsplit("retrying in ", 1)[1].split()[0]) for t in lines[:4]]
        assert delays == [0.05, 0.1, 0.2, 0.2]             # doubling up to retry_max
        with VrpnTestServer(["cf1"], port=port) as server:
            assert client.wait_connected(3.0)
            assert wait_until(lambda: len(rec.of("cf1")) >= 5)
            assert server.accepted == 1
    finally:
        client.stop()
    assert client.state == "stopped"


def test_reconnects_after_server_restart_with_fresh_ids(rec):
    server = VrpnTestServer(["cf1"], rate=100, sender_id_offset=3)
    server.start()
    try:
        with make_client(server.port, rec) as client:
            assert wait_until(lambda: len(rec.of("cf1")) >= 5)
            server.stop()
            assert wait_until(lambda: not client.connected, timeout=2.0)
            n = rec.count()
            time.sleep(0.3)
            assert rec.count() == n                     # nothing while the server is down
            # back with other numeric ids for the same names: the client must not mix them up
            server._sender_ids = {vp.CONTROL_SENDER: 20, "cf1": 21}
            server.set_pose("cf1", (4.0, 5.0, 6.0))
            server.start()
            assert wait_until(lambda: rec.of("cf1")[-1].position == (4.0, 5.0, 6.0), timeout=3.0)
            assert client.connections == 2
            assert client.session.senders == {20: vp.CONTROL_SENDER, 21: "cf1"}
    finally:
        server.stop()
    assert any("connection lost (closed by the server)" in t for _, t in rec.logs)


def test_dropped_connection_is_reopened(rec):
    with VrpnTestServer(["cf1"], rate=100) as server:
        with make_client(server.port, rec) as client:
            assert wait_until(lambda: client.connections == 1 and len(rec.of("cf1")) >= 3)
            for i in range(3):
                # the client counts itself connected on the server's cookie, the server lists it only after the
                # client's cookie and the descriptions: drop it once the server has it, or nothing is dropped
                assert server.wait_for_clients(1)
                server.drop_clients()
                assert wait_until(lambda: client.connections == i + 2 and client.connected, timeout=3.0)
            n = rec.count()
            assert wait_until(lambda: rec.count() >= n + 10)


def test_garbage_is_skipped_without_losing_the_stream(rec):
    with VrpnTestServer(["cf1"], rate=100) as server:
        with make_client(server.port, rec) as client:
            assert wait_until(lambda: len(rec.of("cf1")) >= 3)
            for kind in GARBAGE_KINDS:
                server.send_garbage(kind)
            n = rec.count()
            assert wait_until(lambda: rec.count() >= n + 20)
            st = client.session.stats
            assert client.connections == 1              # same connection all along
            assert st.malformed == 4                    # short pose, long velocity, 2 bad descriptions
            assert st.undescribed >= 1 and st.ignored >= 2 and st.texts == 1
            assert all(p.position == (0.0, 0.0, 0.0) for p in rec.of("cf1"))


def test_broken_framing_resets_the_connection_and_poses_resume(rec):
    with VrpnTestServer(["cf1"], rate=100) as server:
        with make_client(server.port, rec) as client:
            assert wait_until(lambda: len(rec.of("cf1")) >= 3)
            server.send_raw(b"\x00\x00\x00\x05" + b"\xff" * 20)    # length 5 < header size
            assert wait_until(lambda: client.connections == 2 and client.connected, timeout=3.0)
            n = rec.count()
            assert wait_until(lambda: rec.count() >= n + 10)
    assert any("broken stream" in t for _, t in rec.logs)


def test_a_peer_that_is_not_vrpn_is_refused_and_retried(rec):
    ls = socket.socket()
    ls.bind(("127.0.0.1", 0))
    ls.listen(4)
    port = ls.getsockname()[1]

    def serve():
        for _ in range(2):
            try:
                c, _a = ls.accept()
            except OSError:
                return
            c.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")
            time.sleep(0.2)
            c.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    try:
        client = make_client(port, rec).start()
        assert wait_until(lambda: client.failures >= 2, timeout=3.0)
        client.stop()
    finally:
        ls.close()
    assert client.connections == 0
    assert any("not a VRPN 07 peer" in t for _, t in rec.logs)


def test_stop_is_prompt_while_waiting_to_retry(rec):
    client = make_client(free_port(), rec, retry_min=5.0, retry_max=5.0).start()
    assert wait_until(lambda: client.failures >= 1)
    t0 = time.monotonic()
    client.stop()
    assert time.monotonic() - t0 < 1.0
