"""The world server: one process owning the simulated world that every tool and node shares.

``WorldServer`` owns a world (``sim.room.world.World``), the ``LocalMedium`` and one ``SimulatedCrazyflie`` per
vehicle; it serves ``RemoteMedium`` clients on loopback TCP only, without authentication (one thread per
connection, freed when the client hangs up), runs the
firmware timers from a world tick listener and, if asked, opens UDP endpoints for cflib.

CLI: ``rosrun crazyflie_driver crazyflie_world_server --uri radio://0/80/2M/E7E7E7E701 [--uri ...]``;
``--swarm FILE`` places the Crazyflies of crazyflie_server's swarm file (the script passes the reader:
this layer does not read the server's files); ``--vrpn [PORT]`` also serves the world's motion capture
as a VRPN server (``sim.room.mocap_vrpn``).
"""
from __future__ import annotations

import argparse
import json
import logging
import signal
import socket
import sys
import threading
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.sim.air import world_framing as framing
from crazyflie_driver.sim.air.faults import (
    MAX_MOCAP_LATENCY_S,
    MAX_MOCAP_NOISE_M,
    MAX_RADIO_LATENCY_S,
    MIN_MOCAP_RATE_HZ,
    ControlArgs,
    FaultError,
)
from crazyflie_driver.sim.air.medium import DEFAULT_HOST, DEFAULT_PORT, LocalMedium, key_of, parse_address
from crazyflie_driver.sim.crtp.firmware import PROFILES, SimulatedCrazyflie
from crazyflie_driver.sim.crtp.memory_port import DECKS
from crazyflie_driver.sim.onboard.stabilizer import PLATFORM_CF2, PLATFORMS
from crazyflie_driver.sim.onboard.ticks import FIRMWARE_TICK_S
from crazyflie_driver.sim.room import battery as battery_model
from crazyflie_driver.sim.room.mocap_feed import MocapEstimatorFeed
from crazyflie_driver.sim.room.pacing import Pacing, parse_pacing, start_pacing

_log = logging.getLogger(__name__)
UDP_BASE_PORT = 19850
CONTROL_OPS = ("time", "dongle_count", "list", "add_crazyflie", "remove_crazyflie", "state", "vehicle_state", "poses",
               "reboot", "set_rssi", "power", "set_dongle_faults", "dongle_faults", "set_battery",
               "set_mocap_faults", "faults", "clear_faults", "set_mocap_to_estimator",
               "dongle_model", "usb_count", "usb_send", "usb_receive")


@dataclass
class SimEntry:
    uri: str
    name: str
    key: Tuple[int, int, bytes]
    crazyflie: SimulatedCrazyflie
    udp: Any = None          # sim.udp.UdpEndpoint when UDP is on

    def describe(self) -> Dict[str, Any]:
        d = {"uri": self.uri, "name": self.name, "firmware": self.crazyflie.profile.generation}
        if self.udp is not None:
            d["udp"] = self.udp.uri
        return d


