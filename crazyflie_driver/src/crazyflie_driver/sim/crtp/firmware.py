"""The simulated Crazyflie's protocol side: nRF radio link plus the STM's CRTP ports.

``SimulatedCrazyflie`` answers the real protocol of one of two firmware generations (docs/protocol.md):
"current" (protocol 12, TOC V2, 1-byte empty acks) or "2016.02" (protocol 2, TOC V1,
3-byte empty acks carrying RSSI). Its flight behaviour lives in the ``Vehicle`` it is given; this
object only turns packets into vehicle calls and vehicle readings into packets.

Two entry points: ``handle_radio_packet`` (what the dongle's radio delivers; returns the ack payload)
and ``handle_crtp`` + ``pop_outgoing`` (a packet link such as UDP). ``tick(world_time)`` runs the log
timers. Every entry point is thread safe and never raises on malformed input.
"""
from __future__ import annotations

import logging
import threading
from collections import deque
from dataclasses import dataclass, replace
from typing import Any, Callable, Deque, Dict, List, Optional, Sequence, Tuple, Union

from crazyflie_driver.crtp import bootloader as bl
from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.crtp.nrf_system import (
    RESET_TO_FIRMWARE,
    SYS_ALL_OFF,
    SYS_RESET,
    SYS_RESET_INIT,
    SYS_STM_OFF,
    SYS_STM_ON,
)
from crazyflie_driver.crtp.packet import MAX_PAYLOAD, CRTPPacket
from crazyflie_driver.sim.crtp import firmware_toc, ports
from crazyflie_driver.sim.crtp import tables as T
from crazyflie_driver.sim.crtp.bootloader import GEOMETRY, SimBootloader, image_version
from crazyflie_driver.sim.crtp.decoded_values import DecodedValues, trajectory_values
from crazyflie_driver.sim.crtp.high_level_port import ENOEXEC, high_level_port
from crazyflie_driver.sim.crtp.link import NrfLink
from crazyflie_driver.sim.crtp.log import LogService
from crazyflie_driver.sim.crtp.memory_port import DECKS, Memory, deck_memory, eeprom, memory_port
from crazyflie_driver.sim.crtp.param import ParamService
from crazyflie_driver.sim.crtp.state import SimState
from crazyflie_driver.sim.crtp.trajectory_memory import TrajectoryMemory

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FirmwareProfile:
    """What differs between the firmware generations the simulation speaks."""

    generation: str
    protocol_version: int
    firmware_version: str
    device_type: str
    device_type_query: bool          # platform ch 1 cmd 2 and the ch 0 arm/recover commands
    tx_queue_size: int
    rssi_in_empty_ack: bool
    link_loss_timeout: Optional[float]   # radio silence after which running log blocks are deleted
    ports: frozenset
    production: bool = True


PROFILES: Dict[str, FirmwareProfile] = {
    T.GEN_CURRENT: FirmwareProfile(T.GEN_CURRENT, 12, firmware_toc.FIRMWARE_RELEASE, "Crazyflie 2.0", True, 200,
                                   False, 1.0, frozenset({0, 2, 3, 4, 5, 6, 7, 8, 9, 13, 15})),
    T.GEN_2016: FirmwareProfile(T.GEN_2016, 2, "2016.02", "Crazyflie 2.0", False, 60, True, None,
                                frozenset({0, 2, 3, 4, 5, 13, 15})),
}


def profile_for(firmware: str) -> FirmwareProfile:
    try:
        return PROFILES[firmware]
    except KeyError:
        raise ValueError("unknown firmware generation %r (choose one of: %s)"
                         % (firmware, ", ".join(sorted(PROFILES)))) from None


