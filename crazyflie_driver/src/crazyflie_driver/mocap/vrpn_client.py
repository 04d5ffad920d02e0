"""VRPN tracker client: a session that turns received bytes into tracker reports, and a
connection thread that keeps a TCP connection to the server alive.

Transport: the client opens TCP to server:3883 itself ("way A" in VRPN terms, what a C++ client
does for ``Tracker0@tcp://host:3883``). The server then marks the connection TCP-only and sends
every message, poses included, over that one stream, so no UDP socket and no UDP lob are
needed, and nothing has to be sent after the 24-byte cookie: the server sends every sender's
messages to every client without registration.

Ids are per connection: the server describes its senders (-1) and types (-2), and data messages
are dispatched by (type name, sender name). A message whose ids were not described, a type we do
not use, or a payload of the wrong size is skipped; only a length field that cannot be right
(the stream cannot be cut into messages any more) resets the connection.
"""
from __future__ import annotations

import logging
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple

from crazyflie_driver.clock import WALL
from crazyflie_driver.mocap import vrpn_protocol as vp

LogFn = Callable[[int, str], None]
_logger = logging.getLogger("crazyflie_driver.mocap.vrpn")


def _default_log(level: int, text: str) -> None:
    _logger.log(level, text)


@dataclass(frozen=True)
class PoseReport:
    """One ``vrpn_Tracker Pos_Quat`` as received: raw VRPN values, no axis change."""

    tracker: str                    # VRPN sender name, as the server spells it
    sensor: int
    position: vp.Vec3               # metres, mocap world frame
    orientation: vp.Quat            # (x, y, z, w)
    server_sec: int                 # header time (server clock)
    server_usec: int
    receive_time: float             # client clock (see VrpnSession) when the bytes were read


@dataclass(frozen=True)
class TwistReport:
    """One ``vrpn_Tracker Velocity``: linear velocity and the rotation ``rotation`` over ``dt`` s."""

    tracker: str
    sensor: int
    linear: vp.Vec3
    rotation: vp.Quat
    dt: float
    server_sec: int
    server_usec: int
    receive_time: float


@dataclass
class SessionStats:
    messages: int = 0
    poses: int = 0
    velocities: int = 0
    texts: int = 0
    undescribed: int = 0            # ids the server had not described (dropped, as VRPN does)
    ignored: int = 0                # described types we do not use, or filtered trackers
    malformed: int = 0              # wrong payload size, bad description
    callback_errors: int = 0
    descriptions: int = 0


