"""When to poll a Crazyflie for queued log packets while no setpoint is being sent.

Crazyflies sharing a dongle pay an address switch on almost every round trip, so an empty poll
after each log packet would cost as much dongle time as the data itself. The pacer times polls
to the rate the started log blocks produce packets (see ``log_plan.log_packet_rate``).
"""
from __future__ import annotations


class PollPacer:
    """When the next poll (null packet) should go out, from the log packets the Crazyflie is due to send.

    ``rate`` is the packets per second the started log blocks produce. The pacer keeps the count
    of packets due but not yet fetched (``backlog``: grows at ``rate``, one less per packet
    fetched, zero after an empty ack, since the Crazyflie's queue was empty then):

    * a poll that fetched a packet is followed at once while at least one more is due, and at
      least every ``DRAIN_INTERVAL`` s until an ack comes back empty (so a standing backlog,
      e.g. after the link was busy, never lingers: the data would be old when published);
    * after an empty ack the next poll is a ``keepalive_period`` later (10 ms: the firmware's
      shortest log period, so at most one packet per block can be queued by then);
    * otherwise it is timed for when the next packet should be there, ``MARGIN`` times faster
      than ``rate`` so a slow host clock never falls behind, and never later than
      ``keepalive_period``.

    Without log blocks (``rate`` 0) this is a plain keep-alive every ``keepalive_period``.

    ``margin`` below 1 (``SPARSE_MARGIN``, swarm mode: many Crazyflies on one dongle, a long
    ``keepalive_period``) times polls a little after each packet is due instead of before, so a slow
    log costs about one poll per packet (not an empty poll before each), at the price of its packets
    waiting up to one period onboard; the backlog count drains them when two are queued, and a
    standing backlog is cleared every ``SPARSE_DRAIN_INTERVAL``.
    """

    MARGIN = 1.3
    SPARSE_MARGIN = 1.0 / 1.02
    DRAIN_INTERVAL = 0.05
    SPARSE_DRAIN_INTERVAL = 1.0
    MAX_BURST = 8           # immediate polls in a row; a queued setpoint goes out in between anyway

    def __init__(self, keepalive_period: float, rate: float = 0.0, now: float = 0.0, margin: float = MARGIN) -> None:
        self.keepalive_period = keepalive_period
        self.margin = margin
        self.drain_interval = self.DRAIN_INTERVAL if margin >= 1.0 else self.SPARSE_DRAIN_INTERVAL
        self.rate = max(0.0, float(rate))
        self.backlog = 0.0
        self._at = now
        self._empty_at = now
        self._burst = 0

    def reset(self, rate: float, now: float) -> None:
        """New log blocks (after connecting or a restored link)."""
        self.rate = max(0.0, float(rate))
        self.backlog = 0.0
        self._at = self._empty_at = now
        self._burst = 0

    def after_round_trip(self, packets: int, now: float, others: int = 0) -> float:
        """Seconds until the next poll, after a round trip that fetched ``packets`` log packets and
        ``others`` other packets (parameter, memory, high-level replies: not foreseen by ``rate``, so
        more may be queued behind them: the next poll follows at once, within ``MAX_BURST``)."""
        self.backlog += self.rate * max(0.0, now - self._at)
        self._at = now
        if packets > 0:
            self.backlog = max(-1.0, self.backlog - packets)
        elif others == 0:
            self.backlog = 0.0
            self._empty_at = now
        self.backlog = min(self.backlog, 8.0)
        if (packets > 0 or others > 0) and self._burst < self.MAX_BURST and (
                others > 0 or self.backlog >= 1.0 or now - self._empty_at >= self.drain_interval):
            self._burst += 1
            return 0.0
        self._burst = 0
        if self.rate <= 0.0 or packets == 0:
            return self.keepalive_period
        return min(self.keepalive_period, max(0.0, (1.0 - self.backlog) / (self.rate * self.margin)))
