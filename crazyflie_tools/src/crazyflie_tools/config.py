"""config: read, or change, the EEPROM configuration block (radio channel, data rate, address, trims).

Without options it prints the block; with any of them it writes the block with those fields changed
and prints it again. The Crazyflie takes new radio settings at its next boot (``reboot``), so the
URI to reach it changes only then.
"""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver.crtp import config_block as cb

from .common import open_crazyflie, parser, run

describe = cb.describe


def changed(block: cb.ConfigBlock, args) -> cb.ConfigBlock:
    """``block`` with the fields the options name (pure; checked by ``cb.encode`` before writing)."""
    fields = {}
    if args.channel is not None:
        fields["channel"] = args.channel
    if args.datarate is not None:
        fields["datarate"] = cb.parse_datarate(args.datarate)
    if args.address is not None:
        fields["address"] = cb.parse_address(args.address)
    if args.pitch_trim is not None:
        fields["pitch_trim"] = args.pitch_trim
    if args.roll_trim is not None:
        fields["roll_trim"] = args.roll_trim
    return block._replace(**fields)


def _config(args) -> int:
    cf = open_crazyflie(args)
    try:
        block = cf.memory.read_config()
        new = changed(block, args)
        if new != block:
            cb.encode(new)                               # refuse a bad value before writing
            cf.memory.write_config(new)
            block = cf.memory.read_config()
            print(describe(block))
            print("written; the Crazyflie takes it at its next boot (reboot --uri %s)" % args.uri)
        else:
            print(describe(block))
    finally:
        cf.close()
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Read or change the EEPROM configuration of a Crazyflie (radio channel, data rate, address, trims).")
    p.add_argument("--channel", type=int, help="radio channel 0..125")
    p.add_argument("--datarate", help="250K, 1M or 2M")
    p.add_argument("--address", help="radio address, 10 hex digits, e.g. E7E7E7E7E7")
    p.add_argument("--pitch-trim", type=float, help="degrees")
    p.add_argument("--roll-trim", type=float, help="degrees")
    return run(_config, p.parse_args(argv), "config")


if __name__ == "__main__":
    sys.exit(main())