class VrpnSession:
    """Protocol state of one connection (id maps, stream buffer). No sockets: feed it bytes.

    Callbacks run in the thread that calls :meth:`feed`; an exception in a callback is logged
    and counted, never propagated. ``trackers``: only these sender names are reported (None:
    every sender except "VRPN Control").
    """

    def __init__(self, trackers: Optional[Iterable[str]] = None,
                 on_pose: Optional[Callable[[PoseReport], None]] = None,
                 on_twist: Optional[Callable[[TwistReport], None]] = None,
                 on_tracker: Optional[Callable[[str], None]] = None,
                 on_text: Optional[Callable[[str, int, str], None]] = None,
                 log: LogFn = _default_log) -> None:
        self.wanted = None if trackers is None else frozenset(trackers)
        self.on_pose = on_pose
        self.on_twist = on_twist
        self.on_tracker = on_tracker
        self.on_text = on_text
        self._log = log
        self.stats = SessionStats()
        self.senders: Dict[int, str] = {}
        self.types: Dict[int, str] = {}
        self._reader = vp.MessageReader()
        self._handlers: Dict[int, Callable[[vp.Message, str, float], None]] = {}
        self._tracker_ok: Dict[int, bool] = {}    # sender id -> is a tracker we report
        self._seen_trackers: List[str] = []
        self._warned_at: Dict[str, float] = {}

    # -- state ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget ids and buffered bytes (a new connection starts from nothing)."""
        self.senders.clear()
        self.types.clear()
        self._handlers.clear()
        self._tracker_ok.clear()
        self._reader.clear()

    def trackers(self) -> List[str]:
        """Tracker names described by the server so far (all connections), in order of arrival."""
        return list(self._seen_trackers)

    # -- input ---------------------------------------------------------------------------
    def feed(self, data: bytes, receive_time: float) -> int:
        """Process bytes read from the TCP stream; returns the number of whole messages handled.
        Raises vp.VrpnFramingError when the stream cannot be cut into messages any more."""
        msgs = self._reader.feed(data)
        for m in msgs:
            self.handle(m, receive_time)
        return len(msgs)

    def feed_datagram(self, data: bytes, receive_time: float) -> int:
        """Process one UDP datagram (whole messages only); a broken datagram is dropped."""
        try:
            msgs = list(vp.split_datagram(data))
        except vp.VrpnFramingError as e:
            self.stats.malformed += 1
            self._warn("datagram", "VRPN: dropped a broken datagram (%s)" % e)
            return 0
        for m in msgs:
            self.handle(m, receive_time)
        return len(msgs)

    def handle(self, msg: vp.Message, receive_time: float) -> None:
        self.stats.messages += 1
        t = msg.type_id
        if t >= 0:
            handler = self._handlers.get(t)
            if handler is None:
                if t in self.types:
                    self.stats.ignored += 1
                else:
                    self.stats.undescribed += 1
                return
            name = self.senders.get(msg.sender_id)
            if name is None:
                self.stats.undescribed += 1
                return
            handler(msg, name, receive_time)
        elif t == vp.SENDER_DESCRIPTION:
            self._describe_sender(msg)
        elif t == vp.TYPE_DESCRIPTION:
            self._describe_type(msg)
        else:
            self.stats.ignored += 1              # UDP/log descriptions: not needed over TCP

    # -- system messages -----------------------------------------------------------------------
    def _describe_sender(self, msg: vp.Message) -> None:
        try:
            name = vp.decode_name_payload(msg.payload)
        except vp.VrpnProtocolError as e:
            self.stats.malformed += 1
            self._warn("description", "VRPN: skipped a sender description (%s)" % e)
            return
        self.stats.descriptions += 1
        self.senders[msg.sender_id] = name
        is_tracker = name != vp.CONTROL_SENDER
        self._tracker_ok[msg.sender_id] = is_tracker and (self.wanted is None or name in self.wanted)
        if is_tracker and name not in self._seen_trackers:
            self._seen_trackers.append(name)
            if self.on_tracker is not None:
                self._call(self.on_tracker, name)

    def _describe_type(self, msg: vp.Message) -> None:
        try:
            name = vp.decode_name_payload(msg.payload)
        except vp.VrpnProtocolError as e:
            self.stats.malformed += 1
            self._warn("description", "VRPN: skipped a type description (%s)" % e)
            return
        self.stats.descriptions += 1
        described = msg.sender_id           # a description's sender field is the id described
        self.types[described] = name
        handler = {vp.TYPE_POS_QUAT: self._pos_quat, vp.TYPE_VELOCITY: self._velocity,
                   vp.TYPE_TEXT: self._text}.get(name)
        if handler is None:
            self._handlers.pop(described, None)
        else:
            self._handlers[described] = handler

    # -- data messages ---------------------------------------------------------------------------
    def _decoded(self, msg: vp.Message, sender: str, decode: Callable[[bytes], Any], kind: str, noun: str) -> Any:
        """``decode(payload)`` of a data message; None, counted, from a sender that is not a tracker we
        report, or for a payload that does not decode (warned of now and then per ``kind``)."""
        if not self._tracker_ok.get(msg.sender_id, False):
            self.stats.ignored += 1
            return None
        try:
            return decode(msg.payload)
        except vp.VrpnProtocolError as e:
            self.stats.malformed += 1
            self._warn(kind, "VRPN: skipped a %s of %r (%s)" % (noun, sender, e))
            return None

    def _pos_quat(self, msg: vp.Message, sender: str, receive_time: float) -> None:
        p = self._decoded(msg, sender, vp.decode_pos_quat, "pos_quat", "pose")
        if p is None:
            return
        self.stats.poses += 1
        if self.on_pose is not None:
            self._call(self.on_pose, PoseReport(sender, p.sensor, p.position, p.orientation,
                                                msg.sec, msg.usec, receive_time))

    def _velocity(self, msg: vp.Message, sender: str, receive_time: float) -> None:
        v = self._decoded(msg, sender, vp.decode_velocity, "velocity", "velocity")
        if v is None:
            return
        self.stats.velocities += 1
        if self.on_twist is not None:
            self._call(self.on_twist, TwistReport(sender, v.sensor, v.linear, v.rotation, v.dt,
                                                  msg.sec, msg.usec, receive_time))

    def _text(self, msg: vp.Message, sender: str, receive_time: float) -> None:
        try:
            severity, _level, text = vp.decode_text(msg.payload)
        except vp.VrpnProtocolError as e:
            self.stats.malformed += 1
            self._warn("text", "VRPN: skipped a text message (%s)" % e)
            return
        self.stats.texts += 1
        if self.on_text is not None:
            self._call(self.on_text, sender, severity, text)
        else:
            level = (logging.INFO, logging.WARNING, logging.ERROR)[min(severity, 2)]
            self._log(level, "VRPN server (%s): %s" % (sender, text))

    # -- helpers ---------------------------------------------------------------------------------
    def _call(self, fn: Callable, *args) -> None:
        try:
            fn(*args)
        except Exception as e:  # a consumer's bug must not stop the stream
            self.stats.callback_errors += 1
            self._warn("callback", "VRPN: callback %s failed: %r" % (getattr(fn, "__name__", fn), e))

    def _warn(self, key: str, text: str, period: float = 5.0) -> None:
        now = time.monotonic()      # wall clock: how often a person is told
        if now >= self._warned_at.get(key, 0.0):
            self._warned_at[key] = now + period
            self._log(logging.WARNING, text)


