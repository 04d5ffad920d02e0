"""``Crazyswarm``: what a Crazyswarm script builds first (``swarm.timeHelper``, ``swarm.allcfs``,
``swarm.input``), on a running swarm server or, with ``--sim``, our simulated world."""
from __future__ import annotations

import argparse
import sys
from typing import Optional, Sequence, Union

from pycrazyswarm import args as arguments
from pycrazyswarm import config
from pycrazyswarm.crazyflie import Crazyflie, CrazyflieServer, TimeHelper
from pycrazyswarm.input import Input


class Crazyswarm:
    """``Crazyswarm(crazyflies_yaml=None, parent_parser=None, args=None)``: ``crazyflies_yaml`` is a
    path (``*.yaml``) or a YAML string (default ``../launch/crazyflies.yaml``); ``parent_parser`` adds
    the script's own options; ``args`` replaces the command line (a string or a list)."""

    def __init__(self, crazyflies_yaml: Optional[str] = None, parent_parser: Optional[argparse.ArgumentParser] = None,
                 args: Union[None, str, Sequence[str]] = None) -> None:
        self.args, self.unknown_args = arguments.parse(parent_parser, args)
        for note in arguments.ignored(self.args):
            print("pycrazyswarm: WARNING: " + note, file=sys.stderr, flush=True)
        source = config.find(crazyflies_yaml, config.script_dir(sys.argv))
        entries = config.entries(source)
        from pycrazyswarm import sim_world
        self.world = None
        if self.args.sim:
            self.world = sim_world.SimWorld(source).start_or_join()

        from pycrazyswarm import ros_backend
        ros_backend.init_node()
        backend = ros_backend.RosBackend(["/" + e.tf_prefix for e in entries])
        clock = ros_backend.WorldClock() if self.args.sim else ros_backend.RosClock()
        self.timeHelper = TimeHelper(clock)
        self.allcfs = CrazyflieServer([Crazyflie(e.id, e.initial_position, backend, "/" + e.tf_prefix)
                                       for e in entries], backend)
        self.input = Input(self.timeHelper, simulated=bool(self.args.sim) or sim_world.world_running())
