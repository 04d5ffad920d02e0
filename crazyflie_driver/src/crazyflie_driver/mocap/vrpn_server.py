"""A fake motion-capture system: a small VRPN tracker server, for a desk or a test (see docs/mocap.md).

Speaks the wire format of a real VRPN server over TCP (clients that connect to it directly, as
ours does): cookie, sender and type descriptions (ids deliberately offset so that no client can
get away with hard-coded ids), then ``vrpn_Tracker Pos_Quat`` (and optionally
``vrpn_Tracker Velocity``) for every tracker at ``rate`` Hz. Faults on demand: drop every
connection, stop and restart on the same port, hide a tracker (as a mocap does with an occluded
body), inject unknown or malformed messages, or bytes that break the framing.

Sends never block: each client has its own backlog of what its socket did not take yet, flushed as
it drains. A client whose backlog grows older than ``MAX_CLIENT_LAG_S`` (or bigger than
``MAX_CLIENT_BACKLOG_BYTES``) is disconnected, so a client that stops reading never holds back the
others (docs/mocap.md, "Slow clients").

Standalone: ``python3 -m crazyflie_driver.mocap.vrpn_server --tracker cf1 --tracker cf2``
(see ``--help``); poses are given in the ROS Z-up frame and streamed Y-up with ``--y-up``.
"""
from __future__ import annotations

import argparse
import logging
import math
import random
import select
import socket
import sys
import threading
import time
from collections import deque
from typing import Callable, Deque, Dict, Iterable, List, Optional, Sequence, Tuple

from crazyflie_driver.mocap import vrpn_protocol as vp
from crazyflie_driver.mocap.frames import z_up_to_y_up_quaternion, z_up_to_y_up_vector

#: Type names in the order a VRPN tracker server registers them (ids are offset by type_id_offset).
SERVER_TYPES = vp.CONNECTION_EVENT_TYPES + (
    vp.TYPE_POS_QUAT, vp.TYPE_VELOCITY, vp.TYPE_ACCELERATION,
    "vrpn_Tracker To_Room", "vrpn_Tracker Unit_To_Sensor", "vrpn_Tracker Workspace",
    "vrpn_Tracker Request_Tracker_To_Room", "vrpn_Tracker Request_Unit_To_Sensor",
    "vrpn_Tracker Request_Workspace", "vrpn_Tracker Reset_Origin", "vrpn_Tracker Set_Update_Rate",
    vp.TYPE_TEXT, vp.TYPE_PING, vp.TYPE_PONG, "vrpn_Analog Channel",
)

GARBAGE_KINDS = ("unknown_type", "undescribed", "short_pos_quat", "long_velocity", "bad_description",
                 "udp_description", "text", "empty_name")

PoseFn = Callable[[str, float], Tuple[Sequence[float], Sequence[float]]]

LOG = logging.getLogger(__name__)
#: A client whose oldest unsent data waited this long (s) is disconnected: its poses are stale for any
#: controller by then (a swarm calls a pose stale after 0.2 s), and a reconnect gives it a current stream.
MAX_CLIENT_LAG_S = 1.0
#: ... or whose unsent data exceeds this (bytes; about 1 s of 100 trackers at 100 Hz), whatever the rate.
MAX_CLIENT_BACKLOG_BYTES = 1 << 20
#: Kernel send buffer of each client socket (bytes; ~15 frames of 49 trackers): what a client has not
#: taken waits in its backlog, where its age is known, rather than unseen in an ever-growing kernel buffer.
CLIENT_SEND_BUFFER_BYTES = 64 * 1024
#: Stamps of streamed frames a server keeps (``streamed``; 100 s at 100 Hz).
STREAMED_KEPT = 10000
#: How often a client's reader thread looks up when nothing happens (s).
_PEER_POLL_S = 0.2


class _Peer:
    """One client: its non-blocking socket and what it has not taken yet (``lock`` guards both)."""

    def __init__(self, sock: socket.socket, addr) -> None:
        self.sock = sock
        self.addr = addr
        self.lock = threading.Lock()
        self.alive = True
        self.backlog: Deque[Tuple[bytes, float]] = deque()     # (bytes, when queued), oldest first
        self.backlog_bytes = 0

    def queue(self, pieces: Sequence[bytes], now: float) -> None:
        for piece in pieces:
            self.backlog.append((piece, now))
            self.backlog_bytes += len(piece)

    def flush(self, now: float) -> Optional[str]:
        """Send what the socket takes without waiting; why the client must go (or None)."""
        while self.backlog:
            piece, queued = self.backlog[0]
            try:
                n = self.sock.send(piece)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as e:
                return "gone (%s)" % (e,)
            self.backlog_bytes -= n
            if n < len(piece):
                self.backlog[0] = (piece[n:], queued)
                break
            self.backlog.popleft()
        if self.backlog:
            lag = now - self.backlog[0][1]
            if lag > MAX_CLIENT_LAG_S or self.backlog_bytes > MAX_CLIENT_BACKLOG_BYTES:
                return "too slow: took nothing for %.2f s, %d bytes waiting" % (lag, self.backlog_bytes)
        return None


