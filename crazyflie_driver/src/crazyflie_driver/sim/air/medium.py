"""The air between Crazyradio dongles and simulated Crazyflies.

``LocalMedium`` lives in the process that owns the world: a registry of ``SimulatedCrazyflie`` by
(channel, datarate, address), per-dongle fault injection (packet loss and ack loss in percent of
round trips, added latency, unplug) and a per-Crazyflie RSSI model. ``RemoteMedium`` is the same
interface for another process: it forwards every call to a world server (``sim.world_server``) over
loopback TCP, one connection per dongle (as real dongles, they transmit at the same time) and one for
control calls, with a small binary framing (see ``sim.air.world_framing``).
"""
from __future__ import annotations

import json
import os
import random
import socket
import threading
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

from crazyflie_driver.errors import CrazyflieError, RadioMediumGone
from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
from crazyflie_driver.sim.air import world_framing as framing
from crazyflie_driver.sim.air.usb_descriptors import MODELS

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 19840
ENV_ADDRESS = "CRAZYFLIE_SIM_ADDRESS"
POWER_DETECTOR_DBM = -64.0

Key = Tuple[int, int, bytes]


@dataclass
class AirReply:
    acked: bool
    payload: bytes = b""
    retries: int = 0
    power_detector: bool = True
    unplugged: bool = False
    latency_s: float = 0.0


@dataclass
class DongleFaults:
    packet_loss: float = 0.0     # percent of round trips where the Crazyflie never hears the packet
    ack_loss: float = 0.0        # percent where it hears (and acts on) it but the ack is lost
    latency_s: float = 0.0
    unplugged: bool = False


@dataclass
class RssiModel:
    mean_dbm: float = -40.0
    noise_db: float = 2.0


class WorldNotRunning(RadioMediumGone):
    """No world server answers at the configured address."""


def parse_address(text: Optional[str] = None) -> Tuple[str, int]:
    """``host:port`` (default from CRAZYFLIE_SIM_ADDRESS, else 127.0.0.1:19840); loopback only."""
    if text is None:
        text = os.environ.get(ENV_ADDRESS, "") or "%s:%d" % (DEFAULT_HOST, DEFAULT_PORT)
    host, sep, port_text = str(text).strip().rpartition(":")
    if not sep:
        host, port_text = port_text, str(DEFAULT_PORT)
    host = host or DEFAULT_HOST
    if host == "localhost":
        host = DEFAULT_HOST
    if not host.startswith("127."):
        raise ValueError("simulated world address %r: only loopback (127.x.x.x) is allowed" % (text,))
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError("simulated world address %r: port %r is not a number" % (text, port_text)) from None
    if not 0 <= port <= 65535:
        raise ValueError("simulated world address %r: port out of range" % (text,))
    return host, port


def key_of(uri: str) -> Key:
    """(channel, datarate, address) of a radio URI string."""
    from crazyflie_driver.crtp.uri import parse_uri
    u = parse_uri(uri)
    return (u.channel, u.datarate, bytes(u.address))


