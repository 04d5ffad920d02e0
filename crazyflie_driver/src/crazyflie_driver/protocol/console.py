"""Port 0 (console): the text the firmware prints, arriving in pieces of up to 30 bytes.

Packets are cut at a newline or when 30 bytes are buffered, so a line (or a
multi-byte UTF-8 character) may span packets; this module joins them.
"""
from __future__ import annotations

import codecs
import logging
import threading
from typing import Callable, List

from crazyflie_driver.crtp.packet import PORT_CONSOLE, CRTPPacket

_LOG = logging.getLogger(__name__)

#: What the original driver's server put before each console line on rosout (``CF Console: <line>``).
ROSOUT_PREFIX = "CF Console: "
#: Text kept for ``text()``; older text is dropped so a chatty firmware cannot fill memory.
MAX_KEPT_CHARS = 65536
#: Characters of text without a newline handed to the line callbacks as one line: text that never ends
#: its line still reaches them, and the partial line cannot grow without bound.
MAX_LINE_CHARS = 1024


def rosout_line(name: str, line: str) -> str:
    """A console line as the server logs it: the original's prefix, then which Crazyflie (a server serves
    many), then the line with its control characters made visible."""
    visible = "".join(c if c.isprintable() else "\\x%02x" % ord(c) for c in line.rstrip("\r"))
    return "%s[%s] %s" % (ROSOUT_PREFIX, name, visible)


class Console:
    """Accumulates console text; calls text and line callbacks in the link's thread."""

    def __init__(self, link) -> None:
        self.link = link
        self._decoder = codecs.getincrementaldecoder("utf-8")("replace")
        self._text = ""
        self._partial_line = ""
        self._text_callbacks: List[Callable[[str], None]] = []
        self._line_callbacks: List[Callable[[str], None]] = []
        self._lock = threading.Lock()
        self._unsubscribe = link.subscribe(PORT_CONSOLE, 0, self._on_packet)

    def on_text(self, callback: Callable[[str], None]) -> None:
        """callback(chunk) for every piece of text as it arrives."""
        self._text_callbacks.append(callback)

    def on_line(self, callback: Callable[[str], None]) -> None:
        """callback(line) for every complete line, without its trailing newline."""
        self._line_callbacks.append(callback)

    def text(self) -> str:
        """All text received so far (the last MAX_KEPT_CHARS characters)."""
        with self._lock:
            return self._text

    def close(self) -> None:
        self._unsubscribe()

    def _on_packet(self, packet: CRTPPacket) -> None:
        # NUL bytes follow the firmware's "<F>" queue-full marker: not text.
        chunk = self._decoder.decode(packet.data.replace(b"\x00", b""))
        if not chunk:
            return
        with self._lock:
            self._text = (self._text + chunk)[-MAX_KEPT_CHARS:]
            pending = self._partial_line + chunk
            *lines, self._partial_line = pending.split("\n")
            while len(self._partial_line) > MAX_LINE_CHARS:
                lines.append(self._partial_line[:MAX_LINE_CHARS])
                self._partial_line = self._partial_line[MAX_LINE_CHARS:]
        for callback in list(self._text_callbacks):
            _safe_call(callback, chunk)
        for line in lines:
            for callback in list(self._line_callbacks):
                _safe_call(callback, line)


def _safe_call(callback, arg) -> None:
    try:
        callback(arg)
    except Exception:  # a user callback must not kill the link thread
        _LOG.exception("console callback failed")
