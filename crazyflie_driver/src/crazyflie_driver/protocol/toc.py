"""Table of contents (TOC) download for the parameter and log ports.

Both ports describe their variables the same way: an info request gives the
item count and a CRC, then each item is asked for by id, one request in
flight. Protocol V1 (firmware before protocol version 4) uses 8-bit ids and
commands 0/1; V2 uses 16-bit ids and commands 2/3. :class:`TocPortClient` is
the part the parameter and log clients share: a port's TOC, fetched on demand.
"""
from __future__ import annotations

import logging
import struct
import threading
import time
from dataclasses import dataclass
from typing import Callable, Dict, Iterator, List, Optional, Sequence, Tuple

from crazyflie_driver.crtp.ctypes import BY_LOG_CODE, BY_PARAM_CODE
from crazyflie_driver.crtp.firmware_limits import TOC_NAME_MAX_BYTES
from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import LinkTimeout, ProtocolError, UnknownName
from crazyflie_driver.protocol.platform import toc_version

_LOG = logging.getLogger(__name__)

CMD_GET_ITEM_V1 = 0
CMD_GET_INFO_V1 = 1
CMD_GET_ITEM_V2 = 2
CMD_GET_INFO_V2 = 3

PARAM_READONLY = 0x40

#: Requests in flight at once when many items are read (TOC items, parameter values): the answer
#: to one rides back in the ack of the next request instead of costing a null-packet round trip of
#: its own, so a real-size table (~1000 items) takes about half the round trips. Kept small: the
#: firmware queues the answers, and one lost request costs a resend interval.
PIPELINE_DEPTH = 4
#: Seconds before an unanswered request of a pipelined batch is sent again.
PIPELINE_RESEND_S = 0.2

# One download per table (cache file) at a time in this process: a swarm's Crazyflies run the same
# build, so while one downloads a table the others with the same CRC wait and then read the cache.
_DOWNLOADS_LOCK = threading.Lock()
_DOWNLOADS: Dict[str, threading.Lock] = {}


def _download_lock(key: str) -> threading.Lock:
    with _DOWNLOADS_LOCK:
        return _DOWNLOADS.setdefault(key, threading.Lock())


@dataclass(frozen=True)
class TocEntry:
    """One parameter or log variable. ``readonly`` is meaningful for parameters only."""

    ident: int
    group: str
    name: str
    ctype: str
    readonly: bool = False

    @property
    def full_name(self) -> str:
        return "%s.%s" % (self.group, self.name)


@dataclass(frozen=True)
class TocInfo:
    """Answer to a TOC info request. ``max_blocks``/``max_ops`` come with the log TOC only."""

    count: int
    crc: int
    max_blocks: Optional[int] = None
    max_ops: Optional[int] = None


class Toc:
    """The downloaded table: entries by id and by ``group.name``."""

    def __init__(self, entries: List[TocEntry], crc: int = 0) -> None:
        self.entries = sorted(entries, key=lambda e: e.ident)
        self.crc = crc
        self._by_name: Dict[str, TocEntry] = {e.full_name: e for e in self.entries}
        self._by_id: Dict[int, TocEntry] = {e.ident: e for e in self.entries}

    def __iter__(self) -> Iterator[TocEntry]:
        return iter(self.entries)

    def __len__(self) -> int:
        return len(self.entries)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def find(self, name: str) -> Optional[TocEntry]:
        return self._by_name.get(name)

    def by_id(self, ident: int) -> Optional[TocEntry]:
        return self._by_id.get(ident)

    def lookup(self, name: str, kind: str = "variable") -> TocEntry:
        """The entry called ``group.name``; UnknownName (naming it) when absent."""
        entry = self._by_name.get(name)
        if entry is None:
            hint = ""
            if "." not in str(name):
                hint = " (names are written group.name)"
            raise UnknownName("unknown %s %r: not in the Crazyflie's TOC%s" % (kind, name, hint))
        return entry