class LocalMedium:
    """The air in this process. Thread safe: every dongle may transmit from its own thread."""

    def __init__(self, dongles: int = 1, seed: Optional[int] = None, dongle_model: str = "PA") -> None:
        if dongles < 0:
            raise ValueError("dongles must be >= 0, got %d" % dongles)
        if dongle_model not in MODELS:
            raise ValueError("unknown Crazyradio model %r, use one of %s" % (dongle_model, ", ".join(sorted(MODELS))))
        self._dongle_model = dongle_model
        self._usb: List[Any] = []        # Crazyflies on a USB cable, usb://0 first
        self._lock = threading.Lock()
        self._rng = random.Random(seed)
        self._faults: List[DongleFaults] = [DongleFaults() for _ in range(dongles)]
        self._crazyflies: Dict[Key, Any] = {}
        self._rssi: Dict[Key, RssiModel] = {}
        self.round_trips = 0

    # --- registry --------------------------------------------------------------------------
    def add_crazyflie(self, crazyflie, channel: int, datarate: int, rssi: Optional[RssiModel] = None) -> Key:
        key = (int(channel), int(datarate), bytes(crazyflie.address))
        with self._lock:
            if key in self._crazyflies:
                raise ValueError("a simulated Crazyflie already listens on channel %d, rate %d, address %s"
                                 % (key[0], key[1], key[2].hex().upper()))
            self._crazyflies[key] = crazyflie
            self._rssi[key] = rssi or RssiModel(mean_dbm=crazyflie.rssi_dbm)
        bind = getattr(crazyflie, "bind_radio", None)
        if bind is not None:
            bind(key[0], key[1], lambda ch, dr, addr: self._move(crazyflie, (int(ch), int(dr), bytes(addr))))
        return key

    def _move(self, crazyflie, new: Key) -> bool:
        """A Crazyflie booted with other radio settings (its EEPROM changed): it now listens on
        ``new``; False, and nothing moved, when another Crazyflie already listens there."""
        with self._lock:
            old = next((k for k, c in self._crazyflies.items() if c is crazyflie), None)
            if old is None or (new in self._crazyflies and self._crazyflies[new] is not crazyflie):
                return False
            del self._crazyflies[old]
            self._crazyflies[new] = crazyflie
            self._rssi[new] = self._rssi.pop(old)
        return True

    def remove_crazyflie(self, channel: int, datarate: int, address: bytes):
        key = (int(channel), int(datarate), bytes(address))
        with self._lock:
            self._rssi.pop(key, None)
            return self._crazyflies.pop(key, None)

    def crazyflie(self, channel: int, datarate: int, address: bytes):
        return self._crazyflies.get((int(channel), int(datarate), bytes(address)))

    def crazyflies(self) -> Dict[Key, Any]:
        with self._lock:
            return dict(self._crazyflies)

    def set_rssi(self, channel: int, datarate: int, address: bytes, mean_dbm: float,
                 noise_db: Optional[float] = None) -> None:
        key = (int(channel), int(datarate), bytes(address))
        with self._lock:
            if key not in self._crazyflies:
                raise KeyError("no simulated Crazyflie on %r" % (key,))
            model = self._rssi[key]
            model.mean_dbm = float(mean_dbm)
            if noise_db is not None:
                model.noise_db = float(noise_db)

    # --- dongles -----------------------------------------------------------------------------
    def dongle_count(self) -> int:
        return len(self._faults)

    def dongle_model(self) -> str:
        """The Crazyradio model plugged in (``usb_descriptors.MODELS``): "PA" or "2.0" (inline mode)."""
        return self._dongle_model

    # --- Crazyflies on a USB cable -------------------------------------------------------------------
    def plug_usb(self, crazyflie) -> int:
        """Put a simulated Crazyflie on a USB cable to the host; returns its number N (``usb://N``)."""
        with self._lock:
            self._usb.append(crazyflie)
            return len(self._usb) - 1

    def usb_count(self) -> int:
        return len(self._usb)

    def usb_send(self, index: int, data: bytes) -> bool:
        """One CRTP packet down the cable to its STM (no nRF, no radio faults); False when it is off."""
        cf = self._usb[index]
        if not cf.powered:
            return False
        cf.handle_crtp(bytes(data))
        return True

    def usb_receive(self, index: int) -> Optional[bytes]:
        """The next packet the Crazyflie on cable ``index`` sends up, None when it has none."""
        return self._usb[index].pop_outgoing(packet_link=True)

    def set_dongle_count(self, n: int) -> None:
        with self._lock:
            while len(self._faults) < n:
                self._faults.append(DongleFaults())
            del self._faults[n:]

    def set_dongle_faults(self, dongle: int, packet_loss: Optional[float] = None,
                          ack_loss: Optional[float] = None, latency_s: Optional[float] = None,
                          unplugged: Optional[bool] = None) -> None:
        with self._lock:
            if not 0 <= dongle < len(self._faults):
                raise ValueError("no simulated dongle %d (there are %d)" % (dongle, len(self._faults)))
            f = self._faults[dongle]
            if packet_loss is not None:
                f.packet_loss = _percent("packet_loss", packet_loss)
            if ack_loss is not None:
                f.ack_loss = _percent("ack_loss", ack_loss)
            if latency_s is not None:
                if latency_s < 0:
                    raise ValueError("latency_s must be >= 0, got %r" % (latency_s,))
                f.latency_s = float(latency_s)
            if unplugged is not None:
                f.unplugged = bool(unplugged)

    def dongle_faults(self, dongle: int) -> DongleFaults:
        with self._lock:
            f = self._faults[dongle]
            return DongleFaults(f.packet_loss, f.ack_loss, f.latency_s, f.unplugged)

    # --- the air -----------------------------------------------------------------------------
    def transmit(self, dongle: int, channel: int, datarate: int, address: bytes,
                 data: bytes, ack_enabled: bool = True, arc: int = 3) -> AirReply:
        key = (channel, datarate, address if type(address) is bytes else bytes(address))
        with self._lock:
            self.round_trips += 1
            if not 0 <= dongle < len(self._faults):
                return AirReply(acked=False, power_detector=False, unplugged=True)
            f = self._faults[dongle]
            if f.unplugged:
                return AirReply(acked=False, power_detector=False, unplugged=True, latency_s=f.latency_s)
            if key[2] == BROADCAST_ADDRESS:
                listeners = [c for (ch, dr, _), c in self._crazyflies.items() if ch == channel and dr == datarate]
                heard = [c for c in listeners if not (f.packet_loss > 0 and self._rng.random() * 100.0 < f.packet_loss)]
                latency = f.latency_s
                broadcast = True
            else:
                broadcast = False
            cf = self._crazyflies.get(key)
            lost = f.packet_loss > 0 and self._rng.random() * 100.0 < f.packet_loss
            ack_lost = f.ack_loss > 0 and self._rng.random() * 100.0 < f.ack_loss
            rssi_dbm = 0.0
            if cf is not None:
                model = self._rssi[key]
                rssi_dbm = round(model.mean_dbm + (self._rng.gauss(0.0, model.noise_db) if model.noise_db else 0.0))
                rssi_dbm = 0.0 if rssi_dbm >= 0.0 else (-127.0 if rssi_dbm <= -127.0 else rssi_dbm)   # 0..-127
            latency = f.latency_s
        if broadcast:            # every Crazyflie on this channel and data rate takes it; none acks
            for c in heard:
                c.handle_broadcast(data)
            return _miss(arc, latency)
        if cf is None or lost or not cf.radio_on:
            return _miss(arc, latency)
        cf.rssi_dbm = rssi_dbm
        payload = cf.handle_radio_packet(data, ack_enabled)
        if not ack_enabled or ack_lost:
            return _miss(arc, latency)
        return AirReply(True, payload, 0, rssi_dbm > POWER_DETECTOR_DBM, False, latency)