# ------------------------------------------------------------------------------------------------
class VrpnClient:
    """Keeps one TCP connection to a VRPN server in a background thread.

    Server absent, refusing, closing or sending a broken stream: the connection is closed, the
    id maps are cleared and the client connects again after a delay that doubles from
    ``retry_min`` up to ``retry_max`` (back to ``retry_min`` after a connection that lasted
    ``stable_after`` s). It never raises out of its thread. ``clock`` stamps ``receive_time`` (the time
    staleness is judged on: ROS time in a node); the connection's timeouts and back-off are network
    matters, on the wall clock.
    """

    def __init__(self, host: str = "localhost", port: int = vp.DEFAULT_PORT,
                 trackers: Optional[Iterable[str]] = None,
                 on_pose: Optional[Callable[[PoseReport], None]] = None,
                 on_twist: Optional[Callable[[TwistReport], None]] = None,
                 on_tracker: Optional[Callable[[str], None]] = None,
                 on_text: Optional[Callable[[str, int, str], None]] = None,
                 log: LogFn = _default_log, connect_timeout: float = 3.0,
                 retry_min: float = 0.5, retry_max: float = 8.0, stable_after: float = 2.0,
                 clock: Callable[[], float] = WALL.now) -> None:
        if not 0 < int(port) < 65536:
            raise ValueError("VRPN port must be 1..65535, got %r" % (port,))
        self.host = host
        self.port = int(port)
        self.connect_timeout = connect_timeout
        self.retry_min = retry_min
        self.retry_max = retry_max
        self.stable_after = stable_after
        self.clock = clock
        self._log = log
        self.session = VrpnSession(trackers, on_pose, on_twist, on_tracker, on_text, log)
        self.state = "idle"             # idle, connecting, connected, waiting, stopped
        self.connections = 0            # successful handshakes so far
        self.failures = 0               # failed attempts and lost connections
        self.server_version = ""
        self.last_error = ""
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._sock: Optional[socket.socket] = None
        self._sock_lock = threading.Lock()
        self._thread: Optional[threading.Thread] = None

    @property
    def address(self) -> str:
        return "%s:%d" % (self.host, self.port)

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    def start(self) -> VrpnClient:
        if self._thread is not None:
            return self
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vrpn-client-%s" % self.address,
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        with self._sock_lock:
            if self._sock is not None:
                try:
                    self._sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        self.state = "stopped"

    def wait_connected(self, timeout: float) -> bool:
        return self._connected.wait(timeout)

    def __enter__(self) -> VrpnClient:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- thread --------------------------------------------------------------------------------
    def _run(self) -> None:
        delay = self.retry_min
        while not self._stop.is_set():
            self.state = "connecting"
            try:
                sock = self._open()
            except (OSError, vp.VrpnProtocolError) as e:
                self.failures += 1
                self.last_error = _describe_error(e)
                self._log(logging.WARNING, "VRPN server %s: %s (is the mocap software streaming VRPN "
                          "there?); retrying in %.2f s" % (self.address, self.last_error, delay))
                delay = self._wait(delay)
                continue
            started = time.monotonic()      # wall clock, as the back-off: a network matter
            self.connections += 1
            self._log(logging.INFO, "VRPN: connected to %s (server version %s)"
                      % (self.address, self.server_version))
            reason = self._serve(sock)
            self._connected.clear()
            self.failures += 1
            self.last_error = reason
            if self._stop.is_set():
                break
            if time.monotonic() - started >= self.stable_after:
                delay = self.retry_min
            self._log(logging.WARNING, "VRPN server %s: connection lost (%s); reconnecting in %.2f s"
                      % (self.address, reason, delay))
            delay = self._wait(delay)
        self.state = "stopped"

    def _wait(self, delay: float) -> float:
        self.state = "waiting"
        self._stop.wait(delay)
        return min(delay * 2.0, self.retry_max)

    def _open(self) -> socket.socket:
        sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
        try:
            _enable_keepalive(sock)
            sock.sendall(vp.encode_cookie(vp.CLIENT_VERSION))
            cookie = _recv_exact(sock, vp.COOKIE_SIZE, self.connect_timeout, self._stop)
            self.server_version, _mode = vp.decode_cookie(cookie)
            sock.settimeout(0.25)
        except BaseException:
            sock.close()
            raise
        with self._sock_lock:
            self._sock = sock
        return sock

    def _serve(self, sock: socket.socket) -> str:
        """Read until EOF, error or stop; returns why it ended."""
        session = self.session
        session.reset()
        self.state = "connected"
        self._connected.set()
        try:
            while not self._stop.is_set():
                try:
                    data = sock.recv(65536)
                except socket.timeout:
                    continue
                if not data:
                    return "closed by the server"
                session.feed(data, self.clock())
            return "stopped"
        except vp.VrpnFramingError as e:
            return "broken stream: %s" % e
        except OSError as e:
            return _describe_error(e)
        finally:
            with self._sock_lock:
                self._sock = None
            sock.close()


