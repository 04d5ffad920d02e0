"""Crazyswarm's command line, without ROS: the same options, and which of them mean nothing here.

``--sim`` flies our simulated world (its physics, firmware and radio) instead of a running swarm
server; Crazyswarm's other simulation options belong to its kinematic simulator and visualizer, so
they are accepted (a script passing them keeps working) and named when they change nothing.
"""
from __future__ import annotations

import argparse
import math
from typing import List, Optional, Sequence, Tuple, Union

#: Crazyswarm's simulation-only options: name -> (default, why it changes nothing here).
SIM_ONLY = {
    "vis": ("mpl", "no built-in visualizer: roslaunch crazyflie_demo swarm.launch sim:=true gui:=true shows the "
                   "world in rviz"),
    "dt": (0.1, "it is the visualizer's frame period; the world steps its own physics"),
    "writecsv": (False, "no CSV log; record the flight with rosbag (the world's truth: the swarm monitor)"),
    "disturbance": (0.0, "the world's physics has no velocity-disturbance knob; inject faults with "
                         "rosrun crazyflie_tools fault"),
    "maxvel": (math.inf, "speeds come from the simulated firmware and physics, not a kinematic limit"),
    "video": (None, "no video writer"),
}


def build_argparser(parent_parsers: Sequence[argparse.ArgumentParser] = ()) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(formatter_class=argparse.ArgumentDefaultsHelpFormatter,
                                     parents=list(parent_parsers))
    parser.add_argument("--sim", action="store_true",
                        help="Fly the simulated world (started here unless one is running).")
    group = parser.add_argument_group("Simulation-only", "accepted for Crazyswarm's scripts; see each help")
    group.add_argument("--vis", choices=["mpl", "vispy", "null"], default=SIM_ONLY["vis"][0],
                       help="Ignored: " + SIM_ONLY["vis"][1])
    group.add_argument("--dt", type=float, default=SIM_ONLY["dt"][0], help="Ignored: " + SIM_ONLY["dt"][1])
    group.add_argument("--writecsv", action="store_true", help="Ignored: " + SIM_ONLY["writecsv"][1])
    group.add_argument("--disturbance", type=float, default=SIM_ONLY["disturbance"][0],
                       help="Ignored: " + SIM_ONLY["disturbance"][1])
    group.add_argument("--maxvel", type=float, default=SIM_ONLY["maxvel"][0], help="Ignored: " + SIM_ONLY["maxvel"][1])
    group.add_argument("--video", type=str, default=SIM_ONLY["video"][0], help="Ignored: " + SIM_ONLY["video"][1])
    return parser


def parse(parent_parser: Optional[argparse.ArgumentParser] = None,
          args: Union[None, str, Sequence[str]] = None) -> Tuple[argparse.Namespace, List[str]]:
    """(options, the arguments no parser knew) as Crazyswarm parses them: ``args`` a string is split
    on white space; None reads the command line (ROS remappings such as ``__name:=x`` pass through)."""
    parser = build_argparser([parent_parser] if parent_parser is not None else [])
    if isinstance(args, str):
        args = args.split()
    return parser.parse_known_args(args)


def ignored(options: argparse.Namespace) -> List[str]:
    """One sentence per simulation-only option given with a value other than its default."""
    out = []
    for name, (default, why) in SIM_ONLY.items():
        value = getattr(options, name, default)
        if value != default and not (isinstance(value, float) and isinstance(default, float)
                                     and math.isinf(value) and math.isinf(default)):
            scope = "" if options.sim else " (and it is simulation-only; this run is not --sim)"
            out.append("--%s %s ignored: %s%s" % (name, value, why, scope))
    return out