class WorldServer:
    """Serves a world's simulated Crazyflies to RemoteMedium clients (and UDP clients)."""

    def __init__(self, world, dongles: int = 1, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 seed: Optional[int] = None, udp_base_port: Optional[int] = None, dongle_model: str = "PA") -> None:
        self.world = world
        self.medium = LocalMedium(dongles, seed, dongle_model)
        self.host, self.port = parse_address("%s:%d" % (host, port))
        self.udp_base_port = udp_base_port
        self._entries: Dict[str, SimEntry] = {}
        self._crazyflies: Tuple[SimulatedCrazyflie, ...] = ()     # replaced whole: the ticking thread reads it
        self._lock = threading.RLock()
        self._listener: Optional[socket.socket] = None
        self._clients: Dict[socket.socket, threading.Thread] = {}     # connected clients and their threads
        self._threads: List[threading.Thread] = []                    # the accept thread
        self._running = threading.Event()
        self._udp_next = 0
        self.mocap = None        # the world's MocapModel where the process runs one (the sim node); faults reach it
        self._battery_set: Dict[str, float] = {}      # vehicle -> charge a fault set it to
        self._plug_changed_at: Dict[int, float] = {}  # dongle -> world time [s] it was last unplugged or plugged in
        self._mocap_seed = seed
        self.mocap_feed = MocapEstimatorFeed(self._feed_estimator)
        world.add_tick_listener(self._tick, FIRMWARE_TICK_S)

    # --- Crazyflies --------------------------------------------------------------------------
    def add_crazyflie(self, uri: str, name: Optional[str] = None, position: Sequence[float] = (0.0, 0.0, 0.0),
                      firmware: str = "current", yaw: float = 0.0, mocap_to_estimator: bool = False,
                      platform: str = PLATFORM_CF2, decks: Sequence[str] = ()) -> SimulatedCrazyflie:
        """A simulated Crazyflie on ``uri``; ``mocap_to_estimator`` switches on the simulator extension
        that feeds the world's motion capture straight into its estimator (``set_mocap_to_estimator``);
        ``decks``: board names of the decks plugged in (their one-wire memories identify them)."""
        if firmware not in PROFILES:
            raise ValueError("unknown firmware %r for %s (choose one of: %s)" % (firmware, uri, ", ".join(PROFILES)))
        key = key_of(uri)
        pos = tuple(float(v) for v in position)
        if len(pos) != 3:
            raise ValueError("position of %s must have 3 numbers, got %r" % (uri, position))
        with self._lock:
            if self.medium.crazyflie(*key) is not None:
                raise ValueError("a simulated Crazyflie already answers on %s" % uri)
            name = name or "cf%d" % (len(self._entries) + 1)
            if name in self._entries:
                raise ValueError("a simulated Crazyflie is already called %r" % name)
            extra = {"platform": platform} if platform != PLATFORM_CF2 else {}
            vehicle = self.world.add_vehicle(name, position=pos, yaw=float(yaw), firmware=firmware, **extra)
            try:
                cf = SimulatedCrazyflie(key[2], vehicle, firmware=firmware, auto_arm=getattr(vehicle, "auto_arm", True),
                                        decks=tuple(decks))
            except ValueError:
                self.world.remove_vehicle(name)
                raise
            self.medium.add_crazyflie(cf, key[0], key[1])
            entry = SimEntry(uri, name, key, cf)
            if self.udp_base_port is not None:
                from crazyflie_driver.sim.air.udp import UdpEndpoint
                port = self.udp_base_port + self._udp_next if self.udp_base_port else 0
                self._udp_next += 1
                entry.udp = UdpEndpoint(cf, port=port)
                entry.udp.start()
            self._entries[name] = entry
            self._crazyflies = tuple(e.crazyflie for e in self._entries.values())
            if mocap_to_estimator:
                self.set_mocap_to_estimator(name, True)
            return cf

    def remove_crazyflie(self, uri_or_name: str) -> None:
        with self._lock:
            entry = self._find(uri_or_name)
            cf = entry.crazyflie              # where it listens now (its EEPROM may have moved it)
            self.medium.remove_crazyflie(cf.radio_channel, cf.radio_datarate, cf.address)
            if entry.udp is not None:
                entry.udp.stop()
            del self._entries[entry.name]
            self._crazyflies = tuple(e.crazyflie for e in self._entries.values())
            self.mocap_feed.set(entry.name, False)
            try:
                self.world.remove_vehicle(entry.name)
            except Exception:
                _log.exception("world.remove_vehicle(%s) failed", entry.name)

    def _find(self, uri_or_name: str) -> SimEntry:
        entry = self._entries.get(uri_or_name)
        if entry is not None:
            return entry
        try:
            key = key_of(uri_or_name)
        except CrazyflieError:
            raise KeyError("no simulated Crazyflie called %r" % (uri_or_name,)) from None
        for entry in self._entries.values():
            if entry.key == key:
                return entry
        raise KeyError("no simulated Crazyflie on %s" % (uri_or_name,))

    def crazyflie(self, uri_or_name: str) -> SimulatedCrazyflie:
        with self._lock:
            return self._find(uri_or_name).crazyflie

    def entries(self) -> List[SimEntry]:
        with self._lock:
            return list(self._entries.values())

    # --- the mocap-into-estimator extension ----------------------------------------------------
    def use_mocap(self, model) -> None:
        """Feed switched-on estimators from ``model`` (a ``MocapModel``, e.g. the one served over VRPN);
        it becomes the world's motion capture (``mocap``) when there was none."""
        self.mocap_feed.attach(model)
        if self.mocap is None:
            self.mocap = model

    def set_mocap_to_estimator(self, uri_or_name: str, on: bool) -> bool:
        """Switch the feed of the world's mocap into one Crazyflie's estimator; the first switch-on
        without ``use_mocap`` attaches a motion-capture model with the default rate, noise and latency."""
        with self._lock:
            name = self._find(uri_or_name).name
            if on and self.mocap_feed.model is None:
                if self.mocap is None:
                    from crazyflie_driver.sim.room.mocap import MocapModel
                    self.use_mocap(MocapModel(self.world, seed=self._mocap_seed).attach())
                else:
                    self.use_mocap(self.mocap)
            self.mocap_feed.set(name, bool(on))
            return self.mocap_feed.enabled(name)

    def _feed_estimator(self, name: str, position, quaternion) -> None:
        entry = self._entries.get(name)
        if entry is not None:
            entry.crazyflie.external_pose_from_world(position, quaternion)

    def _tick(self, now: float) -> None:
        """The firmware timers of every Crazyflie that has one due (most ticks: none)."""
        for cf in self._crazyflies:
            if now >= cf.timer_due - 1e-9:
                cf.tick(now)

    # --- control calls -----------------------------------------------------------------------
    def control(self, op: str, args: Dict[str, Any]) -> Any:
        """Control operations for tests and tools (also reachable through RemoteMedium.control).

        Every operation reads its arguments through ``faults.ControlArgs``: a missing or wrong one is a
        ``FaultError`` (a ValueError) naming the operation, the argument and what is allowed.
        """
        method = getattr(self, "_op_" + op, None) if op in CONTROL_OPS else None
        if method is None:
            raise ValueError("unknown control operation %r (known: %s)" % (op, ", ".join(CONTROL_OPS)))
        return method(ControlArgs(op, args))

    def _op_time(self, a: ControlArgs) -> float:
        return float(self.world.time)

    def _op_dongle_count(self, a: ControlArgs) -> int:
        return self.medium.dongle_count()

    def _op_dongle_model(self, a: ControlArgs) -> str:
        return self.medium.dongle_model()

    def _usb_index(self, a: ControlArgs) -> int:
        index = int(a.number("index", low=0))
        if index >= self.medium.usb_count():
            raise FaultError("no simulated Crazyflie usb://%d: %d on a USB cable" % (index, self.medium.usb_count()))
        return index

    def _op_usb_count(self, a: ControlArgs) -> int:
        return self.medium.usb_count()

    def _op_usb_send(self, a: ControlArgs) -> bool:
        try:
            data = bytes.fromhex(a.text("data"))
        except ValueError:
            raise FaultError("usb_send: 'data' must be hexadecimal") from None
        if not 1 <= len(data) <= 32:
            raise FaultError("usb_send: a CRTP packet has 1-32 bytes, got %d" % len(data))
        return self.medium.usb_send(self._usb_index(a), data)

    def _op_usb_receive(self, a: ControlArgs) -> Optional[str]:
        packet = self.medium.usb_receive(self._usb_index(a))
        return None if packet is None else packet.hex()

    def plug_usb(self, uri_or_name: str) -> int:
        """Put the simulated Crazyflie ``uri_or_name`` on a USB cable too: it answers ``usb://N`` (N
        returned, in plugging order) as well as its radio URI."""
        with self._lock:
            try:
                entry = self._find(uri_or_name)
            except KeyError:
                raise ValueError("cannot put %r on a USB cable: no simulated Crazyflie of that name or URI (the "
                                 "world has %s)" % (uri_or_name, ", ".join(sorted(self._entries)) or "none")) from None
            return self.medium.plug_usb(entry.crazyflie)

    def _dongle(self, a: ControlArgs) -> int:
        dongle = a.integer("dongle")
        if dongle >= self.medium.dongle_count():
            raise FaultError("%s: no simulated dongle %d (this world has %d: 0..%d)"
                             % (a.op, dongle, self.medium.dongle_count(), self.medium.dongle_count() - 1))
        return dongle

    def _op_set_dongle_faults(self, a: ControlArgs) -> Dict[str, Any]:
        dongle = self._dongle(a)
        self._set_dongle_faults(dongle, a.number("packet_loss", None, 0.0, 100.0),
                                a.number("ack_loss", None, 0.0, 100.0),
                                a.number("latency_s", None, 0.0, MAX_RADIO_LATENCY_S), a.flag("unplugged", None))
        return self._dongle_faults(dongle)

    def _set_dongle_faults(self, dongle: int, packet_loss: Optional[float], ack_loss: Optional[float],
                           latency_s: Optional[float], unplugged: Optional[bool]) -> None:
        """Sets them; a change of plugged state is stamped with the world's time, so that a reaction to
        it is timed from the moment it happened, not from when a slow-starting tool asked for it."""
        was_unplugged = self.medium.dongle_faults(dongle).unplugged
        self.medium.set_dongle_faults(dongle, packet_loss, ack_loss, latency_s, unplugged)
        if unplugged is not None and bool(unplugged) != was_unplugged:
            self._plug_changed_at[dongle] = float(self.world.time)

    def _dongle_faults(self, dongle: int) -> Dict[str, Any]:
        f = self.medium.dongle_faults(dongle)
        return {"dongle": dongle, "packet_loss": f.packet_loss, "ack_loss": f.ack_loss, "latency_s": f.latency_s,
                "unplugged": f.unplugged, "plug_changed_at": self._plug_changed_at.get(dongle)}

    def _op_dongle_faults(self, a: ControlArgs) -> List[Dict[str, Any]]:
        dongles = [self._dongle(a)] if a.has("dongle") else range(self.medium.dongle_count())
        return [self._dongle_faults(d) for d in dongles]

    def _op_add_crazyflie(self, a: ControlArgs) -> Dict[str, Any]:
        uri = a.text("uri")
        self.add_crazyflie(uri, a.text("name", None), a.args.get("position") or (0.0, 0.0, 0.0),
                           a.text("firmware", "current"), mocap_to_estimator=a.flag("mocap_to_estimator", False),
                           platform=a.text("platform", PLATFORM_CF2),
                           decks=[str(d) for d in a.args.get("decks") or ()])
        return self._find(uri).describe()

    def _op_remove_crazyflie(self, a: ControlArgs) -> None:
        self.remove_crazyflie(a.text("uri"))

    def _op_list(self, a: ControlArgs) -> List[Dict[str, Any]]:
        return [e.describe() for e in self.entries()]

    def _op_state(self, a: ControlArgs) -> Dict[str, Any]:
        return self.crazyflie(a.text("uri")).snapshot()

    def _op_vehicle_state(self, a: ControlArgs) -> Dict[str, Any]:
        """The body: position, velocity, motors, lock (World's Vehicle.state)."""
        return self.world.vehicle(self._name(a)).state()

    def _op_poses(self, a: ControlArgs) -> Dict[str, Any]:
        """Every body's true position at one instant of world time (a flight recorder reads it)."""
        with self.world._lock:      # the world's RLock: time and positions of the same tick
            names, positions, _ = self.world.poses()
            now = float(self.world.time)
        return {"time": now, "names": list(names), "positions": positions.tolist()}

    def _name(self, a: ControlArgs) -> str:
        with self._lock:
            return self._find(a.text("uri")).name

    def _op_power(self, a: ControlArgs) -> Dict[str, Any]:
        cf = self.crazyflie(a.text("uri"))
        cf.power_on() if a.flag("on") else cf.power_off()
        return {"powered": cf.powered}

    def _op_reboot(self, a: ControlArgs) -> None:
        self.crazyflie(a.text("uri")).reboot()

    def _op_set_rssi(self, a: ControlArgs) -> None:
        entry = self._find(a.text("uri"))
        self.medium.set_rssi(*entry.key, mean_dbm=a.number("mean_dbm", low=-127.0, high=0.0),
                             noise_db=a.number("noise_db", None, 0.0))

    def _op_set_battery(self, a: ControlArgs) -> Dict[str, Any]:
        """Drain or charge a vehicle's battery: ``voltage`` (V, read under the present load) or ``charge`` (0..1)."""
        name = self._name(a)
        vehicle = self.world.vehicle(name)
        if a.has("voltage") == a.has("charge"):
            raise FaultError("set_battery: give either 'voltage' (V) or 'charge' (0..1)")
        if a.has("charge"):
            charge = a.number("charge", low=0.0, high=1.0)
        else:
            try:
                charge = battery_model.charge_for_voltage(a.number("voltage", low=0.0),
                                                          vehicle.battery()["current"])
            except ValueError as e:
                raise FaultError("set_battery: %s" % e) from None
        vehicle.set_battery_charge(charge)
        if charge < 1.0:
            self._battery_set[name] = charge
        else:                                  # a full battery is no fault any more
            self._battery_set.pop(name, None)
        return vehicle.battery()

    def _op_set_mocap_faults(self, a: ControlArgs) -> Dict[str, Any]:
        """One body's motion-capture faults (``sim.room.mocap.MocapModel.set_body_faults``)."""
        mocap = self._need_mocap(a)
        name = self._name(a)
        if a.flag("clear", False):
            mocap.clear_body_faults(name)
        now = float(self.world.time)
        try:
            f = mocap.set_body_faults(name, now, noise=a.number("noise_m", None, 0.0, MAX_MOCAP_NOISE_M),
                                      latency=a.number("latency_s", None, 0.0, MAX_MOCAP_LATENCY_S),
                                      rate=a.number("rate_hz", None, MIN_MOCAP_RATE_HZ),
                                      dropout=a.number("dropout", None, 0.0, 1.0), freeze=a.span("freeze_s"),
                                      hide=a.span("hide_s"))
        except ValueError as e:
            raise FaultError("set_mocap_faults: %s" % e) from None
        return {"name": name, "faults": f.describe(now) or "none"}

    def _need_mocap(self, a: ControlArgs):
        if self.mocap is None:
            raise FaultError("%s: this world has no motion-capture system (crazyflie_sim_node, started by "
                             "sim.launch, has one; crazyflie_world_server only with --vrpn)" % a.op)
        return self.mocap

    def _op_set_mocap_to_estimator(self, a: ControlArgs) -> Dict[str, Any]:
        """Simulator extension: the world's motion capture straight into one estimator (``on``, default true)."""
        return {"uri": a.text("uri"), "mocap_to_estimator": self.set_mocap_to_estimator(a.text("uri"),
                                                                                        a.flag("on", True))}

    def _op_faults(self, a: ControlArgs) -> List[List[str]]:
        """The faults in force, as [target, description] pairs."""
        return [list(pair) for pair in self.active_faults()]

    def active_faults(self) -> List[Tuple[str, str]]:
        out: List[Tuple[str, str]] = []
        for d in range(self.medium.dongle_count()):
            f = self.medium.dongle_faults(d)
            parts = (["unplugged"] if f.unplugged else []) + \
                (["packet loss %.0f %%" % f.packet_loss] if f.packet_loss else []) + \
                (["ack loss %.0f %%" % f.ack_loss] if f.ack_loss else []) + \
                (["latency %.0f ms" % (f.latency_s * 1000.0)] if f.latency_s else [])
            if parts:
                out.append(("dongle %d" % d, ", ".join(parts)))
        now = float(self.world.time)
        mocap_faults: Dict[str, Any] = self.mocap.body_faults(now) if self.mocap is not None else {}
        for e in self.entries():
            parts = []
            if not e.crazyflie.powered:
                parts.append("switched off")
            if e.name in self._battery_set:
                parts.append("battery set to %.0f %% (now %.2f V)" % (self._battery_set[e.name] * 100.0,
                                                                      self.world.vehicle(e.name).battery()["vbat"]))
            if e.name in mocap_faults:
                parts.append("mocap " + mocap_faults[e.name].describe(now))
            if self.mocap is not None and not self.mocap.visible(e.name):
                parts.append("mocap hidden")
            if parts:
                out.append((e.name, ", ".join(parts)))
        return out

    def _op_clear_faults(self, a: ControlArgs) -> List[List[str]]:
        """End radio and motion-capture faults: all, one dongle's (``dongle``) or one vehicle's (``uri``).
        Power and battery stay as they are: they are the vehicle's state, not a fault of the air."""
        if a.has("dongle"):
            dongles, names = [self._dongle(a)], []
        elif a.has("uri"):
            dongles, names = [], [self._name(a)]
        else:
            dongles, names = list(range(self.medium.dongle_count())), None
        for d in dongles:
            self._set_dongle_faults(d, 0.0, 0.0, 0.0, False)
        if self.mocap is not None:
            if names is None:
                self.mocap.clear_body_faults()
            for n in names or []:
                self.mocap.clear_body_faults(n)
        return self._op_faults(a)

    # --- serving -----------------------------------------------------------------------------
    def start(self) -> Tuple[str, int]:
        """Listen and serve in background threads; returns the bound (host, port)."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
        except OSError as e:
            sock.close()
            raise CrazyflieError("cannot serve the simulated world on %s:%d: %s (is another crazyflie_world_server "
                                 "running? choose another with --address)"
                                 % (self.host, self.port, e.strerror or e)) from e
        sock.listen(16)
        sock.settimeout(0.2)
        self._listener = sock
        self.port = sock.getsockname()[1]
        self._running.set()
        t = threading.Thread(target=self._accept_loop, name="world-server-accept", daemon=True)
        t.start()
        self._threads.append(t)
        return self.host, self.port

    @property
    def address(self) -> str:
        return "%s:%d" % (self.host, self.port)

    def _accept_loop(self) -> None:
        listener = self._listener
        assert listener is not None, "started by serve()"
        while self._running.is_set():
            try:
                client, _ = listener.accept()
            except socket.timeout:
                continue
            except OSError:
                break
            client.settimeout(None)
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            t = threading.Thread(target=self._serve, args=(client,), name="world-server-client", daemon=True)
            with self._lock:
                self._clients[client] = t         # forgotten again when the client goes (_serve's finally)
            t.start()

    def _serve(self, client: socket.socket) -> None:
        conn = framing.Connection(client)
        medium = self.medium
        try:
            while self._running.is_set():
                try:
                    code, body = conn.receive()
                except (EOFError, OSError):
                    break
                try:
                    if code == framing.OP_TRANSMIT:
                        reply = medium.transmit(*framing.decode_transmit(body))
                        conn.send(framing.STATUS_OK, framing.encode_air_reply(reply, self.world.speed))
                        continue
                    if code == framing.OP_CONTROL:
                        request = json.loads(body.decode("utf-8"))
                        result = self.control(str(request.get("op")), dict(request.get("args") or {}))
                        conn.send(framing.STATUS_OK, json.dumps(result).encode("utf-8"))
                        continue
                    conn.send(framing.STATUS_ERROR, json.dumps("unknown request code %d" % code).encode("utf-8"))
                except OSError:
                    break
                except Exception as e:  # a bad request gets an answer, never a dead server
                    text = str(e.args[0]) if isinstance(e, KeyError) and e.args else str(e)
                    try:
                        conn.send(framing.STATUS_ERROR, json.dumps(text or type(e).__name__).encode("utf-8"))
                    except OSError:
                        break
        finally:
            conn.close()
            with self._lock:
                self._clients.pop(client, None)

    def stop(self) -> None:
        self._running.clear()
        if self._listener is not None:
            try:
                self._listener.close()
            except OSError:
                pass
        with self._lock:
            clients = dict(self._clients)
            for c in clients:
                try:
                    c.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
                c.close()
            self._clients.clear()
            for entry in self._entries.values():
                if entry.udp is not None:
                    entry.udp.stop()
        for t in self._threads + list(clients.values()):
            if t is not threading.current_thread():
                t.join(timeout=2.0)
        self._threads.clear()


# --- command line --------------------------------------------------------------------------------
def load_vehicle_config(path: str) -> List[Dict[str, Any]]:
    """Vehicles from YAML: a list (or ``vehicles:`` list) of {uri, name, position, firmware, yaw,
    mocap_to_estimator}."""
    import yaml
    try:
        with open(path) as f:
            doc = yaml.safe_load(f)
    except OSError as e:
        raise ValueError("cannot read vehicle config %s: %s" % (path, e.strerror or e)) from None
    except yaml.YAMLError as e:
        raise ValueError("vehicle config %s is not valid YAML: %s" % (path, e)) from None
    items = doc.get("vehicles") if isinstance(doc, dict) else doc
    if not isinstance(items, list):
        raise ValueError("vehicle config %s: expected a list of vehicles (or a 'vehicles:' list)" % path)
    out = []
    for i, item in enumerate(items):
        if not isinstance(item, dict) or "uri" not in item:
            raise ValueError("vehicle config %s: entry %d needs at least a 'uri'" % (path, i + 1))
        unknown = set(item) - {"uri", "name", "position", "firmware", "yaw", "mocap_to_estimator", "platform",
                               "decks"}
        if unknown:
            raise ValueError("vehicle config %s: entry %d has unknown keys %s" % (path, i + 1, sorted(unknown)))
        if not isinstance(item.get("mocap_to_estimator", False), bool):
            raise ValueError("vehicle config %s: entry %d: mocap_to_estimator must be true or false (a simulator "
                             "extension feeding the world's motion capture into the estimator), got %r"
                             % (path, i + 1, item["mocap_to_estimator"]))
        if item.get("platform", PLATFORM_CF2) not in PLATFORMS:
            raise ValueError("vehicle config %s: entry %d: platform must be one of %s (brushless: must be armed "
                             "before its motors spin), got %r" % (path, i + 1, ", ".join(PLATFORMS), item["platform"]))
        decks = item.get("decks", [])
        if not isinstance(decks, list) or any(d not in DECKS for d in decks):
            raise ValueError("vehicle config %s: entry %d: decks must be a list of deck names out of %s, got %r"
                             % (path, i + 1, ", ".join(sorted(DECKS)), decks))
        out.append(dict(item))
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="crazyflie_world_server", description="Run the simulated Crazyflie world.")
    p.add_argument("--uri", action="append", default=[], help="radio URI of a simulated Crazyflie (repeatable)")
    p.add_argument("--config", help="YAML file listing vehicles (uri, name, position, firmware, yaw, "
                   "mocap_to_estimator)")
    p.add_argument("--swarm", metavar="FILE", help="crazyflie_server's swarm file: every Crazyflie at its "
                   "initialPosition on its id's address and channel, one dongle per channel")
    p.add_argument("--address", default=None,
                   help="host:port to serve on (default $CRAZYFLIE_SIM_ADDRESS or %s:%d)"
                   % (DEFAULT_HOST, DEFAULT_PORT))
    p.add_argument("--speed", default="1.0", help="world time per real time (0 = as fast as possible), or 'auto': "
                   "real time, slower while the other processes of its parent (the host) wait for a CPU "
                   "(docs/simulation.md)")
    p.add_argument("--firmware", default="current", choices=sorted(PROFILES), help="firmware of --uri vehicles")
    p.add_argument("--dongles", type=int, default=None, help="number of simulated Crazyradios (default: 1, or what "
                   "the swarm file needs)")
    p.add_argument("--dongle-model", default="PA", help="the simulated Crazyradios: PA (firmware 0.53), PA-99.55, "
                   "2.0 (firmware 5.4, inline mode) or 2.0-5.0 (no inline mode)")
    p.add_argument("--usb", action="append", default=[], metavar="NAME_OR_URI",
                   help="also put this Crazyflie on a USB cable: it answers usb://N too, N in the order given")
    p.add_argument("--udp", action="store_true", help="also serve udp://127.0.0.1:%d+i per Crazyflie" % UDP_BASE_PORT)
    p.add_argument("--seed", type=int, default=None, help="seed for noise and faults")
    p.add_argument("--vrpn", nargs="?", type=int, const=-1, default=None, metavar="PORT",
                   help="also serve the motion capture as VRPN on 127.0.0.1:PORT, one tracker per vehicle "
                   "(no PORT: 3883 when free, else any; 0: any)")
    p.add_argument("--mocap-rate", type=float, default=100.0, help="VRPN motion capture: frames per second")
    p.add_argument("--mocap-noise", type=float, default=0.0005, help="... position noise, m (standard deviation)")
    p.add_argument("--mocap-latency", type=float, default=0.008, help="... latency, s")
    p.add_argument("--mocap-dropout", type=float, default=0.0, help="... fraction of frames that lose a body")
    return p


def start_vrpn(world, args: argparse.Namespace, seed: Optional[int]):
    """The ``--vrpn`` server: a motion-capture model with the ``--mocap-*`` settings, served over VRPN."""
    from crazyflie_driver.sim.room.mocap import MocapModel
    from crazyflie_driver.sim.room.mocap_vrpn import WorldVrpnServer

    if args.vrpn > 65535:
        raise ValueError("--vrpn port must be 0..65535, got %d" % args.vrpn)
    model = MocapModel(world, rate=args.mocap_rate, position_noise=args.mocap_noise, latency=args.mocap_latency,
                       dropout=args.mocap_dropout, seed=seed)
    server = WorldVrpnServer(world, model, port=None if args.vrpn < 0 else args.vrpn)
    try:
        server.start()
    except OSError as e:
        raise ValueError("cannot serve VRPN on port %d: %s (choose another: --vrpn PORT, 0 for any)"
                         % (args.vrpn, e.strerror or e)) from None
    model.attach()
    return server


SwarmReader = Callable[[str], Tuple[List[Dict[str, Any]], int]]


def vehicles_from_args(args: argparse.Namespace, read_swarm: Optional[SwarmReader]) -> List[Dict[str, Any]]:
    """The Crazyflies the command line asks for (--uri, --config, --swarm), their URIs checked; sets
    ``args.dongles`` from the swarm file when the command line leaves it out."""
    vehicles: List[Dict[str, Any]] = [{"uri": u, "firmware": args.firmware} for u in args.uri]
    if args.config:
        vehicles += load_vehicle_config(args.config)
    swarm_dongles = 1
    if args.swarm:
        if read_swarm is None:
            raise ValueError("--swarm: start the world server with the crazyflie_world_server script, which "
                             "reads swarm files")
        from_swarm, swarm_dongles = read_swarm(args.swarm)
        vehicles += from_swarm
    if args.dongles is None:
        args.dongles = swarm_dongles
    if not vehicles:
        raise ValueError("no Crazyflies to simulate: give --uri radio://0/80/2M/E7E7E7E701 or --config FILE")
    for v in vehicles:
        key_of(str(v["uri"]))             # refuse a bad URI before building the world
    return vehicles


def build_world_server(args: argparse.Namespace, vehicles: List[Dict[str, Any]], host: str, port: int,
                       pacing: Pacing):
    """The world, its server (started) with every vehicle and USB cable, and the VRPN server if asked
    for: (world, server, vrpn or None). The world is not stepping yet."""
    if args.dongles < 1:
        raise ValueError("--dongles must be >= 1, got %r" % args.dongles)
    from crazyflie_driver.sim.room.world import World
    world = World(speed=pacing.target, seed=args.seed)
    server = WorldServer(world, dongles=args.dongles, host=host, port=port, seed=args.seed,
                         udp_base_port=UDP_BASE_PORT if args.udp else None, dongle_model=args.dongle_model)
    for i, v in enumerate(vehicles):
        pos = v.get("position") or (0.5 * i, 0.0, 0.0)
        server.add_crazyflie(str(v["uri"]), v.get("name"), pos, str(v.get("firmware") or args.firmware),
                             float(v.get("yaw") or 0.0), platform=str(v.get("platform") or PLATFORM_CF2),
                             decks=[str(d) for d in v.get("decks") or ()])
    for name in args.usb:
        server.plug_usb(name)
    server.start()
    try:
        vrpn = start_vrpn(world, args, args.seed) if args.vrpn is not None else None
        if vrpn is not None:
            server.mocap = vrpn.mocap       # its motion capture takes faults too
    except ValueError:
        server.stop()
        raise
    if vrpn is not None:
        server.use_mocap(vrpn.mocap)      # estimators fed by the switch see what VRPN clients see
    for v in vehicles:
        if v.get("mocap_to_estimator"):
            server.set_mocap_to_estimator(str(v["uri"]), True)
    return world, server, vrpn


def serve_until_signal(world, server: WorldServer, vrpn, pacing: Pacing, args: argparse.Namespace) -> None:
    """Steps the world and serves it until SIGINT or SIGTERM, then stops everything it started."""
    stop = threading.Event()

    def on_signal(signum, frame):  # noqa: ARG001
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    world.start()
    pacer = start_pacing(world, pacing)
    for entry in server.entries():
        _log.info("%s (%s firmware) on %s%s", entry.name, entry.crazyflie.profile.generation, entry.uri,
                  " and %s" % entry.udp.uri if entry.udp is not None else "")
    if vrpn is not None:
        _log.info("motion capture served as VRPN on 127.0.0.1:%d (%.0f Hz, one tracker per vehicle)", vrpn.port,
                  args.mocap_rate)
    _log.info("world served on %s (speed %s); Ctrl-C to stop", server.address, pacing.describe())
    try:
        while not stop.wait(0.5):
            pass
    finally:
        if pacer is not None:
            pacer.stop()
        if vrpn is not None:
            vrpn.stop()
        server.stop()
        world.stop()
        _log.info("stopped")


def main(argv: Optional[Sequence[str]] = None, read_swarm: Optional[SwarmReader] = None) -> int:
    """``read_swarm(path)``: the vehicles ({uri, name, position}) of a swarm file and the dongles they need."""
    logging.basicConfig(level=logging.INFO, format="crazyflie_world_server: %(message)s")
    args = build_parser().parse_args(argv)
    try:
        vehicles = vehicles_from_args(args, read_swarm)
        host, port = parse_address(args.address)
        pacing = parse_pacing(args.speed)
        world, server, vrpn = build_world_server(args, vehicles, host, port, pacing)
    except (ValueError, KeyError, CrazyflieError, ImportError) as e:
        print("crazyflie_world_server: error: %s" % (e,), file=sys.stderr)
        return 2
    serve_until_signal(world, server, vrpn, pacing, args)
    return 0
