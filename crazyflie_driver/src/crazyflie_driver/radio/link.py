"""The radio link to one Crazyflie over a shared Crazyradio.

``RadioLink`` does safelink (see docs/protocol.md, "Safelink") with a fallback to plain acks, dispatches
the downlink carried by the ack payloads, does request/reply with timeouts and keeps the link's
``LinkStatistics``. No thread of its own: a round trip happens in the thread that calls
``send``/``poll``/``request``, and downlink callbacks run there.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Callable, Dict, Optional, Tuple, Union

from crazyflie_driver.clock import WALL, Clock
from crazyflie_driver.crtp.nrf_system import SYS_RESET, is_nrf_command
from crazyflie_driver.crtp.packet import MAX_PAYLOAD, CRTPPacket
from crazyflie_driver.crtp.uri import RadioUri, parse_uri
from crazyflie_driver.errors import CommandValueError, CrazyflieError, LinkTimeout
from crazyflie_driver.radio.crazyradio import RadioAck
from crazyflie_driver.radio.shared_radio import RadioManager, SharedRadio, default_manager
from crazyflie_driver.radio.statistics import DEFAULT_LOST_THRESHOLD, LinkStatistics

_log = logging.getLogger(__name__)
# Times each round trip for the link statistics: host and USB time of one exchange, on the wall
# clock (a round trip lasts well under a millisecond; a clock following /clock cannot resolve it).
_now = time.perf_counter

SAFELINK_ON = b"\xff\x05\x01"
NULL_PACKET = b"\xff"
#: Packets a Crazyflie's transmit queue can hold ahead of an answer (the simulated firmware's CRTP
#: TX queue; see docs). A request whose answer is queued behind log data waits while packets keep
#: arriving, until this many drained after it.
TX_QUEUE_PACKETS = 200
# Every one-byte packet (a header alone, e.g. a null packet with safelink bits) preallocated.
_ONE_BYTE = tuple(bytes((h,)) for h in range(256))

Callback = Callable[[CRTPPacket], None]


class _Waiter:
    __slots__ = ("match", "result", "error")

    def __init__(self, match: Callable[[CRTPPacket], bool]):
        self.match = match
        self.result: Optional[CRTPPacket] = None
        self.error: Optional[BaseException] = None


class RadioLink:
    """The link to one Crazyflie (contract in docs/architecture.md).

    ``safelink``: try the safelink handshake on open (``safelink_attempts`` tries). In safelink
    mode an unacked packet is re-sent with the same sequence bit up to ``safelink_resends`` times;
    if it still fails, the next packet first redoes the handshake so both sides agree again.
    Thread-safe: round trips of one link are serialised, so its downlink is dispatched in order.
    ``clock`` times the requests' timeouts (the world's time in a simulation).
    """

    def __init__(self, uri: Union[str, RadioUri], manager: Optional[RadioManager] = None,
                 safelink: bool = True, safelink_attempts: int = 10, safelink_resends: int = 10,
                 lost_threshold: int = DEFAULT_LOST_THRESHOLD, clock: Clock = WALL):
        self.uri: RadioUri = parse_uri(uri) if isinstance(uri, str) else uri
        self.manager = manager if manager is not None else default_manager()
        self.stats = LinkStatistics(lost_threshold)
        self.clock = clock
        self.downlink_packets = 0       # non-empty downlink packets received (progress of a request)
        self.use_safelink = safelink
        self.safelink_attempts = safelink_attempts
        self.safelink_resends = safelink_resends
        self.safelink = False          # True once the Crazyflie echoed the handshake
        self._up = 0
        self._down = 0
        self._resync = False
        self._shared: Optional[SharedRadio] = None
        self._send_lock = threading.RLock()
        self._request_lock = threading.Lock()
        self._subs_lock = threading.Lock()
        self._subs: Dict[int, Tuple[Tuple[Optional[int], Callback], ...]] = {}
        self._unclaimed: Optional[Callback] = None
        self._waiter: Optional[_Waiter] = None

    @property
    def needs_resending(self) -> bool:
        """True without safelink: replies may be lost, so requests are re-sent."""
        return not self.safelink

    @property
    def is_open(self) -> bool:
        return self._shared is not None

    # -- open / close -------------------------------------------------------------------------------
    def open(self) -> None:
        """Take the dongle and greet the Crazyflie: safelink if it echoes, else plain acks.

        Raises LinkTimeout when not one greeting packet is acked (no Crazyflie there).
        """
        with self._send_lock:
            if self._shared is not None:
                return
            self._shared = self.manager.acquire(self.uri.index)
            try:
                self._greet()
            except BaseException:
                shared, self._shared = self._shared, None
                self.manager.release(shared)
                raise

    def _greet(self) -> None:
        attempts = max(1, self.safelink_attempts)
        packet = SAFELINK_ON if self.use_safelink else NULL_PACKET
        any_ack = False
        for _ in range(attempts):
            ack = self._round_trip(packet)
            if not ack.ack:
                continue
            any_ack = True
            if not self.use_safelink:
                if ack.data:
                    self._dispatch(ack.data)
                return
            if ack.data == SAFELINK_ON:
                self.safelink = True
                self._up = self._down = 0
                return
            if ack.data:
                self._dispatch(ack.data)   # no safelink there: a plain downlink packet
        if not any_ack:
            raise LinkTimeout("%s: no answer from the Crazyflie (%d packets unacknowledged); is it "
                              "switched on, and on this channel, data rate and address?"
                              % (self.uri, attempts), acked=0)
        self.safelink = False

    def close(self) -> None:
        """Give the dongle back (closed when no other link uses it). Idempotent."""
        with self._send_lock:
            shared, self._shared = self._shared, None
            self.safelink = False
        if shared is not None:
            self.manager.release(shared)

    def __enter__(self) -> RadioLink:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- round trips ------------------------------------------------------------------------------
    def _round_trip(self, data: bytes, background: bool = False) -> RadioAck:
        shared = self._shared
        if shared is None:
            raise CrazyflieError("%s: link is not open" % (self.uri,))
        uri = self.uri
        started = _now()
        ack = shared.round_trip(uri.channel, uri.datarate, uri.address, data, background)
        self.stats.record(ack.ack, ack.retries, _now() - started)
        return ack

    def send(self, packet: CRTPPacket) -> bool:
        """One packet to the Crazyflie (re-sent on loss with safelink); True when acked.

        Downlink packets carried by the ack are dispatched before it returns. Raises RadioUnplugged.
        """
        return self.send_bytes(packet.to_bytes())

    def poll(self, background: bool = False) -> bool:
        """A null packet round trip: fetches downlink and keeps the link alive. ``background`` (an idle
        keep-alive nobody waits for) lets every other round trip waiting for the dongle go first."""
        return self.send_bytes(NULL_PACKET, background)

    def send_bytes(self, data: bytes, background: bool = False) -> bool:
        """``send`` for a raw packet (header byte + payload); safelink bits are set here."""
        if not 1 <= len(data) <= 1 + MAX_PAYLOAD:
            raise CommandValueError("%s: a CRTP packet is a header byte and 0..%d payload bytes, got %d bytes%s"
                                    % (self.uri, MAX_PAYLOAD, len(data),
                                       " (a null packet is b'\\xff')" if not data else ""))
        with self._send_lock:
            if not self.safelink:
                ack = self._round_trip(data, background)
                if ack.ack and ack.data:
                    self._dispatch(ack.data)
                return ack.ack
            if self._resync and not self._resync_safelink():
                return False
            header = (data[0] & 0xF3) | (self._up << 3) | (self._down << 2)
            out = _ONE_BYTE[header] if len(data) == 1 else _ONE_BYTE[header] + data[1:]
            for _ in range(self.safelink_resends + 1):
                ack = self._round_trip(out, background)
                if ack.ack:
                    self._up ^= 1
                    payload = ack.data
                    if payload and (payload[0] & 0x04) == (self._down << 2):
                        self._down ^= 1
                        self._dispatch(payload)
                    # else: a repeat of the last downlink packet (our ack of it was lost): drop it
                    return True
            self._resync = True
            return False

    def send_nrf_command(self, data: bytes, attempts: int = 10) -> bool:
        """One nRF system command (``crtp.nrf_system``) until acked, at most ``attempts`` times; True when
        acked. It bypasses safelink (the nRF takes it before the sequence check); after a reset the
        nRF has forgotten safelink, so the next packet negotiates it again."""
        if not is_nrf_command(data):
            raise CommandValueError("%s: not an nRF system command: %s" % (self.uri, bytes(data).hex(" ")))
        with self._send_lock:
            for _ in range(max(1, attempts)):
                if self._round_trip(bytes(data)).ack:
                    if data[2] == SYS_RESET and self.safelink:
                        self._resync = True
                    return True
            return False

    def exchange_raw(self, data: bytes) -> Optional[bytes]:
        """One raw radio payload outside CRTP and safelink (the bootloaders' packets); the ack's payload,
        or None when no ack came."""
        with self._send_lock:
            ack = self._round_trip(bytes(data))
            return bytes(ack.data) if ack.ack else None

    def _resync_safelink(self) -> bool:
        ack = self._round_trip(SAFELINK_ON)
        if ack.ack and ack.data == SAFELINK_ON:
            self._up = self._down = 0
            self._resync = False
            return True
        return False

    # -- downlink ---------------------------------------------------------------------------------
    def _dispatch(self, payload: bytes) -> None:
        header = payload[0]
        if (header & 0xF3) == 0xF3:
            # Empty ack; the 2016-era nRF firmware appends [0x01, RSSI].
            if len(payload) >= 3 and payload[1] == 0x01:
                self.stats.rssi = payload[2]
            return
        self.downlink_packets += 1
        port = header >> 4
        subs = self._subs.get(port)
        waiter = self._waiter
        if subs is None and waiter is None and self._unclaimed is None:
            return
        packet = CRTPPacket(port, header & 0x03, payload[1:])
        claimed = waiter is not None and self._offer(waiter, packet)
        if subs:
            self._hand_subscribers(subs, packet)
        elif not claimed:
            self._hand_unclaimed(packet)

    @staticmethod
    def _offer(waiter: _Waiter, packet: CRTPPacket) -> bool:
        """Whether the waiting request takes ``packet`` (its answer)."""
        if waiter.result is not None:
            return False
        try:
            if waiter.match(packet):
                waiter.result = packet
                return True
        except Exception as exc:   # the requester's bug: re-raised in its own thread
            waiter.error = exc
        return False

    def _hand_subscribers(self, subs: Tuple[Tuple[Optional[int], Callback], ...], packet: CRTPPacket) -> None:
        channel = packet.channel
        for want, callback in subs:
            if want is None or want == channel:
                try:
                    callback(packet)
                except Exception:
                    _log.exception("%s: downlink callback %r failed on %r", self.uri, callback, packet)

    def on_unclaimed(self, callback: Optional[Callback]) -> None:
        """Call ``callback(packet)`` for each downlink packet no subscriber and no request took (the
        original driver's ``packets`` topic); None: no more. Same thread rules as ``subscribe``."""
        self._unclaimed = callback

    def _hand_unclaimed(self, packet: CRTPPacket) -> None:
        callback = self._unclaimed
        if callback is None:
            return
        try:
            callback(packet)
        except Exception:
            _log.exception("%s: unclaimed-packet callback failed on %r", self.uri, packet)

    def subscribe(self, port: int, channel: Optional[int], callback: Callback) -> Callable[[], None]:
        """Call ``callback(packet)`` for each downlink packet on ``port`` (any channel if None).

        Callbacks run in the thread that made the round trip; they may ``send`` but must not
        ``request``. Returns the unsubscribe function.
        """
        if not 0 <= port <= 15:
            raise ValueError("port must be 0..15, got %r" % (port,))
        if channel is not None and not 0 <= channel <= 3:
            raise ValueError("channel must be 0..3 or None, got %r" % (channel,))
        entry = (channel, callback)
        with self._subs_lock:
            self._subs[port] = self._subs.get(port, ()) + (entry,)

        def unsubscribe() -> None:
            with self._subs_lock:
                current = self._subs.get(port, ())
                remaining = tuple(e for e in current if e is not entry)
                if remaining:
                    self._subs[port] = remaining
                else:
                    self._subs.pop(port, None)

        return unsubscribe

    def request(self, packet: CRTPPacket, match: Callable[[CRTPPacket], bool], timeout: float = 1.0,
                resend_interval: float = 0.2, what: str = "") -> CRTPPacket:
        """Send ``packet``, then poll until a downlink packet satisfies ``match``; return it.

        Without safelink the packet is re-sent every ``resend_interval`` s (the reply may have been
        lost); with safelink only while it is unacked. The matching packet also reaches subscribers.
        ``timeout`` is the longest silence: while other downlink packets keep arriving (the answer
        is queued behind log data in the Crazyflie's transmit queue) the wait goes on, until up to
        twice ``TX_QUEUE_PACKETS`` have drained, so the time follows the link's round-trip time and
        the queue's depth. Raises LinkTimeout naming the URI and ``what``.
        """
        if timeout <= 0:
            raise ValueError("timeout must be > 0, got %r" % (timeout,))
        with self._request_lock:
            waiter = _Waiter(match)
            self._waiter = waiter
            try:
                start = self.clock.now()
                sent0, acked0 = self.stats.sent, self.stats.acked
                first_packet = self.downlink_packets
                seen, last_data = first_packet, start
                acked: int = self.send(packet)   # then the count acked since
                next_resend = start + resend_interval
                while waiter.result is None:
                    if waiter.error is not None:
                        raise waiter.error
                    now = self.clock.now()
                    if self.downlink_packets != seen:
                        seen, last_data = self.downlink_packets, now
                    drained = seen - first_packet
                    if now - last_data >= timeout or (now - start >= timeout and drained > 2 * TX_QUEUE_PACKETS):
                        acked = self.stats.acked - acked0
                        raise LinkTimeout(self._no_answer(what or repr(packet), now - start, drained, acked,
                                                          self.stats.sent - sent0), acked=acked)
                    if self.safelink:
                        resend = not acked
                    else:
                        resend = self.needs_resending and now >= next_resend
                    if resend:
                        acked = self.send(packet)
                        next_resend = now + resend_interval
                    else:
                        self.poll()
                if waiter.error is not None:
                    raise waiter.error
                return waiter.result
            finally:
                self._waiter = None

    def _no_answer(self, what: str, waited: float, drained: int, acked: int, sent: int) -> str:
        """Why a request went unanswered, as far as the round trips meanwhile tell."""
        text = "%s: no answer to %s within %.2f s (%d of %d packets acknowledged, %d other packets received)" % (
            self.uri, what, waited, acked, sent, drained)
        if acked == 0:
            return text + "; is the Crazyflie switched on, in range, and on this channel, data rate and address?"
        if acked < 0.9 * sent:
            return text + ("; the link is poor: move the Crazyradio closer, or choose a channel with less "
                           "interference")
        return text + ("; the Crazyflie acknowledges but its answer never came: most likely another program "
                       "(crazyflie_server, a tool) is talking to it at the same time, through this or another "
                       "Crazyradio, and takes its answers. Stop that program, or go through it (with "
                       "crazyflie_server running: its parameters are on the ROS parameter server, update_params "
                       "writes them). Otherwise its firmware does not answer this request")

    def __repr__(self) -> str:
        return "<RadioLink %s %s>" % (self.uri, "safelink" if self.safelink else
                                       ("plain" if self.is_open else "closed"))


def open_link(uri: Union[str, RadioUri], manager: Optional[RadioManager] = None, **options) -> RadioLink:
    """A new ``RadioLink`` on ``manager`` (the process-wide one if None), already opened."""
    link = RadioLink(uri, manager, **options)
    link.open()
    return link
