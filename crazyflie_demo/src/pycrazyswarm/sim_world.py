"""``--sim``: fly our simulated world (physics, firmware, fake Crazyradios) and swarm server.

A world and swarm server already running on this ROS master (``swarm.launch sim:=true``) are
joined. Otherwise ``swarm.launch sim:=true demo:=false`` is started for the YAML's Crazyflies (a
ROS master with it, if none runs) and stopped when the script ends. A swarm server without the
simulated world is a real swarm: ``--sim`` refuses it rather than fly real Crazyflies.

The started world listens at ``$CRAZYFLIE_SIM_ADDRESS`` (default 127.0.0.1:19840) and serves its
motion capture over VRPN on the next port. The swarm file given to it is the YAML's ``crazyflies``,
the types of a ``crazyflieTypes.yaml`` beside it (as Crazyswarm keeps them), and the firmware
parameters Crazyswarm's server launch file sets for every Crazyflie (``CRAZYSWARM_FIRMWARE_PARAMS``).
"""
from __future__ import annotations

import atexit
import os
import signal
import subprocess
import tempfile
import time
from typing import Any, Dict, Optional

import yaml

from crazyflie_driver.errors import CrazyflieError, SwarmConfigError
from crazyflie_driver.server.swarm.config import parse_swarm
from pycrazyswarm.config import Source

DEFAULT_SIM_ADDRESS = "127.0.0.1:19840"
WORLD_NODE = "/crazyflie_sim"
MASTER_WAIT_S = 30.0
STOP_WAIT_S = 15.0
#: What Crazyswarm's server launch file (hover_swarm.launch) writes to every Crazyflie: the high-level
#: commander, the Kalman estimator (the one that takes motion capture), Mellinger, its std devs.
CRAZYSWARM_FIRMWARE_PARAMS = {
    "commander": {"enHighLevel": 1},
    "stabilizer": {"estimator": 2, "controller": 2},
    "locSrv": {"extPosStdDev": 1e-3, "extQuatStdDev": 0.05},
}


def swarm_file_text(source: Source) -> str:
    """The swarm file the world and server read: the YAML's Crazyflies, its types or those of the
    crazyflieTypes.yaml beside it, Crazyswarm's server-wide parameters first. Checked here."""
    data = yaml.safe_load(source.text)
    if isinstance(data, dict) and "robots" in data:     # Crazyswarm2's file names its own parameters
        parse_swarm(source.text, source.path or "<crazyflies yaml>")
        return source.text
    out: Dict[str, Any] = {"firmwareParams": CRAZYSWARM_FIRMWARE_PARAMS}
    out["crazyflies"] = data["crazyflies"]
    types = data.get("crazyflieTypes")
    if types is None and source.types_path:
        with open(source.types_path) as f:
            types = (yaml.safe_load(f) or {}).get("crazyflieTypes")
    if types:
        out["crazyflieTypes"] = types
    if data.get("firmwareParams"):
        for group, values in data["firmwareParams"].items():
            out["firmwareParams"] = dict(out["firmwareParams"])
            out["firmwareParams"][group] = dict(out["firmwareParams"].get(group, {}), **values)
    text = yaml.safe_dump(out, default_flow_style=None, sort_keys=False)
    try:
        parse_swarm(text, source.path or "<crazyflies yaml>")
    except SwarmConfigError as e:
        raise SwarmConfigError("%s (for --sim; types come from the file itself or a crazyflieTypes.yaml beside it)"
                               % e) from None
    return text


def _master_state():
    """(nodes, services) of the running master, or None when none answers."""
    import rosgraph
    if not rosgraph.is_master_online():
        return None
    pubs, subs, services = rosgraph.Master("/pycrazyswarm").getSystemState()
    nodes = {n for _, ns in list(pubs) + list(subs) + list(services) for n in ns}
    return nodes, {name for name, _ in services}


def world_running() -> bool:
    """Whether the ROS master knows our simulated world's node (a swarm.launch sim:=true)."""
    state = _master_state()
    return state is not None and WORLD_NODE in state[0]


class SimWorld:
    """The world this script flies with --sim; ``stop()`` ends it if this script started it."""

    def __init__(self, source: Source) -> None:
        self.source = source
        self.process: Optional[subprocess.Popen] = None
        self._file: Optional[str] = None
        self.joined = False

    def start_or_join(self) -> SimWorld:
        state = _master_state()
        if state is not None:
            nodes, services = state
            world, server = WORLD_NODE in nodes, "/takeoff" in services
            if world and server:
                self.joined = True
                return self
            if server:
                raise CrazyflieError("--sim, but the swarm server on %s flies no simulated world (no %s node): those "
                                     "may be real Crazyflies. Stop it, or run without --sim to fly them"
                                     % (os.environ.get("ROS_MASTER_URI", "the ROS master"), WORLD_NODE))
            if world:
                raise CrazyflieError("--sim: a simulated world runs without a swarm server; start both with roslaunch "
                                     "crazyflie_demo swarm.launch sim:=true demo:=false swarm_file:=<yaml>, or stop it")
        self._launch()
        return self

    def _launch(self) -> None:
        text = swarm_file_text(self.source)
        fd, self._file = tempfile.mkstemp(prefix="pycrazyswarm_", suffix=".yaml")
        with os.fdopen(fd, "w") as f:
            f.write(text)
        address = os.environ.get("CRAZYFLIE_SIM_ADDRESS", DEFAULT_SIM_ADDRESS)
        host, port = address.rsplit(":", 1)
        n = len(parse_swarm(text, self.source.path or "<crazyflies yaml>").crazyflies)     # the enabled ones
        cmd = ["roslaunch", "crazyflie_demo", "swarm.launch", "sim:=true", "demo:=false", "gui:=false",
               "swarm_file:=%s" % self._file, "n:=%d" % n, "sim_address:=%s" % address,
               "vrpn_port:=%d" % (int(port) + 1), "vrpn_server:=%s:%d" % (host, int(port) + 1)]
        log = open(os.path.join(tempfile.gettempdir(), "pycrazyswarm_sim_%d.log" % os.getpid()), "w")
        print("pycrazyswarm --sim: starting the simulated world and swarm server for %d Crazyflies (%s; log %s)"
              % (n, address, log.name), flush=True)
        self.process = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                        start_new_session=True)
        atexit.register(self.stop)
        deadline = time.monotonic() + MASTER_WAIT_S
        while _master_state() is None:
            if self.process.poll() is not None or time.monotonic() > deadline:
                raise CrazyflieError("--sim: roslaunch crazyflie_demo swarm.launch did not bring up a ROS master "
                                     "(exit %s); see %s" % (self.process.poll(), log.name))
            time.sleep(0.2)

    def stop(self) -> None:
        """End the world and server this script started (SIGINT, as Ctrl-C would, then SIGTERM)."""
        p, self.process = self.process, None
        if p is not None and p.poll() is None:
            p.send_signal(signal.SIGINT)
            try:
                p.wait(STOP_WAIT_S)
            except subprocess.TimeoutExpired:
                p.terminate()
                try:
                    p.wait(STOP_WAIT_S)
                except subprocess.TimeoutExpired:
                    p.kill()
        if self._file is not None:
            try:
                os.unlink(self._file)
            except OSError:
                pass
            self._file = None