def check_toc_name(full_name: object, kind: str = "variable") -> str:
    """``group.name`` of a parameter or log variable, checked against what a TOC entry can be
    before anything is sent: one ``.``, both parts non-empty printable ASCII without space, ``.`` or
    ``/`` (a NUL would end the name on the Crazyflie), ``group NUL name NUL`` within the firmware's
    TOC_NAME_MAX_BYTES. UnknownName naming the name and the rule; returns the name."""
    if not isinstance(full_name, str):
        raise UnknownName("unknown %s %r: a name is text" % (kind, full_name))
    group, dot, name = full_name.partition(".")
    if not dot or not group or not name:
        raise UnknownName("unknown %s %r: not of the form group.name" % (kind, full_name))
    for i, c in enumerate(full_name):
        if not ("!" <= c <= "~") or (c in "./" and i != len(group)):
            raise UnknownName("unknown %s %r: it holds %s at position %d; names on a Crazyflie are printable ASCII "
                              "without spaces, '.' only between group and name" % (
                                  kind, full_name, "a NUL character" if c == "\0" else "character %r" % c, i))
    if len(group) + len(name) + 2 > TOC_NAME_MAX_BYTES:
        raise UnknownName("unknown %s %r: %d characters long; the firmware's TOC names (group and name with their "
                          "NULs) are at most %d bytes" % (kind, full_name, len(full_name), TOC_NAME_MAX_BYTES))
    return full_name


def toc_types(toc: Optional[Toc]) -> Dict[str, str]:
    """``{"group.name": ctype}`` of a TOC ({} before it is fetched)."""
    return {} if toc is None else {e.full_name: e.ctype for e in toc}


def parse_item(kind: str, version: int, data: bytes) -> TocEntry:
    """Decode a GET_ITEM reply payload (command byte included)."""
    if version >= 2:
        if len(data) < 4:
            raise ProtocolError("%s TOC item reply too short: %s" % (kind, data.hex(" ")))
        ident = data[1] | (data[2] << 8)
        type_byte = data[3]
        rest = data[4:]
    else:
        if len(data) < 3:
            raise ProtocolError("%s TOC item reply too short: %s" % (kind, data.hex(" ")))
        ident = data[1]
        type_byte = data[2]
        rest = data[3:]
    parts = rest.split(b"\x00")
    if len(parts) < 3:
        raise ProtocolError("%s TOC item %d: group and name are not NUL-terminated: %s"
                            % (kind, ident, data.hex(" ")))
    try:
        group = parts[0].decode("ascii")
        name = parts[1].decode("ascii")
    except UnicodeDecodeError:
        raise ProtocolError("%s TOC item %d: name is not ASCII: %s" % (kind, ident, data.hex(" "))) from None
    if kind == "param":
        ct = BY_PARAM_CODE.get(type_byte & 0x0F)
        readonly = bool(type_byte & PARAM_READONLY)
    else:
        ct = BY_LOG_CODE.get(type_byte & 0x0F)
        readonly = False
    if ct is None:
        raise ProtocolError("%s TOC item %d (%s.%s): unknown type byte 0x%02X"
                            % (kind, ident, group, name, type_byte))
    return TocEntry(ident, group, name, ct.name, readonly)


def request_all(link, requests: Sequence[Tuple[bytes, CRTPPacket]], port: int, channel: int,
                key_of: Callable[[CRTPPacket], Optional[bytes]], timeout: float, what: Callable[[bytes], str],
                refused: Optional[Callable[[bytes], str]] = None,
                depth: int = PIPELINE_DEPTH) -> Dict[bytes, CRTPPacket]:
    """Send ``requests`` (key, packet) with up to ``depth`` in flight and collect the answer to each.

    ``key_of(reply)`` names the request a downlink packet on ``port``/``channel`` answers (None: not
    an answer; b"": an error reply that names no request, raised as ProtocolError ``refused(key)`` of the
    oldest unanswered request, since the firmware answers in order). A
    request unanswered for PIPELINE_RESEND_S is sent again (the answers are idempotent reads);
    LinkTimeout when nothing at all arrives for ``timeout`` s. Returns the answers by key.
    """
    pipeline = _Pipeline(link, requests, key_of, timeout, what, refused, depth)
    unsubscribe = link.subscribe(port, channel, pipeline.on_packet)
    try:
        return pipeline.run()
    finally:
        unsubscribe()