def _recv_exact(sock: socket.socket, n: int, timeout: float, stop: threading.Event) -> bytes:
    deadline = time.monotonic() + timeout
    buf = b""
    while len(buf) < n:
        left = deadline - time.monotonic()
        if left <= 0 or stop.is_set():
            raise socket.timeout("no VRPN cookie within %.1f s (got %d of %d bytes)" % (timeout, len(buf), n))
        sock.settimeout(min(left, 0.25))
        try:
            chunk = sock.recv(n - len(buf))
        except socket.timeout:
            continue
        if not chunk:
            raise ConnectionResetError("server closed the connection during the VRPN handshake")
        buf += chunk
    return buf


def _enable_keepalive(sock: socket.socket) -> None:
    """Notice a dead peer (cable pulled, host gone) within a few seconds: VRPN servers never ping."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        for opt, value in (("TCP_KEEPIDLE", 2), ("TCP_KEEPINTVL", 1), ("TCP_KEEPCNT", 3)):
            if hasattr(socket, opt):
                sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, opt), value)
    except OSError:
        pass


def _describe_error(e: BaseException) -> str:
    if isinstance(e, ConnectionRefusedError):
        return "connection refused"
    if isinstance(e, socket.timeout):
        return str(e) or "timed out"
    if isinstance(e, socket.gaierror):
        return "unknown host (%s)" % (e.strerror or e)
    if isinstance(e, OSError) and e.strerror:
        return e.strerror.lower()
    return str(e) or type(e).__name__


def parse_server(server: str, port: Optional[int] = None) -> Tuple[str, int]:
    """(host, port) from vrpn_client_ros-style ``server`` ("host", "host:port", "tcp://host:port")
    and ``port`` parameters; an explicit ``port`` wins over one inside ``server``."""
    text = str(server).strip()
    if text.startswith("tcp://"):
        text = text[len("tcp://"):]
    if "@" in text:                       # "Tracker0@host:port": the device part is not needed
        text = text.split("@", 1)[1]
    if text.count(":") == 1:
        host, tail = text.split(":")
    else:                                 # no port (or a bare IPv6 address)
        host, tail = text, ""
    if not host:
        raise ValueError("VRPN server %r has no host name" % (server,))
    if port is None:
        if tail:
            try:
                port = int(tail)
            except ValueError:
                raise ValueError("VRPN server %r: port %r is not a number" % (server, tail)) from None
        else:
            port = vp.DEFAULT_PORT
    port = int(port)
    if not 0 < port < 65536:
        raise ValueError("VRPN port must be 1..65535, got %d" % port)
    return host, port
