"""listMemories: every memory the Crazyflie lists (id, type, size, serial), decks by name."""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver.errors import ProtocolError
from crazyflie_driver.protocol.memory import TYPE_ONE_WIRE, parse_one_wire, type_name

from .common import open_crazyflie, parser, run


def _list(args) -> int:
    cf = open_crazyflie(args)
    try:
        for info in cf.memory.memories():
            line = "%d: %s, %d bytes, serial %s" % (info.id, type_name(info.type), info.size, info.serial.hex())
            if info.type == TYPE_ONE_WIRE:
                head = cf.memory.read(info.id, 0, min(info.size, 64))
                try:
                    deck = parse_one_wire(head)
                    line += ", deck %s rev %s (vid 0x%02X, pid 0x%02X)" % (deck.name, deck.revision, deck.vid, deck.pid)
                except ProtocolError as error:
                    line += ", unreadable deck memory (%s)" % error
            print(line)
    finally:
        cf.close()
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("List the memories of a Crazyflie (EEPROM, decks' one-wire memories, trajectory memory, ...).")
    return run(_list, p.parse_args(argv), "listMemories")


if __name__ == "__main__":
    sys.exit(main())
