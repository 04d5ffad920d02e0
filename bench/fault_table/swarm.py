"""The fault table in swarm mode: four Crazyflies of a swarm file hovering on the onboard high-level
commander, fed by the server's own packed motion-capture broadcasts, and one fault at a time addressed to
one Crazyflie, to a radio two of them share, or to the swarm as a whole.

Each row says what the addressed Crazyflies did and whether the fault reached the others, on the world's
truth of every Crazyflie (``harness.analyse`` per Crazyflie, each against its own hover point: its initial
position, ``HEIGHT`` up).
"""
from __future__ import annotations

import os
import signal
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from fault_table.harness import (
    REPO,
    SAMPLE_HZ,
    Graph,
    analyse,
    cleaned_up,
    hover_ok,
    node_pid,
    roslaunch,
)
from fault_table.rows import battery_levels

SWARM_FILE = os.path.join(REPO, "crazyflie_demo", "config", "swarm4.yaml")
SIM_ADDRESS = "127.0.0.1:19894"
VRPN_PORT = 19895
HEIGHT = 0.5
"""Hover height [m] of the swarm's takeoff."""
SHARED_DONGLE = 0
"""The Crazyradio cf1 and cf2 share (channel 80 in swarm4.yaml)."""
SPEED = 1.0
"""World speed [x real time]: fixed, so a row's observation window in wall time is its window in world time."""

Goal = Tuple[float, float, float]


def goals() -> Dict[str, Goal]:
    """Each Crazyflie's hover point: its initial position, HEIGHT up (the swarm's takeoff)."""
    from crazyflie_driver.server.swarm.config import load_swarm_file
    return {cf.tf_prefix: (cf.initial_position[0], cf.initial_position[1], HEIGHT)
            for cf in load_swarm_file(SWARM_FILE).crazyflies}


# --- the graph -----------------------------------------------------------------------------------
def world_launch_text() -> str:
    """The world of the swarm file, VRPN motion capture as a room serves it, /clock; its own launch, so
    killing the server leaves it running."""
    return "\n".join([
        "<launch>",
        '  <include file="$(find crazyflie_driver)/launch/sim.launch">',
        '    <arg name="swarm_file" value="%s" /><arg name="vrpn" value="true" />' % SWARM_FILE,
        '    <arg name="vrpn_port" value="%d" /><arg name="mocap" value="none" />' % VRPN_PORT,
        '    <arg name="mocap_noise" value="0.0005" /><arg name="mocap_latency" value="0.005" />',
        '    <arg name="speed" value="%s" /><arg name="sim_address" value="%s" />' % (SPEED, SIM_ADDRESS),
        "  </include>",
        "</launch>"]) + "\n"


def launch_text() -> str:
    """The server in swarm mode (its defaults: the emergency-stop watchdog keep-alive on), no demo script."""
    return "\n".join([
        "<launch>",
        '  <include file="$(find crazyflie_driver)/launch/crazyflie_server.launch">',
        '    <arg name="sim" value="true" /><arg name="sim_address" value="%s" />' % SIM_ADDRESS,
        '    <arg name="swarm_file" value="%s" /><arg name="mocap" value="vrpn" />' % SWARM_FILE,
        '    <arg name="vrpn_server" value="127.0.0.1:%d" />' % VRPN_PORT,
        "  </include>",
        "</launch>"]) + "\n"


class SwarmGraph(Graph):
    """World and swarm server as two launches (the world outlives the server)."""

    def __init__(self, work: str) -> None:       # not Graph.__init__: that one launches the chapter's graph
        self.path = "swarm"
        self.work = work
        self.extra = []
        self.mocap_forward = None
        self.world = roslaunch(os.path.join(work, "swarm_world.launch"), world_launch_text())
        self.proc = roslaunch(os.path.join(work, "swarm_graph.launch"), launch_text())


class SwarmTruth:
    """Every Crazyflie's truth at SAMPLE_HZ: (monotonic time, {name: state or None})."""

    def __init__(self, names: Sequence[str]) -> None:
        self.names = list(names)
        self.lock = threading.Lock()
        self.samples: List[Tuple[float, Dict[str, Optional[Dict[str, Any]]]]] = []
        self._stop = threading.Event()
        threading.Thread(target=self._run, name="swarm truth", daemon=True).start()

    def _run(self) -> None:
        from crazyflie_driver.sim.air.medium import RemoteMedium
        world = RemoteMedium(SIM_ADDRESS, timeout=1.0)
        while not self._stop.wait(1.0 / SAMPLE_HZ):
            states: Dict[str, Optional[Dict[str, Any]]] = {}
            for n in self.names:
                try:
                    states[n] = world.control("vehicle_state", uri=n)
                except Exception:
                    states[n] = None
            with self.lock:
                self.samples.append((time.monotonic(), states))
                if len(self.samples) > 100000:
                    del self.samples[:50000]

    def of(self, name: str, t0: float) -> List[Tuple[float, Optional[Dict[str, Any]]]]:
        with self.lock:
            return [(t, s[name]) for t, s in self.samples if t >= t0]

    def stop(self) -> None:
        self._stop.set()