class SimulatedCrazyflie:
    """One simulated Crazyflie (protocol side) bound to a vehicle of the world."""

    def __init__(self, address: bytes, vehicle: Any, firmware: str = T.GEN_CURRENT,
                 rssi_dbm: float = -40.0, param_table: Optional[Sequence[T.ParamVar]] = None,
                 log_table: Optional[Sequence[T.LogVar]] = None, auto_arm: bool = True,
                 decks: Sequence[str] = ()) -> None:
        """``auto_arm`` False: a platform that must be armed before its motors spin (a Brushless one).
        ``decks``: board names (memory_port.DECKS) of the decks plugged in, one one-wire memory each."""
        self.address = bytes(address)
        unknown = [d for d in decks if d not in DECKS]
        if unknown:
            raise ValueError("unknown deck %s: use one of %s" % (", ".join(unknown), ", ".join(sorted(DECKS))))
        self.decks = tuple(decks)
        # The radio settings in force (set by the medium that carries this Crazyflie) and the EEPROM,
        # which keeps its bytes across reboots; ``_radio_moved`` tells the medium of new settings.
        self.radio_channel, self.radio_datarate = cb.DEFAULT_CHANNEL, cb.DEFAULT_DATARATE
        self.eeprom = eeprom(cb.ConfigBlock(address=int.from_bytes(self.address, "big")))
        self._radio_moved: Optional[Callable[[int, int, bytes], bool]] = None
        self.auto_arm = bool(auto_arm)
        self.vehicle = vehicle
        self.profile = profile_for(firmware)
        self.rssi_dbm = float(rssi_dbm)          # RSSI of the last uplink packet (set by the medium)
        self.state = SimState(armed=self.auto_arm)
        self.lock = threading.RLock()
        self._param_table = tuple(param_table if param_table is not None else T.PARAM_TABLE)
        self._log_table = tuple(log_table if log_table is not None else T.LOG_TABLE)
        self._tx: Deque[bytes] = deque()
        self._tx_queued_at: Deque[float] = deque()   # world time [s] each packet in _tx was queued
        self._tx_listener: Optional[Callable[[], None]] = None
        self._last_radio: Optional[float] = None
        self.radio_on = True                     # the nRF's power: off only after "all off" or the switch
        self.in_bootloader = False               # rebooted into the bootloader: no firmware answers CRTP
        self._reset_armed = False                # an nRF RESET_INIT came: the next RESET is taken
        self.bootloader = SimBootloader()        # both chips' flash: kept across reboots
        self.link = NrfLink(self._dispatch, self._pop_locked, self._rssi_positive,
                            self.profile.rssi_in_empty_ack, self._system_command)
        self._ports: Dict[int, Callable[[int, int, bytes], None]] = {}
        self.decoded = DecodedValues()           # extremes of every value handed to the vehicle (tests read it)
        self._boot()

    # --- lifecycle ---------------------------------------------------------------------------
    def _boot(self) -> None:
        self.timer_due = 0.0                 # world time at which `tick` next has work (0: at once)
        self._boot_time = self.now()
        self._clear_tx()
        self._last_radio = None
        self.packet_link_active = False      # True while a packet link (UDP) is the active link
        self.params = ParamService(self.profile.generation, self.profile.protocol_version, self._param_table,
                                   self._vehicle_param_defaults(), self._write_param, self.send)
        self.logs = LogService(self.profile.generation, self._log_table, self.read_value, self.send, self.now)
        self.console = ports.Console(self.send)
        state, profile = self.state, self.profile
        vehicle_hook, decoded = ports.vehicle_hook(self.vehicle), self.decoded

        def hook(name: str, *args) -> bool:
            decoded.observe(name, args)
            return vehicle_hook(name, *args)
        self._apply_config_block()
        self.trajectory_memory = TrajectoryMemory()           # RAM: empty after every boot
        self.memories: List[Memory] = [deck_memory(DECKS[name], slot) for slot, name in enumerate(self.decks)]
        self.memories.append(self.eeprom)
        if 8 in profile.ports:
            self.memories.append(self.trajectory_memory)  # type: ignore[arg-type]
        memory = memory_port(self.send, self.memories)
        handlers = {
            2: self.params.handle,
            3: ports.commander_port(state, hook),
            4: memory,
            5: self.logs.handle,
            6: ports.localization_port(state, hook, self.emergency_stop, self.now, self.address[-1]),
            7: ports.generic_setpoint_port(state, hook, self.halt),
            8: high_level_port(self.send, self._high_level, self.trajectory_memory),
            9: ports.supervisor_port(state, self.send, self.supervisor_bits, self.arm, self.recover,
                                     self.emergency_stop, self.now),
            13: ports.platform_port(self.send, profile.protocol_version, profile.firmware_version,
                                    profile.device_type, profile.device_type_query, self.arm, self.recover),
            15: ports.link_port(self.send),
        }
        self._ports = {p: h for p, h in handlers.items() if p in self.profile.ports}
        cpu_id = "%08X%08X%08X" % tuple(int(self.params.value("cpu.id%d" % i)) for i in range(3)) \
            if self.params.ident("cpu.id0") is not None else "0" * 24
        self.console.write(ports.boot_text(self.profile.device_type, self.profile.firmware_version, cpu_id,
                                           self.profile.production))

    def bind_radio(self, channel: int, datarate: int, moved: Optional[Callable[[int, int, bytes], bool]]) -> None:
        """The medium carries this Crazyflie on ``channel``/``datarate`` at its address: the EEPROM is
        programmed with them (as a Crazyflie configured for that swarm slot), and ``moved(channel,
        datarate, address)`` is asked at a later boot whose EEPROM names other settings (it returns
        False when the medium cannot take them; the Crazyflie then stays where it was)."""
        with self.lock:
            self.radio_channel, self.radio_datarate = int(channel), int(datarate)
            self._radio_moved = moved
            try:
                current = cb.decode(bytes(self.eeprom.data[:cb.SIZE]))
            except ValueError:
                current = cb.ConfigBlock()
            self.eeprom.data[:cb.SIZE] = cb.encode(current._replace(
                channel=self.radio_channel, datarate=self.radio_datarate,
                address=int.from_bytes(self.address, "big")))

    def config_block(self) -> cb.ConfigBlock:
        """What the firmware reads from the EEPROM at boot: the block, or the defaults when it is invalid."""
        try:
            return cb.decode(bytes(self.eeprom.data[:cb.SIZE]))
        except ValueError:
            return cb.ConfigBlock()

    def _apply_config_block(self) -> None:
        """At boot the radio takes the EEPROM's channel, data rate and address (the firmware hands
        them to the nRF); a change moves this Crazyflie on the medium."""
        block = self.config_block()
        wanted = (block.channel, block.datarate, block.address_bytes)
        if wanted == (self.radio_channel, self.radio_datarate, self.address):
            return
        moved = self._radio_moved
        if moved is not None and not moved(*wanted):
            _log.warning("simulated Crazyflie %s keeps channel %d, rate %d: another Crazyflie listens on "
                         "channel %d, rate %d, address %s", self.address.hex().upper(), self.radio_channel,
                         self.radio_datarate, wanted[0], wanted[1], wanted[2].hex().upper())
            return
        self.radio_channel, self.radio_datarate, self.address = wanted

    def reboot(self, bootloader: bool = False, reset_nrf: bool = True) -> None:
        """Power cycle: protocol state back to boot (params, log blocks, console text, uptime); with
        ``reset_nrf`` the radio's safelink state too. Into the bootloader the firmware does not run:
        the nRF acks, nothing answers CRTP until a reset into the firmware."""
        with self.lock:
            hook = getattr(self.vehicle, "reboot", None)
            if hook is not None:
                try:
                    hook()
                except Exception:
                    _log.exception("vehicle.reboot failed")
            reboots = self.state.reboots + 1
            self.state = SimState(reboots=reboots, armed=self.auto_arm)
            self.radio_on = True
            self.in_bootloader = bool(bootloader)
            self._reset_armed = False
            image = self.bootloader.stm32_image()
            if image is not None and not bootloader:     # a flashed image runs: its version is reported
                self.profile = replace(self.profile, firmware_version=image_version(image))
            if reset_nrf:
                self.link.reset()
            self._boot()
            if bootloader:
                self.state.powered = False
                self._clear_tx()                 # no firmware ran: no boot text

    def power_off(self) -> None:
        """The power switch: everything off (the radio too)."""
        with self.lock:
            self._cut_power()
            self.radio_on = False

    def _cut_power(self) -> None:
        """STM off: the motors stop with it (the vehicle would otherwise fly on its last setpoint)."""
        self.state.powered = False
        self._clear_tx()
        stop = getattr(self.vehicle, "stop_motors", None)
        try:
            stop() if stop is not None else self.vehicle.set_rpyt(0.0, 0.0, 0.0, 0)
        except Exception:
            _log.exception("stopping the vehicle's motors at power-off failed")

    def power_on(self) -> None:
        """The power switch on: a cold boot when anything was off."""
        with self.lock:
            if not self.state.powered or not self.radio_on:
                self.reboot()

    @property
    def powered(self) -> bool:
        return self.state.powered

    # --- clocks and readings -----------------------------------------------------------------
    def now(self) -> float:
        try:
            return float(self.vehicle.time())
        except Exception:
            return 0.0

    def timestamp_ms(self, now: Optional[float] = None) -> int:
        t = self.now() if now is None else now
        return max(0, int(round((t - self._boot_time) * 1000.0))) & 0xFFFFFF

    def _rssi_positive(self) -> int:
        return int(round(-self.rssi_dbm))

    def radio_connected(self, now: Optional[float] = None) -> bool:
        if self._last_radio is None:
            return False
        t = self.now() if now is None else now
        return t - self._last_radio <= 1.0

    def read_value(self, name: str) -> float:
        """Current value of a log variable (vehicle readings; radio variables from the link)."""
        if name == "radio.rssi":
            return float(self._rssi_positive())
        if name == "radio.isConnected":
            return 1.0 if self.radio_connected() else 0.0
        if name == "sys.tick":
            return float(self.timestamp_ms())
        if name == "sys.armed":
            return 1.0 if self.state.armed else 0.0
        if name == "radio.numRxBc":
            return float(self.state.rx_broadcast & 0xFFFF)
        if name == "radio.numRxUc":
            return float(self.state.rx_unicast & 0xFFFF)
        if name == "supervisor.info":
            return float(self.supervisor_bits())
        return float(self.vehicle.read(name))

    def _vehicle_param_defaults(self) -> Dict[str, float]:
        """The vehicle's values, plus ``deck.<board>`` = 1 for each deck plugged in (the deck
        drivers' read-only "detected" flags, set at boot from the one-wire identification)."""
        fn = getattr(self.vehicle, "param_defaults", None)
        decks = {"deck." + name: 1.0 for name in self.decks}
        try:
            return {**(dict(fn()) if fn is not None else {}), **decks}
        except Exception:
            _log.exception("vehicle.param_defaults failed")
            return decks

    def _write_param(self, name: str, value: float) -> None:
        self.decoded.observe("param." + name, value)
        fn = getattr(self.vehicle, "write_param", None)
        if fn is not None:
            fn(name, value)

    def _supervisor_flags(self) -> Dict[str, bool]:
        """The vehicle's supervisor flags (``Vehicle.supervisor_flags``), or what its log variables say."""
        fn = getattr(self.vehicle, "supervisor_flags", None)
        if fn is not None:
            try:
                return dict(fn())
            except Exception:
                _log.exception("vehicle.supervisor_flags failed")

        def flag(name: str, default: float) -> bool:
            try:
                return bool(self.vehicle.read(name))
            except Exception:
                return bool(default)
        try:   # the vehicle's own locks (setpoint watchdog, tumble, battery) lock the supervisor too
            vehicle_locked = bool(getattr(self.vehicle, "lock_reason", ""))
        except Exception:
            vehicle_locked = False
        return {"locked": vehicle_locked, "crashed": False, "tumbled": flag("sys.isTumbled", 0),
                "flying": flag("sys.isFlying", 0), "hl_active": False, "hl_finished": True, "hl_disabled": False}

    def supervisor_bits(self) -> int:
        """``supervisor.info``: the bits of the firmware's supervisor (docs/protocol.md, port 9)."""
        f = self._supervisor_flags()
        locked = self.state.emergency or bool(f.get("locked"))
        crashed = bool(f.get("crashed")) and not locked
        blocked = locked or crashed
        armed = self.state.armed and not blocked
        bits = int(not self.state.armed and not blocked)        # 0: can arm
        bits |= int(armed) << 1
        bits |= int(self.auto_arm) << 2                         # auto arm
        bits |= int(armed) << 3                                 # can fly: motors allowed
        bits |= int(bool(f.get("flying"))) << 4
        bits |= int(bool(f.get("tumbled"))) << 5
        bits |= int(locked) << 6
        bits |= int(crashed) << 7
        bits |= int(bool(f.get("hl_active"))) << 8
        bits |= int(bool(f.get("hl_finished"))) << 9
        bits |= int(bool(f.get("hl_disabled"))) << 10
        return bits

    def arm(self, do_arm: bool) -> Tuple[bool, bool]:
        """An arming request: (success, armed). Arming needs a supervisor that is neither locked nor
        crashed; disarming always succeeds."""
        bits = self.supervisor_bits()
        if do_arm and not bits & 0x03:              # neither armed nor able to arm (a locked supervisor disarms)
            return False, False
        self.state.armed = bool(do_arm)
        hook = getattr(self.vehicle, "set_armed", None)
        if hook is not None:
            try:
                hook(bool(do_arm))
            except Exception:
                _log.exception("vehicle.set_armed failed")
        return True, bool(self.supervisor_bits() & 0x02)

    def recover(self) -> Tuple[bool, bool]:
        """A crash-recovery request: (success, not crashed); refused while the Crazyflie is tumbled."""
        fn = getattr(self.vehicle, "recover_crash", None)
        try:
            ok = bool(fn()) if fn is not None else True
        except Exception:
            _log.exception("vehicle.recover_crash failed")
            ok = False
        return ok, not self.supervisor_bits() & 0x80

    # --- packets in --------------------------------------------------------------------------
    def handle_radio_packet(self, data: bytes, ack_requested: bool = True) -> bytes:
        """One radio packet from a dongle; returns the ack payload the nRF sends back."""
        with self.lock:
            if not self.radio_on:
                return b""
            self._last_radio = self.now()
            self.packet_link_active = False
            self.state.rx_unicast += 1
            try:
                if self.in_bootloader:
                    return self._bootloader_packet(bytes(data))
                return self.link.handle(bytes(data), ack_requested)
            except Exception:
                _log.exception("radio packet %s broke the simulated nRF", bytes(data).hex())
                return self.link.empty_ack()

    def handle_broadcast(self, data: bytes) -> None:
        """A radio packet on the broadcast address 0xFFE7E7E7E7: the nRF never acks it and hands it
        to the STM as it is (no safelink); it counts in ``radio.numRxBc`` and keeps the link alive."""
        with self.lock:
            if not self.state.powered:
                return
            self._last_radio = self.now()
            self.packet_link_active = False
            self.state.rx_broadcast += 1
            raw = bytes(data)
            if len(raw) == 1 and raw[0] == 0xFF:
                return                                  # a null packet: nothing for the STM
            self._dispatch(raw)

    def handle_crtp(self, packet: Union[bytes, CRTPPacket]) -> None:
        """One CRTP packet (header + payload) from a packet link; replies go to the TX queue."""
        raw = packet.to_bytes() if isinstance(packet, CRTPPacket) else bytes(packet)
        with self.lock:
            if self.state.powered:
                # A packet link is now the active link (as the firmware switches to USB): radio
                # silence from an earlier radio user must not delete this host's log blocks.
                self._last_radio = None
                self.packet_link_active = True
                self._dispatch(raw)

    def external_pose_from_world(self, position, quaternion) -> None:
        """A pose for the onboard estimator that did not come over a link (the world's mocap feed, a
        simulator extension): taken like an external pose while the STM runs."""
        with self.lock:
            if not self.state.powered or self.state.halted:
                return
            fn = getattr(self.vehicle, "external_measurement", None)
            if fn is None:
                return
            try:
                fn(tuple(float(v) for v in position), tuple(float(v) for v in quaternion))
            except Exception:
                _log.exception("vehicle.external_measurement failed")

    def _dispatch(self, raw: bytes) -> None:
        if not raw or len(raw) > MAX_PAYLOAD + 1 or self.state.halted or not self.state.powered:
            return
        header = raw[0]
        port, channel = header >> 4, header & 0x03
        handler = self._ports.get(port)
        if handler is None:
            return
        self.state.packets_by_port[port] = self.state.packets_by_port.get(port, 0) + 1
        self.timer_due = 0.0                 # a packet may start a log block or a watchdog
        try:
            handler(header, channel, raw[1:])
        except Exception:
            _log.exception("CRTP packet %s broke port %d of the simulated firmware", raw.hex(), port)

    def _bootloader_packet(self, raw: bytes) -> bytes:
        """A packet while the bootloaders run: their commands, and RESET_INIT + RESET to leave them.
        RESET_INIT is answered with four bytes of the CPU id (the host derives the bootloader's
        radio address from them)."""
        answer: Optional[bytes] = None
        armed, self._reset_armed = self._reset_armed, False
        if len(raw) >= 3 and raw[1] == bl.TARGET_NRF51 and raw[0] & 0xF3 == 0xF3:
            raw = bytes((bl.BOOT_HEADER,)) + raw[1:]      # the nRF's commands, whatever the sequence bits
        if len(raw) >= 3 and raw[0] == bl.BOOT_HEADER and raw[1] in (bl.TARGET_STM32, bl.TARGET_NRF51):
            if raw[2] == bl.CMD_RESET_INIT:
                self._reset_armed = True
                answer = bl.command(raw[1], bl.CMD_RESET_INIT, self.bootloader_cpu_id()[:4])
            elif raw[2] == bl.CMD_RESET and armed and len(raw) >= 4:
                self.reboot(bootloader=raw[3] != bl.RESET_TO_FIRMWARE)
                return self.link.empty_ack()
            else:
                answer = self.bootloader.handle(raw)
        return answer if answer is not None else self.link.empty_ack()

    def bootloader_cpu_id(self) -> bytes:
        return GEOMETRY[bl.TARGET_STM32].cpu_id

    def _system_command(self, command: bytes) -> None:
        """An nRF system command (the bytes after its 0xFE target), as the nRF firmware takes it: a
        reset only right after a RESET_INIT; the STM32 domain on boots the STM (the nRF keeps its
        safelink state); "all off" leaves nothing on the air."""
        cmd, arg = command[0], command[1:2]
        armed, self._reset_armed = self._reset_armed, cmd == SYS_RESET_INIT
        if cmd == SYS_RESET and armed and arg:
            self.reboot(bootloader=arg[0] != RESET_TO_FIRMWARE)
        elif cmd == SYS_STM_OFF:
            self._cut_power()
        elif cmd == SYS_STM_ON and not self.state.powered:
            self.reboot(reset_nrf=False)
        elif cmd == SYS_ALL_OFF:
            self._cut_power()
            self.radio_on = False

    # --- packets out -------------------------------------------------------------------------
    def send(self, header: int, payload: bytes) -> bool:
        """Queue a packet for the host; False (and dropped) when the TX queue is full."""
        with self.lock:
            if len(self._tx) >= self.profile.tx_queue_size:
                self.state.tx_dropped += 1
                return False
            self._tx.append(bytes([header & 0xFF]) + bytes(payload[:MAX_PAYLOAD]))
            self._tx_queued_at.append(self.now())
            listener = self._tx_listener
        if listener is not None:
            try:
                listener()
            except Exception:
                _log.exception("TX listener failed")
        return True

    def _pop_locked(self) -> Optional[bytes]:
        if not self._tx:
            return None
        if self._tx_queued_at:
            self.state.tx_last_wait_s = self.now() - self._tx_queued_at.popleft()
        packet = self._tx.popleft()
        port = packet[0] >> 4       # counted as it leaves the queue for an ack or the cable: what the host got
        self.state.sent_by_port[port] = self.state.sent_by_port.get(port, 0) + 1
        return packet

    def _clear_tx(self) -> None:
        self._tx.clear()
        self._tx_queued_at.clear()

    def pop_outgoing(self, packet_link: bool = False) -> Optional[bytes]:
        """Next queued packet for a packet link (header + payload), or None.

        With ``packet_link=True`` also None while the radio is the active link (a radio packet came
        after the last packet-link packet), checked atomically with the pop.
        """
        with self.lock:
            if packet_link and not self.packet_link_active:
                return None
            return self._pop_locked()

    def pending_outgoing(self) -> int:
        with self.lock:
            return len(self._tx)

    def set_tx_listener(self, listener: Optional[Callable[[], None]]) -> None:
        """``listener()`` is called (must not block) whenever a packet is queued."""
        with self.lock:
            self._tx_listener = listener

    # --- time ----------------------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """Run the firmware timers at world time ``now``: log blocks, e-stop watchdog, link loss.

        Sets ``timer_due``, the world time before which another call has nothing to do (a packet
        that may change the timers sets it back to 0), so a caller ticking many Crazyflies every
        millisecond skips the idle ones.
        """
        with self.lock:
            due = float("inf")
            try:
                if not self.state.powered or self.state.halted:
                    return
                wd = self.state.estop_watchdog
                if wd is not None and not self.state.emergency:
                    if now - wd > 1.0:
                        self.emergency_stop("emergency-stop watchdog expired")
                    else:
                        due = wd + 1.0
                blocks = [b for b in self.logs.blocks.values() if b.running]
                if not blocks:
                    return
                timeout = self.profile.link_loss_timeout
                if timeout is not None and self._last_radio is not None:
                    if now - self._last_radio > timeout:
                        self.logs.reset()          # the firmware cleans up after a lost radio link
                        self._clear_tx()
                        self._last_radio = None
                        return
                    due = min(due, self._last_radio + timeout)
                self.logs.tick(now, self.timestamp_ms(now))
                for b in blocks:
                    if b.running:
                        due = min(due, now if b.next_due is None else b.next_due)
            except Exception:
                _log.exception("firmware tick failed")
                due = 0.0
            finally:
                self.timer_due = due

    def _high_level(self, command: str, **args) -> int:
        """A high-level commander command for the vehicle; ENOEXEC when the vehicle has no planner."""
        self.decoded.observe("high_level." + command, args)
        fn = getattr(self.vehicle, "high_level", None)
        if fn is None:
            return ENOEXEC
        try:
            return int(fn(command, **args))
        except Exception:
            _log.exception("vehicle.high_level(%s) failed", command)
            return ENOEXEC

    # --- safety ----------------------------------------------------------------------------------
    def halt(self, reason: str, packet: bytes) -> None:
        """An assert tripped: the STM stops (motors off, no more CRTP answers) until a reboot."""
        with self.lock:
            if self.state.halted:
                return
            self.state.halted = reason
            self._clear_tx()
            _log.error("simulated Crazyflie %s halted on a firmware assert: %s; packet %s. A real Crazyflie "
                       "stops the same way: fix the host's packet. Reboot it to fly again.",
                       self.address.hex().upper(), reason, packet.hex())
            try:
                hook = getattr(self.vehicle, "halt", None)
                hook() if hook is not None else self.vehicle.emergency_stop()
            except Exception:
                _log.exception("halting the vehicle failed")

    def emergency_stop(self, reason: str = "emergency stop") -> None:
        with self.lock:
            self.state.emergency = True
            self.state.emergency_reason = reason
            try:
                self.vehicle.emergency_stop()
            except Exception:
                _log.exception("vehicle.emergency_stop failed")

    # --- inspection ------------------------------------------------------------------------------
    def snapshot(self) -> Dict[str, Any]:
        """Plain-data view of what the Crazyflie saw (JSON friendly, for control clients)."""
        with self.lock:
            s = self.state
            return {
                "address": self.address.hex().upper(),
                "firmware": self.profile.generation,
                "powered": s.powered,
                "radio_on": self.radio_on,
                "in_bootloader": self.in_bootloader,
                "emergency": s.emergency,
                "emergency_reason": s.emergency_reason,
                "halted": s.halted,
                "external_measurements": s.external_measurements,
                "rx_broadcast": s.rx_broadcast,
                "rx_unicast": s.rx_unicast,
                "armed": s.armed,
                "last_setpoint": list(s.last_setpoint) if s.last_setpoint is not None else None,
                "setpoints": s.setpoints,
                "last_generic_type": s.last_generic[0] if s.last_generic else None,
                "packets_by_port": {str(k): v for k, v in s.packets_by_port.items()},
                "sent_by_port": {str(k): v for k, v in s.sent_by_port.items()},
                "tx_pending": len(self._tx),
                "tx_dropped": s.tx_dropped,
                "tx_last_wait_s": s.tx_last_wait_s,
                "safelink": self.link.safelink,
                "reboots": s.reboots,
                "radio": {"channel": self.radio_channel, "datarate": self.radio_datarate},
                "config_block": self.config_block()._asdict(),
                "decks": list(self.decks),
                "uptime_ms": self.timestamp_ms(),
                "params_changed": {e.full_name: self.params.values[i] for i, e in enumerate(self.params.entries)
                                   if self.params.values[i] != self.params.default_of(i)},
                "rssi_dbm": self.rssi_dbm,
                "log_blocks": {str(b.ident): {"running": b.running, "period_ms": int(round(b.period_s * 1000)),
                                              "variables": [self.logs.entries[v].full_name for v, _ in b.ops]}
                               for b in self.logs.blocks.values()},
                "params": {e.full_name: self.params.values[i] for i, e in enumerate(self.params.entries)},
                "decoded": self.decoded.summary(),
                "trajectories": trajectory_values(self.trajectory_memory.decoded, self.trajectory_memory.descriptors),
            }
