"""Test doubles for the radio layers: a scripted Medium, an nRF-side safelink peer, a fake clock."""
from __future__ import annotations

from collections import deque
from typing import Callable, Deque, List, NamedTuple, Optional

from crazyflie_driver.sim.air.medium import AirReply, DongleFaults


class Transmit(NamedTuple):
    dongle: int
    channel: int
    datarate: int
    address: bytes
    data: bytes
    ack_enabled: bool
    arc: int


class ScriptedMedium:
    """Records every transmit; replies from ``script`` (queued AirReplies) first, then ``responder``."""

    def __init__(self, responder: Optional[Callable[[Transmit], AirReply]] = None, dongles: int = 1):
        self.transmits: List[Transmit] = []
        self.script: Deque[AirReply] = deque()
        self.responder = responder or (lambda tx: AirReply(True, b""))
        self.faults: List[tuple] = []
        self.dongles = dongles

    def push(self, *replies: AirReply) -> None:
        self.script.extend(replies)

    def transmit(self, dongle, channel, datarate, address, data, ack_enabled=True, arc=3):
        tx = Transmit(dongle, channel, datarate, bytes(address), bytes(data), ack_enabled, arc)
        self.transmits.append(tx)
        if self.script:
            return self.script.popleft()
        return self.responder(tx)

    def set_dongle_faults(self, dongle, packet_loss=None, ack_loss=None, latency_s=None, unplugged=None):
        self.faults.append((dongle, packet_loss, ack_loss, latency_s, unplugged))

    def dongle_faults(self, dongle) -> DongleFaults:
        """Only ``unplugged`` is followed: the latest value set for ``dongle``."""
        out = [f[4] for f in self.faults if f[0] == dongle and f[4] is not None]
        return DongleFaults(unplugged=bool(out and out[-1]))

    def dongle_count(self) -> int:
        return self.dongles

    def dongle_model(self) -> str:
        return "PA"

    def usb_count(self) -> int:
        return 0


class NrfPeer:
    """The Crazyflie's nRF side as docs/protocol.md ("Safelink, empty acks and RSSI") describes it: safelink,
    downlink queue, empty acks.

    ``received`` holds every uplink packet accepted (duplicates dropped in safelink mode).
    ``lose_uplink`` / ``lose_ack``: sets of transmit numbers (0-based, counting every packet that
    reaches this peer's address) to lose on the way up / on the way back.
    ``rssi``: when set, empty acks are the 3-byte 2016-era form [F3|down, 01, rssi].
    """

    def __init__(self, channel: int = 80, address: bytes = b"\xe7\xe7\xe7\xe7\x01",
                 safelink_capable: bool = True, rssi: Optional[int] = None):
        self.channel = channel
        self.address = address
        self.safelink_capable = safelink_capable
        self.rssi = rssi
        self.safelink = False
        self.curr_up = 1
        self.curr_down = 1
        self.queue: Deque[bytes] = deque()
        self.last_payload: Optional[bytes] = None
        self.received: List[bytes] = []
        self.count = 0
        self.lose_uplink: set = set()
        self.lose_ack: set = set()
        self.on_packet: Optional[Callable[[bytes], None]] = None

    def hears(self, tx: Transmit) -> bool:
        return tx.channel == self.channel and tx.address == self.address

    def __call__(self, tx: Transmit) -> AirReply:
        if not self.hears(tx):
            return AirReply(False)
        n = self.count
        self.count += 1
        if n in self.lose_uplink:
            return AirReply(False)
        payload = self._receive(tx.data)
        if n in self.lose_ack:
            return AirReply(False)
        return AirReply(True, payload)

    def _empty(self) -> bytes:
        header = 0xF3 | (self.curr_down << 2)
        return bytes([header, 0x01, self.rssi]) if self.rssi is not None else bytes([header])

    def _receive(self, data: bytes) -> bytes:
        if (data[0] & 0xF3) == 0xF3 and len(data) == 3 and data[1] == 0x05 and self.safelink_capable:
            self.safelink = bool(data[2])
            self.curr_up = self.curr_down = 1
            self.last_payload = None
            return bytes(data)
        if not self.safelink:
            self._accept(data)
            self.curr_down ^= 1
            return self._next_downlink()
        if ((data[0] >> 3) & 1) != self.curr_up:
            self.curr_up ^= 1
            self._accept(data)
        if ((data[0] >> 2) & 1) != self.curr_down:
            self.curr_down ^= 1   # the last downlink packet was delivered: send the next one
            self.last_payload = self._next_downlink()
        elif self.last_payload is None:
            self.last_payload = self._next_downlink()
        return self.last_payload   # else: re-send the one the host has not confirmed

    def _accept(self, data: bytes) -> None:
        if (data[0] & 0xF3) == 0xF3 and len(data) == 1:
            return  # null packet
        self.received.append(bytes([data[0] & 0xF3]) + data[1:])
        if self.on_packet is not None:
            self.on_packet(data)

    def _next_downlink(self) -> bytes:
        if self.queue:
            raw = self.queue.popleft()
            return bytes([(raw[0] & 0xF3) | (self.curr_down << 2)]) + raw[1:]
        return self._empty()


class FakeClock:
    """time()/sleep() that never waits: sleeps are recorded and advance the time."""

    def __init__(self) -> None:
        self.now = 0.0
        self.sleeps: List[float] = []

    def time(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += seconds