@dataclass
class SwarmRow:
    key: str
    title: str
    affected: Tuple[str, ...]               # the Crazyflies the fault is addressed to (all: the swarm)
    inject: Callable[[SwarmBench], None]
    observe_s: float
    cleanup: Callable[[SwarmBench], None] = lambda b: None
    path: str = "swarm"
    result: Dict[str, Any] = field(default_factory=dict)


class SwarmBench:
    def __init__(self, work: str) -> None:
        import rospy
        from rosgraph_msgs.msg import Log
        self.rospy = rospy
        self.work = work
        self.goals = goals()
        self.graph: Optional[SwarmGraph] = None
        self.truth = SwarmTruth(list(self.goals))
        self.lock = threading.Lock()
        self.rosout: List[Tuple[float, Any]] = []

        def keep(msg) -> None:
            with self.lock:
                self.rosout.append((time.monotonic(), msg))
        rospy.Subscriber("/rosout_agg", Log, keep, queue_size=1000)

    def hovering(self, seconds: float = 1.0) -> bool:
        t0 = time.monotonic() - seconds
        for name, goal in self.goals.items():
            samples = self.truth.of(name, t0)
            if len(samples) < seconds * SAMPLE_HZ * 0.5 or not all(s is not None and hover_ok(s, goal)
                                                                   for _, s in samples):
                return False
        return True

    def fly(self) -> float:
        """The swarm hovering, each Crazyflie over its initial position; the seconds it took (0: it was)."""
        t0 = time.monotonic()
        g = self.graph
        if g is not None and g.alive() and self.hovering():
            return 0.0
        if g is not None:
            g.stop()
        self.graph = SwarmGraph(self.work)
        rospy = self.rospy
        from crazyflie_driver.srv import Takeoff
        rospy.wait_for_service("/takeoff", 90.0)
        takeoff = rospy.ServiceProxy("/takeoff", Takeoff)
        deadline = time.monotonic() + 60.0
        while True:        # refused until every estimator is placed from its first pose
            try:
                takeoff(groupMask=0, height=HEIGHT, duration=rospy.Duration(2.0))
                break
            except rospy.ServiceException:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        deadline = time.monotonic() + 40.0
        while time.monotonic() < deadline:
            if self.hovering(1.5):
                return time.monotonic() - t0
            time.sleep(0.1)
        raise RuntimeError("the swarm did not reach its hover")

    def run(self, row: SwarmRow) -> Dict[str, Any]:
        setup_s = self.fly()
        time.sleep(0.5)
        t_fault = time.monotonic()
        row.inject(self)
        time.sleep(row.observe_s)
        t_end = time.monotonic()
        per = {n: analyse(self.truth.of(n, t_fault), t_fault, t_end, goal) for n, goal in self.goals.items()}
        for n in per:
            end = self.truth.of(n, t_end - 0.5)
            locked = next((s["locked"] for _, s in reversed(end) if s is not None), "")
            if locked:
                per[n]["does"] += " (firmware locked: %s)" % locked
        result = summarise(row.affected, per)
        result["reported"] = self.reported(t_fault, t_end)
        result["setup_s"] = setup_s
        return cleaned_up(row, self, result)

    def reported(self, t_fault: float, t_end: float) -> List[str]:
        """The first warning or error line of each node after the fault."""
        out, seen = [], set()
        with self.lock:
            lines = [(t, m) for t, m in self.rosout if t_fault <= t <= t_end]
        for t, m in lines:
            if m.level < 4 or m.name in seen or m.name.startswith("/bench_faults"):
                continue
            seen.add(m.name)
            out.append("log %s +%.1fs %s: %s" % ({4: "WARN", 8: "ERROR", 16: "FATAL"}.get(m.level, m.level),
                                                t - t_fault, m.name.lstrip("/"), m.msg.replace("\n", " ")[:110]))
        return out

    def close(self) -> None:
        self.truth.stop()
        if self.graph is not None:
            self.graph.stop()


