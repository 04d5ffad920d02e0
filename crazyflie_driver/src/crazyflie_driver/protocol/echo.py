"""Port 15 channel 0 (echo): the Crazyflie returns every packet unchanged, so a numbered echo
measures the link's round trip and loss end to end (radio, nRF, STM and back), as HEAD's comCheck did.
"""
from __future__ import annotations

import struct
import time
from typing import Callable, List, NamedTuple, Optional, Sequence

from crazyflie_driver.crtp.packet import PORT_LINK, CRTPPacket
from crazyflie_driver.errors import LinkTimeout

CH_ECHO = 0
_SEQ = struct.Struct("<I")
Request = Callable[..., CRTPPacket]


def echo_packet(seq: int, size: int = _SEQ.size) -> CRTPPacket:
    """An echo request carrying ``seq`` (u32) padded to ``size`` bytes (4..30)."""
    if not _SEQ.size <= size <= 30:
        raise ValueError("an echo packet carries 4..30 bytes, got %d" % size)
    return CRTPPacket(PORT_LINK, CH_ECHO, _SEQ.pack(seq & 0xFFFFFFFF).ljust(size, b"\x00"))


class EchoSummary(NamedTuple):
    sent: int
    answered: int
    min_s: float
    mean_s: float
    max_s: float

    @property
    def lost(self) -> int:
        return self.sent - self.answered


def summarize(round_trips: Sequence[Optional[float]]) -> EchoSummary:
    """Counts and min/mean/max [s] of the answered round trips (None: no answer)."""
    got = [t for t in round_trips if t is not None]
    if not got:
        return EchoSummary(len(round_trips), 0, 0.0, 0.0, 0.0)
    return EchoSummary(len(round_trips), len(got), min(got), sum(got) / len(got), max(got))


def echo_round_trips(request: Request, count: int, size: int = _SEQ.size, timeout: float = 1.0,
                     clock: Callable[[], float] = time.monotonic) -> List[Optional[float]]:
    """Round trip [s] of ``count`` numbered echoes, one at a time; None for an echo that never came
    back within ``timeout`` (the check goes on: a lossy link is what it measures)."""
    out: List[Optional[float]] = []
    for seq in range(count):
        packet = echo_packet(seq, size)
        started = clock()
        try:
            request(packet, match=lambda p, d=packet.data: p.port == PORT_LINK and p.channel == CH_ECHO
                    and p.data == d, timeout=timeout, what="echo %d (15:0)" % seq)
        except LinkTimeout:
            out.append(None)
            continue
        out.append(clock() - started)
    return out
