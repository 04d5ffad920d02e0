"""How long the fake Crazyradio takes for each kind of USB transfer, and the clock it waits on.

Figures and their sources: docs/simulation.md, "Crazyradio timing".
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from crazyflie_driver.clock import WALL, Clock, ScaledClock

#: Seconds one vendor request takes on a Crazyradio 2.0 (a user's measurement, docs/simulation.md).
CRAZYRADIO_2_CONTROL_TRANSFER_S = 0.0025
#: Seconds one radio packet sent without ack holds the dongle at 2 Mbit/s: the nRF24's 130 us TX
#: settling + a full ESB packet (1 + 5 + 32 + 2 bytes and a 9-bit control field, 329 bits: 165 us),
#: rounded up (nRF24L01+/nRF24LU1+ product specifications; docs/simulation.md, "Crazyradio timing").
NO_ACK_PACKET_S = 0.0003
#: Seconds of an acked round trip spent waiting for the ack: the Crazyflie's 130 us turnaround and
#: its ack packet (37-165 us at 2M, empty to full), about 0.2 ms (same sources).
ACK_WAIT_S = 0.0002


@dataclass
class DongleTiming:
    """Seconds the fake dongle takes for each kind of transfer (every figure a knob).

    An acked round trip (bulk OUT + IN) costs ``bulk_round_trip_s`` plus ``retransmission_s`` per
    retry the medium reports; an unacked one costs ARC retransmissions on top (about 2 ms at ARC 3).
    With acks off (a broadcast) there is no ack to wait for: on the legacy path no IN reply either,
    and the firmware takes the next OUT while the radio sends, so each radio packet costs its air time
    ``no_ack_packet_s``; in the 2.0's inline mode the IN reply still follows, so a packet costs the
    round trip without its ack wait (``bulk_round_trip_s - ack_wait_s``).
    The medium's ``AirReply.latency_s`` is added to the round trip.
    """

    bulk_round_trip_s: float = 0.0008
    retransmission_s: float = 0.00067
    control_transfer_s: float = 0.0015
    no_ack_packet_s: float = NO_ACK_PACKET_S
    ack_wait_s: float = ACK_WAIT_S

    @property
    def inline_no_ack_s(self) -> float:
        """One inline-mode OUT with acks off and its IN reply: the acked round trip minus the ack wait."""
        return max(0.0, self.bulk_round_trip_s - self.ack_wait_s)

    @classmethod
    def crazyradio_2(cls) -> DongleTiming:
        """The Crazyradio 2.0: the same bulk round trip, control transfers of about 2.5 ms (its
        setup requests go through the firmware's command queue; docs/simulation.md)."""
        return cls(control_transfer_s=CRAZYRADIO_2_CONTROL_TRANSFER_S)

    @classmethod
    def instant(cls) -> DongleTiming:
        """No modelled delay at all (unit tests, as-fast-as-possible simulation)."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0)


class DongleClock:
    """The clock a fake dongle times its transfers on (``time()`` and ``sleep(s)``), over a ``Clock``.

    By default the wall clock, as a real dongle. A dongle flying a world served by another process
    (``RemoteMedium``) runs in world time: ``DongleClock.world_paced(medium)``, so a transfer of
    0.8 ms takes 0.8 ms of world time, 0.8 ms / speed of wall time, and a radio budget means the same
    at any speed. At speed 1 that is the wall clock exactly.
    """

    def __init__(self, clock: Clock = WALL) -> None:
        self.clock = clock
        #: ``time()``: the clock's ``now`` itself (read twice per packet, so no call in between)
        self.time: Callable[[], float] = clock.now

    def sleep(self, seconds: float) -> None:
        self.clock.sleep(seconds)

    @classmethod
    def world_paced(cls, medium) -> DongleClock:
        """Paced by the world speed ``medium.speed`` that the world server's replies carry."""
        return cls(ScaledClock(lambda: medium.speed))