def summarise(affected: Sequence[str], per: Dict[str, Dict[str, Any]]) -> Dict[str, Any]:
    """One row's verdict: the addressed Crazyflies' outcomes, and the others' (did the fault reach them?).
    ``safe``: every Crazyflie safe (hovering or on the floor with its motors off) by the end; ``safe_s``
    the latest of their times."""
    others = [n for n in per if n not in affected]
    parts = ["%s: %s" % (n, per[n]["does"]) for n in affected]
    kept = [n for n in others if per[n].get("safe_kind") == "hover" and per[n].get("safe_s") == 0.0]
    if others:
        if len(kept) == len(others):
            worst = max(per[n]["max_dev"] for n in kept)
            parts.append("the others (%s) keep hovering (max %.3f m from their points)" % (", ".join(others), worst))
        else:
            parts += ["%s (not addressed): %s" % (n, per[n]["does"]) for n in others if n not in kept]
    unsafe = [n for n in per if per[n].get("safe_kind") is None]
    safe_s = None if unsafe else max(per[n]["safe_s"] for n in per)
    kinds = {per[n]["safe_kind"] for n in per if per[n].get("safe_kind")}
    return {"does": "; ".join(parts), "per": per, "unsafe": unsafe, "safe_s": safe_s,
            "safe": None if unsafe else "%s after %.2f s" % (" / ".join(sorted(kinds)), safe_s)}


# --- the rows ------------------------------------------------------------------------------------
def fault(words: str) -> Any:
    """One fault operation on the swarm's world (as ``rosrun crazyflie_tools fault`` sends it)."""
    from crazyflie_driver.sim.air.faults import parse_command
    from crazyflie_driver.sim.air.medium import RemoteMedium
    op, args = parse_command(words)
    world = RemoteMedium(SIM_ADDRESS, timeout=2.0)
    try:
        return world.control(op, **args)
    finally:
        world.close()


def inject(words: str) -> Callable[[SwarmBench], None]:
    return lambda bench: fault(words)


def clear(bench: SwarmBench) -> None:
    fault("clear")


def kill_server(sig: int) -> Callable[[SwarmBench], None]:
    return lambda bench: os.kill(node_pid("/crazyflie_server"), sig)


def emergency(bench: SwarmBench) -> None:
    from std_srvs.srv import Empty
    bench.rospy.ServiceProxy("/emergency", Empty)()


def land_while_one_hidden(bench: SwarmBench) -> None:
    """cf1's body hidden, then at once the broadcast /land for all: the others land, and cf1 (no pose,
    its estimator drifting) must not be left flying."""
    from crazyflie_driver.srv import Land
    fault("mocap cf1 --hide")
    bench.rospy.ServiceProxy("/land", Land)(groupMask=0, height=0.0, duration=bench.rospy.Duration(2.0))


def rows() -> List[SwarmRow]:
    shared = ("cf1", "cf2")
    _, critical_v, _, source = battery_levels()       # the server's levels, as the chapter's rows use
    return [
        SwarmRow("swarm_loss30", "30 % packet loss on the radio two Crazyflies share", shared,
                 inject("loss %d --packet 0.3" % SHARED_DONGLE), 6.0, clear),
        SwarmRow("swarm_latency", "50 ms latency on the radio two Crazyflies share", shared,
                 inject("latency %d 50ms" % SHARED_DONGLE), 6.0, clear),
        SwarmRow("swarm_freeze2", "mocap of one body frozen 2 s", ("cf1",), inject("mocap cf1 --freeze 2"), 6.0, clear),
        SwarmRow("swarm_hide", "mocap of one body lost for good (hidden)", ("cf1",), inject("mocap cf1 --hide"), 8.0,
                 clear),
        SwarmRow("swarm_battery_crit", "one Crazyflie's battery at critical (%.2f V; levels: %s)"
                 % (critical_v, source), ("cf1",), inject("battery cf1 %.2f" % critical_v), 10.0,
                 lambda b: fault("battery cf1 100%")),
        SwarmRow("swarm_poweroff", "one Crazyflie switched off", ("cf1",), inject("power cf1 off"), 4.0,
                 lambda b: fault("power cf1 on")),
        SwarmRow("swarm_unplug", "the radio two Crazyflies share unplugged for good", shared,
                 inject("unplug %d" % SHARED_DONGLE), 8.0, clear),
        SwarmRow("swarm_land_hidden", "broadcast /land while one body is hidden", ("cf1", "cf2", "cf3", "cf4"),
                 land_while_one_hidden, 8.0, clear),
        SwarmRow("swarm_server_int", "server stopped (Ctrl-C)", ("cf1", "cf2", "cf3", "cf4"),
                 kill_server(signal.SIGINT), 10.0),
        SwarmRow("swarm_server_kill", "server killed (SIGKILL)", ("cf1", "cf2", "cf3", "cf4"),
                 kill_server(signal.SIGKILL), 6.0),
        SwarmRow("swarm_emergency", "/emergency", ("cf1", "cf2", "cf3", "cf4"), emergency, 3.0),
    ]
