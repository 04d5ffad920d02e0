"""``rosrun crazyflie_tools fault <what> [args]``: inject a fault into the simulated world.

Works against either world (``crazyflie_world_server`` or the ``crazyflie_sim_node`` of sim.launch):
both serve the same control channel at ``CRAZYFLIE_SIM_ADDRESS`` (default 127.0.0.1:19840). The words
are those of ``crazyflie_driver.sim.air.faults`` (the sim node's ``~fault`` service takes the same).
Bad input or a world that refuses gets one line on stderr and exit code 1.
"""
from __future__ import annotations

import sys
from typing import List, Optional, Sequence, Tuple

PROG = "fault"


def split_address(argv: Sequence[str]) -> Tuple[Optional[str], List[str]]:
    """``--address HOST:PORT`` (or ``--address=...``) before the fault's words, and the rest."""
    words = list(argv)
    if words and words[0].startswith("--address"):
        if "=" in words[0]:
            return words[0].split("=", 1)[1], words[1:]
        if len(words) < 2:
            raise ValueError("--address needs HOST:PORT")
        return words[1], words[2:]
    return None, words


def main(argv: Optional[Sequence[str]] = None) -> int:
    from crazyflie_driver.errors import CrazyflieError
    from crazyflie_driver.sim.air.faults import USAGE, FaultError, describe_result, parse_command
    from crazyflie_driver.sim.air.medium import RemoteMedium

    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print("usage: rosrun crazyflie_tools " + USAGE)
        return 0 if argv else 1
    try:
        address, words = split_address(argv)
        op, args = parse_command(words)
        medium = RemoteMedium(address, timeout=5.0) if address else RemoteMedium(timeout=5.0)
        try:
            result = medium.control(op, **args)
        finally:
            medium.close()
    except (FaultError, CrazyflieError, ValueError, OSError) as e:
        text = str(e)
        if text.startswith("simulated world: "):
            text = text[len("simulated world: "):]
        print("%s: error: %s" % (PROG, text.replace("\n", " ")), file=sys.stderr)
        return 1
    print(describe_result(op, args, result))
    return 0
