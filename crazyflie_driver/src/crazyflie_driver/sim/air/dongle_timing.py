"""How long the fake Crazyradio takes for each kind of USB transfer, and the clock it waits on.

Figures and their sources: docs/simulation.md, "Crazyradio timing".
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass


@dataclass
class DongleTiming:
    """Seconds the fake dongle takes for each kind of transfer (every figure a knob).

    An acked round trip (bulk OUT + IN) costs ``bulk_round_trip_s`` plus ``retransmission_s`` per
    retry the medium reports; an unacked one costs ARC retransmissions on top (about 2 ms at ARC 3).
    The medium's ``AirReply.latency_s`` is added to the round trip.
    """

    bulk_round_trip_s: float = 0.0008
    retransmission_s: float = 0.00067
    control_transfer_s: float = 0.0015

    @classmethod
    def instant(cls) -> "DongleTiming":
        """No modelled delay at all (unit tests, as-fast-as-possible simulation)."""
        return cls(0.0, 0.0, 0.0)


class RealClock:
    """Monotonic wall clock; ``sleep`` really sleeps."""

    time = staticmethod(_time.monotonic)
    sleep = staticmethod(_time.sleep)
