"""The real firmware's variable tables, read from the data file the package ships.

``data/firmware_2026.08_toc.tsv`` lists every parameter and log variable the Crazyflie firmware's
source declares (release 2026.08): kind, group, name, C type with flags, the macro that declared it
and the source file (docs/simulation.md, "The firmware's variable tables"). A Crazyflie 2.1 build
links the core modules and every deck driver; this module picks that build's entries (tables.py turns
them into the simulated firmware's entries). It is pure: reading the file is the only I/O.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Iterable, List, Tuple

from crazyflie_driver.errors import FirmwareTableError

#: The firmware release whose tables ship beside this module (commit 2a18fc2); the simulated current
#: firmware reports this release tag as its version, so the tables and the version never disagree.
FIRMWARE_RELEASE = "2026.08"
#: The table of that release, shipped beside this module.
FIRMWARE_TOC_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data",
                                 "firmware_%s_toc.tsv" % FIRMWARE_RELEASE)

#: Source files that only other platforms link (Bolt, Flapper, Brushless); a Crazyflie 2.1 build has none.
OTHER_PLATFORM_SOURCES = ("flapper", "brushless", "bolt")
#: Macros whose entries a release build leaves out (CONFIG_DEBUG_LOG_ENABLE only).
LEFT_OUT_MACROS = ("debug",)

_PARAM_TYPES = {"PARAM_UINT8": "uint8_t", "PARAM_UINT16": "uint16_t", "PARAM_UINT32": "uint32_t",
                "PARAM_INT8": "int8_t", "PARAM_INT16": "int16_t", "PARAM_INT32": "int32_t",
                "PARAM_FLOAT": "float"}
_LOG_TYPES = {"LOG_UINT8": "uint8_t", "LOG_UINT16": "uint16_t", "LOG_UINT32": "uint32_t",
              "LOG_INT8": "int8_t", "LOG_INT16": "int16_t", "LOG_INT32": "int32_t",
              "LOG_FLOAT": "float", "LOG_FP16": "FP16"}
_COLUMNS = ("kind", "group", "name", "type_and_flags", "macro", "source")


@dataclass(frozen=True)
class TocRow:
    """One declaration of the firmware source."""

    kind: str        # "param" or "log"
    group: str
    name: str
    ctype: str       # C type name as the simulated tables write it (tables.FIRMWARE_CTYPES)
    flags: Tuple[str, ...]   # PARAM_RONLY, PARAM_PERSISTENT as written in the source
    macro: str       # plain, core, by_function, with_callback, debug
    source: str


def parse_rows(lines: Iterable[str], origin: str = "firmware TOC") -> List[TocRow]:
    """Rows of the tab-separated table (``#`` comments and the header skipped), in file order."""
    rows: List[TocRow] = []
    header_seen = False
    for number, line in enumerate(lines, 1):
        line = line.rstrip("\r\n")
        if not line or line.startswith("#"):
            continue
        cells = line.split("\t")
        if not header_seen:
            if tuple(cells) != _COLUMNS:
                raise FirmwareTableError("%s line %d: expected the header %s; give the firmware table file"
                                  % (origin, number, "\\t".join(_COLUMNS)))
            header_seen = True
            continue
        if len(cells) != len(_COLUMNS):
            raise FirmwareTableError("%s line %d: %d columns, expected %d (tab-separated)"
                              % (origin, number, len(cells), len(_COLUMNS)))
        kind, group, name, type_and_flags, macro, source = cells
        parts = type_and_flags.split("|")
        types = _PARAM_TYPES if kind == "param" else _LOG_TYPES if kind == "log" else None
        if types is None or parts[0] not in types:
            raise FirmwareTableError("%s line %d: unknown kind/type %r/%r (kinds: param, log; types: %s)"
                              % (origin, number, kind, parts[0], ", ".join(sorted(_PARAM_TYPES) + sorted(_LOG_TYPES))))
        rows.append(TocRow(kind, group, name, types[parts[0]], tuple(parts[1:]), macro, source))
    if not header_seen:
        raise FirmwareTableError("%s: no header line; give the firmware table file" % origin)
    return rows


def in_cf21_build(row: TocRow) -> bool:
    """True when a Crazyflie 2.1 release build declares the row."""
    return row.macro not in LEFT_OUT_MACROS and not any(p in row.source for p in OTHER_PLATFORM_SOURCES)


def first_of_each_name(rows: Iterable[TocRow]) -> List[TocRow]:
    """Two deck drivers may declare the same variable; a host finds one entry per name, the first."""
    seen = set()
    out = []
    for r in rows:
        key = (r.kind, r.group, r.name)
        if key not in seen:
            seen.add(key)
            out.append(r)
    return out


def load(path: str = FIRMWARE_TOC_PATH) -> List[TocRow]:
    """The Crazyflie 2.1 build's rows of the table file at ``path``."""
    try:
        with open(path, encoding="ascii") as f:
            return [r for r in parse_rows(f, path) if in_cf21_build(r)]
    except OSError as e:
        raise FirmwareTableError("cannot read the firmware table %s (%s); reinstall crazyflie_driver"
                                 % (path, e)) from e