class _Pipeline:
    """One ``request_all``: the requests still to send, those in flight with the time each was sent,
    the answers (filled from the link's receive path, hence the lock) and the time of the last progress."""

    def __init__(self, link, requests: Sequence[Tuple[bytes, CRTPPacket]],
                 key_of: Callable[[CRTPPacket], Optional[bytes]], timeout: float, what: Callable[[bytes], str],
                 refused: Optional[Callable[[bytes], str]], depth: int) -> None:
        self.link = link
        self.requests = requests
        self.key_of = key_of
        self.timeout = timeout
        self.what = what
        self.refused = refused
        self.depth = depth
        self.answers: Dict[bytes, CRTPPacket] = {}
        self._wanted = {key for key, _ in requests} | {b""}
        self._lock = threading.Lock()
        self._clock: Callable[[], float] = getattr(getattr(link, "clock", None), "now", time.monotonic)
        self._pending = list(reversed(requests))       # the next to send last
        self._in_flight: Dict[bytes, List] = {}      # key -> [packet, time sent]
        self._last_progress = 0.0
        self._seen: Tuple[int, int] = (0, 0)

    def on_packet(self, packet: CRTPPacket) -> None:
        key = self.key_of(packet)
        if key in self._wanted:
            with self._lock:
                self.answers.setdefault(key, packet)

    def run(self) -> Dict[bytes, CRTPPacket]:
        self._last_progress = self._clock()
        self._seen = self._progress()
        while self._pending or self._in_flight:
            now = self._clock()
            self._drop_answered()
            self._raise_if_refused()
            self._raise_if_stalled(now)
            if self._pending and len(self._in_flight) < self.depth:
                self._send_next(now)
            elif self._in_flight:
                self._resend_oldest_or_poll(now)
        return self.answers

    def _progress(self) -> Tuple[int, int]:
        """Answers so far and downlink packets so far: either moving counts as progress."""
        return len(self.answers), getattr(self.link, "downlink_packets", 0)

    def _drop_answered(self) -> None:
        with self._lock:
            for key in [k for k in self._in_flight if k in self.answers]:
                del self._in_flight[key]

    def _raise_if_refused(self) -> None:
        if b"" in self.answers:
            key = next(iter(self._in_flight), b"")
            raise ProtocolError("%s: %s" % (self.link.uri,
                                             self.refused(key) if self.refused else "a request was refused"))

    def _raise_if_stalled(self, now: float) -> None:
        progress = self._progress()
        if progress != self._seen:
            self._seen, self._last_progress = progress, now
        elif now - self._last_progress >= self.timeout:
            key = next(iter(self._in_flight)) if self._in_flight else self._pending[-1][0]
            raise LinkTimeout("%s: no answer to %s within %.2f s (%d of %d answered)"
                              % (self.link.uri, self.what(key), now - self._last_progress, len(self.answers),
                                 len(self.requests)))

    def _send_next(self, now: float) -> None:
        key, packet = self._pending.pop()
        if key not in self.answers:
            self._in_flight[key] = [packet, now]
            self.link.send(packet)

    def _resend_oldest_or_poll(self, now: float) -> None:
        oldest = min(self._in_flight, key=lambda k: self._in_flight[k][1])
        if now - self._in_flight[oldest][1] >= PIPELINE_RESEND_S:
            self._in_flight[oldest][1] = now
            self.link.send(self._in_flight[oldest][0])
        else:
            self.link.poll()


