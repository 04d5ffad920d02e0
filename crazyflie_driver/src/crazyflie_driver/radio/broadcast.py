"""Broadcasts: packets that every Crazyflie on a channel takes, sent without acks.

Each Crazyflie listens on its own address and on the fixed broadcast address 0xFFE7E7E7E7; a
packet to the latter is never acknowledged, so nothing comes back and nothing is retried. A
``BroadcastLink`` shares its dongle with the unicast links on it: a burst (all packets of one
``send_all``) is one turn of the dongle's FIFO, the way one unicast round trip is, and by default it
goes before the polls waiting there, as setpoints do; a stream of bursts (motion capture) only while
it leaves the unicast links their reserve of the dongle's time (``shared_radio.UNICAST_RESERVE``).
Where the dongle takes two packets per USB transfer, consecutive packets of the same length go out in pairs;
a Crazyradio 2.0 in inline mode gets each packet with the broadcast address and acks off in its header.
Idempotent commands are sent several times (``send_repeated``) because a broadcast can be lost.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, List, Optional, Sequence, Union

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.crtp.uri import RadioUri
from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.radio.crazyradio import DR_2MPS, MAX_RADIO_PACKET, Crazyradio
from crazyflie_driver.radio.shared_radio import RadioManager, SharedRadio, default_manager

BROADCAST_ADDRESS = b"\xff\xe7\xe7\xe7\xe7"
#: Copies of an idempotent command and the pause between them (s), as swarm servers send them.
DEFAULT_REPEATS = 15
DEFAULT_REPEAT_INTERVAL_S = 0.001

Packet = Union[CRTPPacket, bytes]


def _raw(packet: Packet) -> bytes:
    data = packet.to_bytes() if isinstance(packet, CRTPPacket) else bytes(packet)
    if not 0 < len(data) <= MAX_RADIO_PACKET:
        raise ValueError("a radio packet has 1-%d bytes, got %d" % (MAX_RADIO_PACKET, len(data)))
    return data


def pair_transfers(packets: Sequence[bytes], two_per_transfer: bool,
                   max_pair_bytes: int = 2 * MAX_RADIO_PACKET) -> List[bytes]:
    """The USB transfers for ``packets`` in order: consecutive packets of equal length joined in
    pairs (of at most ``max_pair_bytes``) when the dongle splits such transfers, else one packet per
    transfer.

    The splitting dongle firmware halves only a transfer longer than one radio packet (32 bytes), so
    two packets of 16 bytes or less joined would go out as one 32-byte packet: those stay single.
    """
    if not two_per_transfer:
        return list(packets)
    transfers = []
    i = 0
    while i < len(packets):
        if (i + 1 < len(packets) and len(packets[i]) == len(packets[i + 1])
                and MAX_RADIO_PACKET < 2 * len(packets[i]) <= max_pair_bytes):
            transfers.append(packets[i] + packets[i + 1])
            i += 2
        else:
            transfers.append(packets[i])
            i += 1
    return transfers


class BroadcastStatistics:
    """Counters of one broadcast link: radio packets, USB transfers, transfers the dongle did not take."""

    def __init__(self) -> None:
        self.packets = 0
        self.transfers = 0
        self.failed_transfers = 0

    def as_dict(self) -> dict:
        return {"packets": self.packets, "transfers": self.transfers, "failed_transfers": self.failed_transfers}


class BroadcastLink:
    """Broadcasts on one dongle, channel and data rate.

    ``sleep`` paces ``send_repeated`` (a world clock's sleep in simulations).
    """

    def __init__(self, index: int, channel: int, datarate: int = DR_2MPS, manager: Optional[RadioManager] = None,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if not 0 <= channel <= 125:
            raise CrazyflieError("broadcast channel must be 0..125, got %r" % (channel,))
        if datarate not in (0, 1, 2):
            raise CrazyflieError("broadcast data rate must be 0 (250K), 1 (1M) or 2 (2M), got %r" % (datarate,))
        self.index = index
        self.channel = channel
        self.datarate = datarate
        self.manager = manager if manager is not None else default_manager()
        self.stats = BroadcastStatistics()
        self._sleep = sleep
        self._shared: Optional[SharedRadio] = None
        self._lock = threading.Lock()

    @classmethod
    def for_uri(cls, uri: RadioUri, manager: Optional[RadioManager] = None, **options) -> BroadcastLink:
        """The broadcast link reaching the Crazyflie at ``uri`` (same dongle, channel and rate)."""
        return cls(uri.index, uri.channel, uri.datarate, manager, **options)

    @property
    def is_open(self) -> bool:
        return self._shared is not None

    @property
    def sends_inline(self) -> bool:
        """True when its dongle is a Crazyradio 2.0 with inline mode: the unicast links on it send inline,
        so its bursts go inline too and cost no control transfer (the radio budget plans with that)."""
        shared = self._shared
        radio = shared.radio if shared is not None else None
        return bool(radio is not None and radio.inline_capable)

    def open(self) -> None:
        """Take the dongle (opened if no other link uses it). Idempotent."""
        with self._lock:
            if self._shared is None:
                self._shared = self.manager.acquire(self.index)

    def close(self) -> None:
        """Give the dongle back. Idempotent."""
        with self._lock:
            shared, self._shared = self._shared, None
        if shared is not None:
            self.manager.release(shared)

    def __enter__(self) -> BroadcastLink:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def send(self, packet: Packet, urgent: bool = True) -> int:
        """One packet to every Crazyflie on the channel; returns the USB transfers made (0 or 1)."""
        return self.send_all([packet], urgent)

    def send_all(self, packets: Sequence[Packet], urgent: bool = True, capped: bool = False) -> int:
        """All ``packets`` in one turn of the dongle, paired where it can; returns the USB transfers
        the dongle took. ``urgent`` (the default: commands and motion capture steer Crazyflies in
        flight) goes before the unicast links' waiting polls, as setpoints do; ``capped`` (a stream
        such as motion capture) only within the share of the dongle that bursts may take while
        unicast round trips wait (``shared_radio.UNICAST_RESERVE``)."""
        raw = [_raw(p) for p in packets]
        if not raw:
            return 0
        shared = self._shared
        if shared is None:
            raise CrazyflieError("broadcast link on Crazyradio %d channel %d is not open" % (self.index, self.channel))
        channel, datarate = self.channel, self.datarate

        def burst(radio: Crazyradio) -> int:
            if radio.in_inline_mode:
                return self._inline_burst(radio, raw)
            if channel != radio.channel or datarate != radio.datarate or radio.address != BROADCAST_ADDRESS:
                radio.configure(channel, datarate, BROADCAST_ADDRESS)
            taken = 0
            for transfer in pair_transfers(raw, radio.two_per_transfer, radio.max_pair_bytes):
                if radio.send_no_ack(transfer):
                    taken += 1
                else:
                    self.stats.failed_transfers += 1
            return taken

        taken = shared.run(burst, urgent=urgent, capped=capped)
        self.stats.packets += len(raw)
        self.stats.transfers += taken
        return taken

    def _inline_burst(self, radio: Crazyradio, raw: Sequence[bytes]) -> int:
        """A burst on a Crazyradio 2.0 in inline mode (its unicast packets went inline): each packet
        carries the broadcast address with its ack flag off, so no control transfer leaves or re-enters
        inline mode; one packet per transfer, each answered by the firmware."""
        for packet in raw:
            radio.send_inline(self.channel, self.datarate, BROADCAST_ADDRESS, packet, ack=False)
        return len(raw)

    def send_repeated(self, packet: Packet, repeats: int = DEFAULT_REPEATS,
                      interval_s: float = DEFAULT_REPEAT_INTERVAL_S) -> int:
        """An idempotent command ``repeats`` times, ``interval_s`` apart, each copy its own turn of
        the dongle (unicast links keep flowing in between). Returns the transfers taken."""
        if repeats < 1:
            raise ValueError("repeats must be >= 1, got %r" % (repeats,))
        taken = 0
        for i in range(repeats):
            if i:
                self._sleep(interval_s)
            taken += self.send(packet)
        return taken

    def __repr__(self) -> str:
        return "<BroadcastLink radio %d channel %d %s>" % (self.index, self.channel,
                                                           "open" if self.is_open else "closed")
