"""The VRPN test server's sends: no client that stops reading holds back the others; one that is only
slow for a moment gets its whole stream, intact."""
from __future__ import annotations

import socket
import time

from crazyflie_driver.mocap import vrpn_protocol as vp
from crazyflie_driver.mocap.vrpn_client import VrpnClient, VrpnSession
from crazyflie_driver.mocap.vrpn_server import MAX_CLIENT_LAG_S, VrpnTestServer

TRACKERS = ["cf%d" % i for i in range(20)]     # with velocities ~3.7 kB a frame: buffers fill in ~1 s


def wait_until(cond, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end and not cond():
        time.sleep(0.01)
    return cond()


def raw_client(port: int) -> socket.socket:
    """Completes the handshake (sends its cookie) with a small receive buffer, then reads only if told."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", port))
    s.sendall(vp.encode_cookie())
    return s


def test_five_clients_that_never_read_hold_back_no_one():
    """Five clients complete the handshake and never read: the reading client still gets every frame
    at the stream's rate (no gap), and the five are disconnected once they are MAX_CLIENT_LAG_S behind."""
    arrivals = []

    def on_pose(report):
        if report.tracker == "cf0":
            arrivals.append(time.monotonic())

    with VrpnTestServer(TRACKERS, rate=100, velocity=True) as server:
        with VrpnClient("127.0.0.1", server.port, on_pose=on_pose, log=lambda level, text: None) as client:
            assert client.wait_connected(3.0) and wait_until(lambda: len(arrivals) >= 10, 3.0)
            silent = [raw_client(server.port) for _ in range(5)]
            try:
                assert wait_until(lambda: server.client_count() == 6, 3.0)
                start = len(arrivals)
                # their buffers fill, then they wait MAX_CLIENT_LAG_S (on a blocking server: for ever or
                # until a send times out, every frame held up meanwhile)
                assert wait_until(lambda: server.client_count() == 1, 15.0)
                n = len(arrivals)
                assert wait_until(lambda: len(arrivals) >= n + 20, 2.0)       # and it goes on
            finally:
                for s in silent:
                    s.close()
    window = arrivals[start:]
    gaps = [b - a for a, b in zip(window, window[1:])]
    assert server.slow_clients == 5
    assert window[-1] - window[0] > MAX_CLIENT_LAG_S
    assert max(gaps) < 0.25, "the reading client waited %.2f s for a frame" % max(gaps)
    assert len(window) >= 0.8 * 100 * (window[-1] - window[0])


def test_a_client_slow_for_a_moment_gets_its_whole_stream_intact():
    """A client that reads nothing for half of MAX_CLIENT_LAG_S keeps its connection and then gets every
    frame since, in order and well framed (the backlog is sent in order, never cut)."""
    with VrpnTestServer(TRACKERS, rate=100, velocity=True, fragment=True) as server:
        s = raw_client(server.port)
        try:
            assert wait_until(lambda: server.client_count() == 1, 3.0)
            time.sleep(MAX_CLIENT_LAG_S / 2)        # the pause under test, not a wait for a condition
            stamps = []
            session = VrpnSession(on_pose=lambda r: stamps.append((r.server_sec, r.server_usec))
                                  if r.tracker == "cf0" else None)
            s.settimeout(1.0)
            data = b""
            while len(data) < vp.COOKIE_SIZE:
                data += s.recv(vp.COOKIE_SIZE - len(data))
            end = time.monotonic() + 1.0
            while time.monotonic() < end:
                session.feed(s.recv(65536), time.monotonic())
        finally:
            s.close()
    assert server.slow_clients == 0
    assert session.stats.malformed == 0 and session.stats.undescribed == 0
    # every frame the server streamed from the first one the client got on, none missing, in order
    # (the server's stream thread may itself be late on a busy machine: its own stamps are the measure)
    streamed = list(server.streamed)
    assert len(stamps) >= 100 and stamps[0] in streamed
    first = streamed.index(stamps[0])
    assert stamps == streamed[first:first + len(stamps)]