class VrpnTestServer:
    """Streams tracker poses to every connected client. Poses are Z-up unless ``y_up``.

    ``pose_fn(name, t)`` gives (position, quaternion xyzw) at Unix time t; default: the pose set
    with :meth:`set_pose`, else tracker i resting at (i, 0, 0) with identity orientation.
    """

    def __init__(self, trackers: Iterable[str] = ("cf1",), host: str = "127.0.0.1", port: int = 0,
                 rate: float = 100.0, velocity: bool = False, y_up: bool = False,
                 pose_fn: Optional[PoseFn] = None, sender_id_offset: int = 3, type_id_offset: int = 7,
                 fragment: bool = False, version: str = vp.SERVER_VERSION, seed: int = 0,
                 stream: bool = True) -> None:
        if rate <= 0:
            raise ValueError("rate must be > 0 Hz, got %r" % (rate,))
        self.host = host
        self.port = port
        self.rate = float(rate)
        self.velocity = velocity
        self.y_up = y_up
        self.pose_fn = pose_fn
        self.fragment = fragment
        self.version = version
        self.stream = stream            # False: no timer; the owner sends each cycle with send_poses()
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._sender_ids: Dict[str, int] = {vp.CONTROL_SENDER: sender_id_offset}
        self._next_sender = sender_id_offset + 1
        self._type_ids = {name: type_id_offset + i for i, name in enumerate(SERVER_TYPES)}
        self._poses: Dict[str, Tuple[Tuple[float, ...], Tuple[float, ...]]] = {}
        self._velocities: Dict[str, vp.Velocity] = {}
        self._hidden: set = set()
        self._peers: List[_Peer] = []
        self._listener: Optional[socket.socket] = None
        self._stop = threading.Event()
        self._threads: List[threading.Thread] = []
        self._seq = 0
        self.poses_sent = 0             # Pos_Quat messages written (all clients)
        self.streamed: Deque[Tuple[int, int]] = deque(maxlen=STREAMED_KEPT)
        """(sec, usec) stamp of each frame the stream sent to its clients, newest last (what a test
        compares a client's frames with)."""
        self.accepted = 0               # connections that completed the handshake
        self.rejected_cookies = 0
        self.slow_clients = 0           # disconnected for not reading (MAX_CLIENT_LAG_S)
        for name in trackers:
            self.add_tracker(name)

    # -- configuration ---------------------------------------------------------------------------
    @property
    def trackers(self) -> List[str]:
        with self._lock:
            return [n for n in self._sender_ids if n != vp.CONTROL_SENDER]

    def add_tracker(self, name: str) -> None:
        """Register a tracker; connected clients get its description at once."""
        with self._lock:
            if name in self._sender_ids:
                return
            sid = self._sender_ids[name] = self._next_sender
            self._next_sender += 1
        self._broadcast(vp.encode_sender_description(sid, name))

    def set_pose(self, name: str, position: Sequence[float], orientation: Sequence[float] = (0, 0, 0, 1)) -> None:
        """Pose of ``name`` in the ROS Z-up frame (converted to Y-up on the wire when ``y_up``)."""
        with self._lock:
            self._poses[name] = (tuple(float(v) for v in position), tuple(float(v) for v in orientation))

    def set_velocity(self, name: str, linear: Sequence[float], rotation: Sequence[float] = (0, 0, 0, 1),
                     dt: float = 0.01) -> None:
        with self._lock:
            self._velocities[name] = vp.Velocity(0, vp.vec3(linear), vp.quat(rotation), float(dt))

    def hide(self, name: str, hidden: bool = True) -> None:
        """Stop (or resume) sending ``name``, as a mocap does with a body it cannot see."""
        with self._lock:
            if hidden:
                self._hidden.add(name)
            else:
                self._hidden.discard(name)

    # -- life cycle ------------------------------------------------------------------------------
    def start(self) -> Tuple[str, int]:
        """Listen (on the same port after a :meth:`stop`) and start streaming; returns (host, port)."""
        if self._listener is not None:
            return self.host, self.port
        ls = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        ls.bind((self.host, self.port))
        ls.listen(8)
        ls.settimeout(0.1)
        self.port = ls.getsockname()[1]
        self._listener = ls
        self._stop.clear()
        self._threads = [threading.Thread(target=self._accept_loop, name="vrpn-server-accept", daemon=True)]
        if self.stream:
            self._threads.append(threading.Thread(target=self._stream_loop, name="vrpn-server-stream", daemon=True))
        for t in self._threads:
            t.start()
        return self.host, self.port

    def stop(self) -> None:
        """Close the listening socket and every connection (clients see EOF)."""
        self._stop.set()
        for t in self._threads:
            t.join(2.0)
        self._threads = []
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        self.drop_clients()

    def restart(self, down_for: float = 0.0) -> None:
        self.stop()
        if down_for > 0:
            time.sleep(down_for)
        self.start()

    def __enter__(self) -> VrpnTestServer:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def drop_clients(self) -> None:
        """Close every client connection; the server keeps listening."""
        with self._lock:
            peers, self._peers = self._peers, []
        for p in peers:
            p.alive = False
            try:
                p.sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            p.sock.close()

    def client_count(self) -> int:
        with self._lock:
            return len(self._peers)

    def wait_for_clients(self, n: int = 1, timeout: float = 5.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.client_count() >= n:
                return True
            time.sleep(0.01)
        return self.client_count() >= n

    # -- faults ----------------------------------------------------------------------------------
    def send_raw(self, data: bytes) -> None:
        """Bytes as they are to every client (e.g. something that breaks the framing)."""
        self._broadcast(data)

    def send_garbage(self, kind: str) -> None:
        """One well-framed message a client must skip without losing the stream (GARBAGE_KINDS)."""
        self._broadcast(self.garbage(kind))

    def garbage(self, kind: str) -> bytes:
        sec, usec = vp.split_time(time.time())
        with self._lock:
            tracker_ids = [i for n, i in self._sender_ids.items() if n != vp.CONTROL_SENDER]
        sid = tracker_ids[0] if tracker_ids else 0
        t = self._type_ids
        if kind == "unknown_type":
            return vp.encode_message(t["vrpn_Analog Channel"], sid, bytes(self._rng.randrange(256) for _ in range(40)),
                                     sec, usec)
        if kind == "undescribed":
            return vp.encode_message(999, 777, vp.encode_pos_quat(vp.PosQuat(0, (9, 9, 9), (0, 0, 0, 1))), sec, usec)
        if kind == "short_pos_quat":
            return vp.encode_message(t[vp.TYPE_POS_QUAT], sid, b"\x00" * 40, sec, usec)
        if kind == "long_velocity":
            return vp.encode_message(t[vp.TYPE_VELOCITY], sid, b"\x00" * 80, sec, usec)
        if kind == "bad_description":
            return vp.encode_message(vp.SENDER_DESCRIPTION, 55, b"\x00\x00\x10\x00abc\x00", sec, usec)
        if kind == "empty_name":
            return vp.encode_message(vp.TYPE_DESCRIPTION, 56, b"\x00\x00\x00\x01\x00", sec, usec)
        if kind == "udp_description":
            return vp.encode_udp_description(4500, "127.0.0.1", sec, usec)
        if kind == "text":
            return vp.encode_message(t[vp.TYPE_TEXT], self._sender_ids[vp.CONTROL_SENDER],
                                     vp.encode_text("fake mocap: hello", vp.TEXT_WARNING), sec, usec)
        raise ValueError("unknown garbage kind %r (one of %s)" % (kind, ", ".join(GARBAGE_KINDS)))

    # -- internals -------------------------------------------------------------------------------
    def _descriptions(self) -> bytes:
        with self._lock:
            senders = sorted(self._sender_ids.items(), key=lambda kv: kv[1])
        out = [vp.encode_sender_description(sid, name) for name, sid in senders]
        out += [vp.encode_type_description(tid, name) for name, tid in self._type_ids.items()]
        return b"".join(out)

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            ls = self._listener
            if ls is None:
                return
            try:
                sock, addr = ls.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            threading.Thread(target=self._handshake, args=(sock, addr), daemon=True).start()

    def _handshake(self, sock: socket.socket, addr) -> None:
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, CLIENT_SEND_BUFFER_BYTES)
            sock.sendall(vp.encode_cookie(self.version))
            sock.settimeout(3.0)
            cookie = b""
            while len(cookie) < vp.COOKIE_SIZE:
                chunk = sock.recv(vp.COOKIE_SIZE - len(cookie))
                if not chunk:
                    raise ConnectionResetError("client left during the handshake")
                cookie += chunk
            vp.decode_cookie(cookie)
        except (OSError, vp.VrpnProtocolError):
            self.rejected_cookies += 1
            sock.close()
            return
        peer = _Peer(sock, addr)
        try:
            sock.settimeout(2.0)
            sock.sendall(self._descriptions())
            sock.setblocking(False)         # from now on every send is the backlog's, and never waits
        except OSError:
            sock.close()
            return
        with self._lock:
            self._peers.append(peer)
            self.accepted += 1
        self._drain(peer)

    def _drain(self, peer: _Peer) -> None:
        """Read (and discard) what the client sends, to notice when it leaves; flush its backlog as its
        socket takes it."""
        sock = peer.sock
        while peer.alive and not self._stop.is_set():
            with peer.lock:
                waiting = bool(peer.backlog)
            try:
                readable, writable, _ = select.select([sock], [sock] if waiting else [], [], _PEER_POLL_S)
                if readable and not sock.recv(4096):
                    break
            except (BlockingIOError, InterruptedError):
                continue
            except (OSError, ValueError):       # closed under us
                break
            if writable:
                with peer.lock:
                    why = peer.flush(time.monotonic())
                if why is not None:
                    self._drop(peer, why)
                    return
        self._remove(peer)

    def _drop(self, peer: _Peer, why: str) -> None:
        if why.startswith("too slow"):
            self.slow_clients += 1
            LOG.warning("VRPN client %s:%d disconnected, %s (the others do not wait for it; it may reconnect)",
                        peer.addr[0], peer.addr[1], why)
        self._remove(peer)

    def _remove(self, peer: _Peer) -> None:
        with self._lock:
            if peer in self._peers:
                self._peers.remove(peer)
        peer.alive = False
        try:
            peer.sock.close()
        except OSError:
            pass

    def _broadcast(self, data: bytes) -> None:
        """``data`` to every client, without waiting for any: what a socket does not take now waits in
        that client's backlog (a client too far behind is disconnected)."""
        with self._lock:
            peers = list(self._peers)
        pieces = [data]
        if self.fragment:
            pieces, pos = [], 0
            while pos < len(data):
                n = self._rng.randint(1, 61)
                pieces.append(data[pos:pos + n])
                pos += n
        now = time.monotonic()
        for p in peers:
            with p.lock:
                p.queue(pieces, now)
                why = p.flush(now)
            if why is not None:
                self._drop(p, why)

    def _pose_of(self, index: int, name: str, t: float) -> Tuple[Sequence[float], Sequence[float]]:
        if self.pose_fn is not None:
            return self.pose_fn(name, t)
        return self._poses.get(name, ((float(index), 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))

    def frame(self, t: float) -> Tuple[bytes, int]:
        """The bytes of one report cycle at Unix time t, and how many poses they hold."""
        sec, usec = vp.split_time(t)
        pq = self._type_ids[vp.TYPE_POS_QUAT]
        vel = self._type_ids[vp.TYPE_VELOCITY]
        with self._lock:
            items = [(n, sid) for n, sid in self._sender_ids.items()
                     if n != vp.CONTROL_SENDER and n not in self._hidden]
            velocities = dict(self._velocities)
        out = []
        for i, (name, sid) in enumerate(items):
            pos, quat = self._pose_of(i, name, t)
            if self.y_up:
                pos, quat = z_up_to_y_up_vector(pos), z_up_to_y_up_quaternion(quat)
            self._seq += 1
            out.append(vp.encode_message(pq, sid, vp.encode_pos_quat(vp.PosQuat(0, vp.vec3(pos), vp.quat(quat))),
                                         sec, usec, self._seq))
            if self.velocity:
                v = velocities.get(name, vp.Velocity(0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 0.01))
                if self.y_up:
                    v = vp.Velocity(0, z_up_to_y_up_vector(v.linear), z_up_to_y_up_quaternion(v.rotation), v.dt)
                out.append(vp.encode_message(vel, sid, vp.encode_velocity(v), sec, usec, self._seq))
        return b"".join(out), len(items)

    def send_poses(self, poses: Sequence[Tuple[str, Sequence[float], Sequence[float]]], t: float) -> int:
        """One report cycle of the given (name, position, quaternion xyzw) poses, stamped Unix time t.

        For an owner that reports as its own source delivers (``stream=False``); trackers not yet
        known are added. Returns how many poses went to how many clients.
        """
        for name, _, _ in poses:
            if name not in self._sender_ids:
                self.add_tracker(name)
        sec, usec = vp.split_time(t)
        pq = self._type_ids[vp.TYPE_POS_QUAT]
        out = []
        for name, pos, quat in poses:
            if self.y_up:
                pos, quat = z_up_to_y_up_vector(pos), z_up_to_y_up_quaternion(quat)
            self._seq += 1
            out.append(vp.encode_message(pq, self._sender_ids[name], vp.encode_pos_quat(
                vp.PosQuat(0, vp.vec3(pos), vp.quat(quat))), sec, usec, self._seq))
        clients = self.client_count()
        if out and clients:
            self._broadcast(b"".join(out))
            self.poses_sent += len(out) * clients
        return len(out) * clients

    def _stream_loop(self) -> None:
        period = 1.0 / self.rate
        next_t = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if now < next_t:
                self._stop.wait(next_t - now)
                continue
            next_t += period
            if next_t < now - 1.0:             # fell far behind: do not burst to catch up
                next_t = now + period
            t = time.time()
            data, n = self.frame(t)
            if data and self.client_count():
                self._broadcast(data)
                self.poses_sent += n * self.client_count()
                self.streamed.append(vp.split_time(t))


# -- standalone fake mocap ----------------------------------------------------------------------
def circle_pose(index: int, radius: float = 0.5, period: float = 10.0, height: float = 1.0) -> PoseFn:
    """Tracker ``index`` flying a horizontal circle, nose along the direction of flight (Z-up)."""

    def fn(name: str, t: float):
        a = 2 * math.pi * t / period + index * 2 * math.pi / 7
        pos = (radius * math.cos(a) + index, radius * math.sin(a), height)
        yaw = a + math.pi / 2
        return pos, (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))

    return fn


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m crazyflie_driver.mocap.vrpn_server",
                                 description="Fake VRPN motion capture: streams tracker poses over TCP.")
    ap.add_argument("--tracker", action="append", help="tracker name (repeat for several; default cf1)")
    ap.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    ap.add_argument("--port", type=int, default=vp.DEFAULT_PORT, help="TCP port (default 3883)")
    ap.add_argument("--rate", type=float, default=100.0, help="reports per second per tracker")
    ap.add_argument("--motion", choices=("static", "circle"), default="static",
                    help="static: tracker i rests at (i, 0, 0); circle: 0.5 m circles at 1 m height")
    ap.add_argument("--position", type=float, nargs=3, metavar=("X", "Y", "Z"),
                    help="static position (Z-up, metres) for every tracker")
    ap.add_argument("--yaw", type=float, default=0.0, help="static yaw in degrees (Z-up)")
    ap.add_argument("--velocity", action="store_true", help="also send vrpn_Tracker Velocity")
    ap.add_argument("--y-up", action="store_true", help="stream in OptiTrack's Y-up frame")
    ap.add_argument("--drop-every", type=float, default=0.0, help="drop all connections every S seconds")
    ap.add_argument("--garbage-every", type=float, default=0.0, help="send a malformed message every S seconds")
    ap.add_argument("--duration", type=float, default=0.0, help="stop after S seconds (0: run until Ctrl-C)")
    args = ap.parse_args(argv)
    names = args.tracker or ["cf1"]
    pose_fn = None
    if args.motion == "circle":
        fns = {n: circle_pose(i) for i, n in enumerate(names)}
        pose_fn = lambda name, t: fns[name](name, t)  # noqa: E731
    server = VrpnTestServer(names, host=args.host, port=args.port, rate=args.rate,
                            velocity=args.velocity, y_up=args.y_up, pose_fn=pose_fn)
    if args.position is not None:
        half = math.radians(args.yaw) / 2
        for n in names:
            server.set_pose(n, args.position, (0.0, 0.0, math.sin(half), math.cos(half)))
    try:
        host, port = server.start()
    except OSError as e:
        print("vrpn_test_server: cannot listen on %s:%d: %s" % (args.host, args.port, e.strerror or e),
              file=sys.stderr)
        return 1
    print("fake VRPN server on %s:%d, trackers %s, %.0f Hz%s" % (host, port, ", ".join(names), args.rate,
                                                                 ", Y-up" if args.y_up else ""), flush=True)
    start = time.monotonic()
    next_drop = start + args.drop_every if args.drop_every > 0 else float("inf")
    next_garbage = start + args.garbage_every if args.garbage_every > 0 else float("inf")
    kinds = list(GARBAGE_KINDS)
    try:
        while args.duration <= 0 or time.monotonic() - start < args.duration:
            time.sleep(0.05)
            now = time.monotonic()
            if now >= next_drop:
                print("dropping %d connection(s)" % server.client_count(), flush=True)
                server.drop_clients()
                next_drop = now + args.drop_every
            if now >= next_garbage:
                server.send_garbage(kinds[0])
                kinds.append(kinds.pop(0))
                next_garbage = now + args.garbage_every
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