def _miss(arc: int, latency_s: float) -> AirReply:
    """No ack: the dongle gave up after its ``arc`` retransmissions."""
    return AirReply(acked=False, retries=arc & 0x0F, power_detector=False, latency_s=latency_s)


def _percent(name: str, value: float) -> float:
    v = float(value)
    if not 0.0 <= v <= 100.0:
        raise ValueError("%s must be a percentage 0..100, got %r" % (name, value))
    return v


class _Lane:
    """One connection to the world server and the lock that keeps its requests one at a time."""

    __slots__ = ("lock", "conn")

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.conn: Optional[framing.Connection] = None


class RemoteMedium:
    """The ``Medium`` of a world server in another process (loopback TCP).

    Each dongle's radio packets have a connection of their own (control calls share one more), one
    request at a time on each: real Crazyradios transmit at the same time, so a packet of one fake
    dongle must not wait for another dongle's round trip (docs/simulation.md, "Crazyradio timing").
    """

    def __init__(self, host: Optional[str] = None, port: Optional[int] = None, timeout: float = 5.0) -> None:
        if host is not None and port is None and ":" in host:
            self.host, self.port = parse_address(host)
        elif host is None and port is None:
            self.host, self.port = parse_address(None)
        else:
            port = DEFAULT_PORT if port is None else port
            self.host, self.port = parse_address("%s:%d" % (host or DEFAULT_HOST, port))
        self.timeout = float(timeout)
        self._lock = threading.Lock()       # guards ``_lanes`` (the dict), not the requests
        self._lanes: Dict[Optional[int], _Lane] = {}     # by dongle; None: control calls
        self.speed = 1.0
        """The world's speed [world s / wall s] its latest radio reply carried (1.0 before the first)."""

    @property
    def address(self) -> str:
        return "%s:%d" % (self.host, self.port)

    def _connect(self) -> framing.Connection:
        try:
            sock = socket.create_connection((self.host, self.port), timeout=self.timeout)
        except OSError as e:
            raise WorldNotRunning("no simulated world at %s (start one with: rosrun crazyflie_driver "
                                  "crazyflie_world_server --uri radio://0/80/2M/E7E7E7E7E7): %s"
                                  % (self.address, e.strerror or e)) from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return framing.Connection(sock)

    def _lane(self, key: Optional[int]) -> _Lane:
        lane = self._lanes.get(key)
        if lane is None:
            with self._lock:
                lane = self._lanes.setdefault(key, _Lane())
        return lane

    def _request(self, op: int, body: bytes, lane_key: Optional[int] = None) -> Tuple[int, bytes]:
        """One request/response on the connection of ``lane_key`` (a dongle, None for control calls);
        reconnects once if that connection dropped since its last call."""
        lane = self._lane(lane_key)
        with lane.lock:
            for attempt in (0, 1):
                conn = lane.conn
                fresh = conn is None
                if conn is None:
                    conn = lane.conn = self._connect()
                try:
                    conn.send(op, body)
                    return conn.receive()
                except (OSError, EOFError) as e:
                    conn.close()
                    lane.conn = None
                    if fresh or attempt:
                        raise WorldNotRunning("simulated world at %s went away (%s)" % (self.address, e)) from None
            raise AssertionError("unreachable")

    def close(self) -> None:
        with self._lock:
            lanes = list(self._lanes.values())
        for lane in lanes:
            with lane.lock:
                if lane.conn is not None:
                    lane.conn.close()
                    lane.conn = None

    # --- Medium ------------------------------------------------------------------------------
    def transmit(self, dongle: int, channel: int, datarate: int, address: bytes,
                 data: bytes, ack_enabled: bool = True, arc: int = 3) -> AirReply:
        request = framing.encode_transmit(dongle, channel, datarate, address, data, ack_enabled, arc)
        status, body = self._request(framing.OP_TRANSMIT, request, dongle)
        if status != framing.STATUS_OK:
            raise CrazyflieError("world server refused a radio packet: %s" % body.decode("utf-8", "replace"))
        reply, self.speed = framing.decode_air_reply(body, AirReply)
        return reply

    def control(self, op: str, **args) -> Any:
        """A control call on the world server (see ``WorldServer.control``); raises its error text."""
        status, body = self._request(framing.OP_CONTROL, json.dumps({"op": op, "args": args}).encode("utf-8"))
        result = json.loads(body.decode("utf-8")) if body else None
        if status != framing.STATUS_OK:
            raise CrazyflieError("simulated world: %s" % (result,))
        return result

    def set_dongle_faults(self, dongle: int, packet_loss: Optional[float] = None,
                          ack_loss: Optional[float] = None, latency_s: Optional[float] = None,
                          unplugged: Optional[bool] = None) -> None:
        self.control("set_dongle_faults", dongle=dongle, packet_loss=packet_loss, ack_loss=ack_loss,
                     latency_s=latency_s, unplugged=unplugged)

    def dongle_count(self) -> int:
        return int(self.control("dongle_count"))

    def dongle_model(self) -> str:
        return str(self.control("dongle_model"))

    def usb_count(self) -> int:
        return int(self.control("usb_count"))

    def usb_send(self, index: int, data: bytes) -> bool:
        return bool(self.control("usb_send", index=index, data=bytes(data).hex()))

    def usb_receive(self, index: int) -> Optional[bytes]:
        text = self.control("usb_receive", index=index)
        return None if text is None else bytes.fromhex(text)

    def dongle_faults(self, dongle: int) -> DongleFaults:
        row = self.control("dongle_faults", dongle=dongle)[0]
        return DongleFaults(row["packet_loss"], row["ack_loss"], row["latency_s"], row["unplugged"])

    # convenience wrappers used by tests and tools
    def add_crazyflie(self, uri: str, name: Optional[str] = None, position=(0.0, 0.0, 0.0),
                      firmware: str = "current") -> Dict[str, Any]:
        return self.control("add_crazyflie", uri=uri, name=name, position=list(position), firmware=firmware)

    def remove_crazyflie(self, uri: str) -> None:
        self.control("remove_crazyflie", uri=uri)

    def power(self, uri: str, on: bool) -> None:
        self.control("power", uri=uri, on=bool(on))

    def crazyflie_state(self, uri: str) -> Dict[str, Any]:
        return self.control("state", uri=uri)

    def list_crazyflies(self) -> List[Dict[str, Any]]:
        return self.control("list")

    def set_rssi(self, uri: str, mean_dbm: float, noise_db: Optional[float] = None) -> None:
        self.control("set_rssi", uri=uri, mean_dbm=mean_dbm, noise_db=noise_db)

    def ping(self) -> float:
        """World time of the server (a cheap liveness check)."""
        return float(self.control("time"))

