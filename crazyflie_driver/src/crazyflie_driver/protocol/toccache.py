"""TOC cache on disk: one JSON file per (kind, CRC).

Downloading a TOC item by item takes hundreds of radio round trips; a firmware
build always reports the same CRC for the same table, so a second connect to
the same build reads the table from here instead. A corrupt or mismatching
file is ignored (and rewritten after the download), never fatal.
"""
from __future__ import annotations

import json
import logging
import os
import tempfile
from typing import List, Optional

from crazyflie_driver.crtp.ctypes import CTYPES
from crazyflie_driver.protocol.toc import TocEntry

_LOG = logging.getLogger(__name__)
_FORMAT_VERSION = 1


def default_cache_dir() -> str:
    """``$CRAZYFLIE_TOC_CACHE``, else ``$XDG_CACHE_HOME/crazyflie_driver/toc``, else ~/.cache/..."""
    explicit = os.environ.get("CRAZYFLIE_TOC_CACHE")
    if explicit:
        return explicit
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "crazyflie_driver", "toc")


class TocCache:
    """Reads and writes cached TOCs in ``cache_dir`` (created on first write)."""

    def __init__(self, cache_dir: Optional[str] = None) -> None:
        self.cache_dir = cache_dir or default_cache_dir()

    def path(self, kind: str, crc: int) -> str:
        return os.path.join(self.cache_dir, "%s_%08X.json" % (kind, crc & 0xFFFFFFFF))

    def load(self, kind: str, crc: int, count: Optional[int] = None) -> Optional[List[TocEntry]]:
        """The cached entries, or None when absent, unreadable or not ``count`` long."""
        path = self.path(kind, crc)
        try:
            with open(path, encoding="utf-8") as f:
                doc = json.load(f)
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as e:
            _LOG.warning("ignoring unreadable TOC cache file %s: %s", path, e)
            return None
        try:
            entries = _decode(doc, kind, crc)
        except (KeyError, TypeError, ValueError) as e:
            _LOG.warning("ignoring corrupt TOC cache file %s: %s", path, e)
            return None
        if count is not None and len(entries) != count:
            _LOG.warning("ignoring TOC cache file %s: %d entries, the Crazyflie has %d",
                         path, len(entries), count)
            return None
        return entries

    def store(self, kind: str, crc: int, entries: List[TocEntry]) -> None:
        """Write the entries atomically; a failure to write is logged, not raised."""
        path = self.path(kind, crc)
        doc = {
            "format": _FORMAT_VERSION, "kind": kind, "crc": crc & 0xFFFFFFFF,
            "entries": [[e.ident, e.group, e.name, e.ctype, e.readonly] for e in entries],
        }
        try:
            os.makedirs(self.cache_dir, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=".toc-", suffix=".json", dir=self.cache_dir)
            try:
                with os.fdopen(fd, "w", encoding="utf-8") as f:
                    json.dump(doc, f)
                os.replace(tmp, path)
            except BaseException:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
                raise
        except OSError as e:
            _LOG.warning("could not write TOC cache file %s: %s", path, e)


def _decode(doc, kind: str, crc: int) -> List[TocEntry]:
    if not isinstance(doc, dict):
        raise ValueError("not a JSON object")
    if doc.get("format") != _FORMAT_VERSION or doc["kind"] != kind or doc["crc"] != crc & 0xFFFFFFFF:
        raise ValueError("format, kind or CRC does not match the file name")
    entries = []
    for row in doc["entries"]:
        ident, group, name, ctype, readonly = row
        if not isinstance(ident, int) or not isinstance(group, str) or not isinstance(name, str):
            raise ValueError("bad entry %r" % (row,))
        if ctype not in CTYPES or not isinstance(readonly, bool):
            raise ValueError("bad entry %r" % (row,))
        entries.append(TocEntry(ident, group, name, ctype, readonly))
    return entries