class TocFetcher:
    """Downloads one port's TOC over a link, using an optional cache keyed by CRC.

    ``kind`` is "param" or "log"; ``version`` is the TOC generation (1 or 2).
    """

    def __init__(self, link, port: int, kind: str, version: int, timeout: float = 1.0,
                 cache=None) -> None:
        self.link = link
        self.port = port
        self.kind = kind
        self.version = version
        self.timeout = timeout
        self.cache = cache
        self._label = "parameter" if kind == "param" else "log"

    def fetch_info(self) -> TocInfo:
        """Ask for the item count and CRC (and, for the log TOC, the block/op limits)."""
        cmd = CMD_GET_INFO_V2 if self.version >= 2 else CMD_GET_INFO_V1
        reply = self.link.request(
            CRTPPacket(self.port, 0, bytes([cmd])),
            match=lambda p: p.port == self.port and p.channel == 0 and p.data[:1] == bytes([cmd]),
            timeout=self.timeout, what="%s TOC info" % self._label)
        data = reply.data
        try:
            if self.version >= 2:
                count, crc = struct.unpack_from("<HI", data, 1)
                extra = data[7:9]
            else:
                count, crc = struct.unpack_from("<BI", data, 1)
                extra = data[6:8]
        except struct.error:
            raise ProtocolError("%s: %s TOC info reply too short: %s"
                                % (self.link.uri, self._label, data.hex(" "))) from None
        if len(extra) == 2:
            return TocInfo(count, crc, extra[0], extra[1])
        return TocInfo(count, crc)

    def fetch_item(self, ident: int) -> TocEntry:
        """Ask for one item by id."""
        if self.version >= 2:
            cmd = CMD_GET_ITEM_V2
            request = bytes([cmd, ident & 0xFF, ident >> 8])
            id_bytes = request[1:3]
        else:
            cmd = CMD_GET_ITEM_V1
            request = bytes([cmd, ident])
            id_bytes = request[1:2]
        n = len(id_bytes)

        def match(p: CRTPPacket) -> bool:
            if p.port != self.port or p.channel != 0 or p.data[:1] != bytes([cmd]):
                return False
            return len(p.data) == 1 or p.data[1:1 + n] == id_bytes

        reply = self.link.request(CRTPPacket(self.port, 0, request), match=match,
                                  timeout=self.timeout,
                                  what="%s TOC item %d" % (self._label, ident))
        if len(reply.data) == 1:
            raise ProtocolError("%s: %s TOC item %d is out of range although the TOC info "
                                "announced it" % (self.link.uri, self._label, ident))
        return parse_item(self.kind, self.version, reply.data)

    def fetch_items(self, count: int) -> List[TocEntry]:
        """Items 0..count-1, several requests in flight (``request_all``)."""
        v2 = self.version >= 2
        cmd = CMD_GET_ITEM_V2 if v2 else CMD_GET_ITEM_V1
        n = 2 if v2 else 1
        keys = [struct.pack("<H", i) if v2 else bytes([i]) for i in range(count)]
        requests = [(k, CRTPPacket(self.port, 0, bytes([cmd]) + k)) for k in keys]

        def key_of(p: CRTPPacket) -> Optional[bytes]:
            if p.data[:1] != bytes([cmd]):
                return None
            return b"" if len(p.data) == 1 else bytes(p.data[1:1 + n])

        answers = request_all(self.link, requests, self.port, 0, key_of, self.timeout,
                              lambda k: "%s TOC item %d" % (self._label, int.from_bytes(k, "little")),
                              refused=lambda k: "%s TOC item %d is out of range although the TOC info announced "
                              "%d items" % (self._label, int.from_bytes(k, "little"), count))
        return [parse_item(self.kind, self.version, answers[key].data) for key in keys]

    def fetch(self) -> tuple[Toc, TocInfo]:
        """The whole TOC: from the cache when its CRC is known, else item by item."""
        info = self.fetch_info()
        if self.cache is None:
            return Toc(self.fetch_items(info.count), info.crc), info
        entries = self._cached(info)
        if entries is None:
            with _download_lock(self.cache.path(self.kind, info.crc)):   # another Crazyflie may be fetching it
                entries = self._cached(info)
                if entries is None:
                    entries = self.fetch_items(info.count)
                    self.cache.store(self.kind, info.crc, entries)
        return Toc(entries, info.crc), info

    def _cached(self, info: TocInfo) -> Optional[List[TocEntry]]:
        entries = self.cache.load(self.kind, info.crc, info.count)
        if entries is not None:
            _LOG.debug("%s: %s TOC 0x%08X from cache", self.link.uri, self.kind, info.crc)
        return entries


class TocPortClient:
    """Base of the parameter and log clients: the link, the port's TOC and the request lock.

    The Crazyflie facade sets ``protocol_version`` once it knows it; ``version`` (1 or 2) is
    the TOC generation that follows from it. The TOC is fetched on first use.
    """

    def __init__(self, link, port: int, kind: str, cache=None, timeout: float = 1.0) -> None:
        self.link = link
        self.cache = cache
        self.timeout = timeout
        self.protocol_version = -1
        self.toc: Optional[Toc] = None
        self._toc_port = port
        self._toc_kind = kind
        self._lock = threading.RLock()

    @property
    def version(self) -> int:
        """TOC and value format generation in use (1 or 2)."""
        return toc_version(self.protocol_version)

    def _download_toc(self) -> TocInfo:
        """Fetch the TOC (or take it from the cache) into ``self.toc``; returns the TOC info."""
        with self._lock:
            fetcher = TocFetcher(self.link, self._toc_port, self._toc_kind, self.version,
                                 self.timeout, self.cache)
            self.toc, info = fetcher.fetch()
            return info

    def _ensure_toc(self) -> Toc:
        if self.toc is None:
            self.fetch_toc()
        assert self.toc is not None
        return self.toc

    def fetch_toc(self) -> List[TocEntry]:
        """Download the TOC (or take it from the cache)."""
        with self._lock:
            self._download_toc()
            assert self.toc is not None
            return list(self.toc)
