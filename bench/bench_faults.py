#!/usr/bin/env python3
"""The fault table: each fault on a simulated flight through the real stack, and what the stack does.

One Crazyflie hovers at (0, 0, 0.5) in the full ROS stack: the simulated world (``crazyflie_sim_node``,
Vicon-style mocap at 100 Hz), ``crazyflie_server`` over the fake Crazyradio, and either the chapter's
host-side position controller (``controller`` + a ``goal`` publisher; path "chapter") or the onboard
high-level commander fed with the world's mocap as ``external_position`` (path "onboard"). Each row
injects one fault (through the world's fault operations, the ones ``rosrun crazyflie_tools fault``
uses, or by killing/calling a node) and measures, from the world's truth (position, velocity, motors,
sampled over the control channel at 50 Hz) and from the topics (/rosout_agg, /diagnostics,
/crazyflie1/status, the controller's ~state):

* what the stack does: how the vehicle moves after the fault (keeps hovering / descends / falls);
* time to a safe state: on the floor with the motors off, or hovering under control again
  (within 0.15 m of the goal and slower than 0.3 m/s until the end of the row), from the fault;
* where it is reported: the first warning/error lines of each node, the non-OK /diagnostics entries,
  the Crazyflie's status topic, the controller's state changes;
* anything lost: log packets counted lost by the server, a firmware lock that needs a reboot,
  a link that did not come back.

Nothing in here decides the reaction: the stack's nodes and their defaults do, so a re-run after a
change to the stack's reactions picks them up. A row runs on the graph the previous row left
hovering; a row that leaves the vehicle down (or a node dead) makes the next one start a fresh graph.

Usage (takes the ROS lock on a shared machine; about 5 minutes):
    source tools/env.sh
    flock /tmp/ros.lock bench/bench_faults.py --readme        # every row -> bench/results/faults.txt + README
    flock /tmp/ros.lock bench/bench_faults.py --rows loss30,emergency --out -
    flock /tmp/ros.lock bench/bench_faults.py --rows freeze,hide --readme   # measured again, merged by row key
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Tuple

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
try:
    import crazyflie_driver.srv  # noqa: F401  (the catkin workspace: source tools/env.sh first)
except ImportError:
    sys.exit("bench_faults: the catkin workspace is not on the path: source tools/env.sh first")

from bench_support import free_port  # noqa: E402  (after the workspace check: it names the fix)

SIM_ADDRESS = "127.0.0.1:19897"
URI = "radio://0/80/2M/E7E7E7E701"
NAME = "crazyflie1"
GOAL = (0.0, 0.0, 0.5)
SAMPLE_HZ = 50.0
HOVER_TOLERANCE_M = 0.15       # "hovering under control": this close to the goal ...
HOVER_SPEED_MS = 0.3           # ... and slower than this
FLOOR_Z_M = 0.03
FALL_SPEED_MS = 1.0            # touching down faster than this is a fall, not a landing
KEEPALIVE = "onboard+keep-alive"


# --- the graph -----------------------------------------------------------------------------------
def world_launch_text() -> str:
    """The simulated world alone: it stands for the physical one, so it outlives the stack's nodes (the
    server is a required node: when it dies, roslaunch takes the stack's other nodes down, not the world)."""
    return "\n".join([
        "<launch>",
        '  <node pkg="crazyflie_driver" type="crazyflie_sim_node" name="crazyflie_sim" output="log">',
        '    <param name="address" value="%s" /><param name="mocap" value="vicon" />' % SIM_ADDRESS,
        '    <param name="mocap_rate" value="100.0" /><param name="mocap_noise" value="0.0005" />',
        '    <param name="mocap_latency" value="0.008" /><param name="seed" value="1" />',
        '    <param name="vehicles" type="str" value="[{uri: \'%s\', name: %s}]" />' % (URI, NAME),
        "  </node>",
        "</launch>"]) + "\n"


def launch_text(path: str) -> str:
    """The stack's nodes; path "onboard+keep-alive" is "onboard" with the emergency-stop watchdog keep-alive on."""
    rows = ["<launch>",
            '  <include file="$(find crazyflie_driver)/launch/crazyflie_server.launch">',
            '    <arg name="sim" value="true" /><arg name="sim_address" value="%s" />' % SIM_ADDRESS,
            '    <arg name="emergency_watchdog" value="%s" />' % ("true" if path == KEEPALIVE else "false"),
            "  </include>",
            '  <group ns="%s">' % NAME,
            '    <include file="$(find crazyflie_driver)/launch/crazyflie_add.launch">',
            '      <arg name="uri" value="%s" /><arg name="tf_prefix" value="%s" />' % (URI, NAME),
            "    </include>"]
    if path == "chapter":
        rows += ['    <include file="$(find crazyflie_controller)/launch/crazyflie2.launch">',
                 '      <arg name="frame" value="/vicon/%s/%s" />' % (NAME, NAME),
                 "    </include>",
                 '    <node name="pose" pkg="crazyflie_demo" type="publish_pose.py">',
                 '      <param name="name" value="goal" /><param name="rate" value="30" />',
                 '      <param name="x" value="%s" /><param name="y" value="%s" /><param name="z" value="%s" />'
                 % GOAL,
                 "    </node>"]
    rows += ["  </group>", "</launch>"]
    return "\n".join(rows) + "\n"


class Recorder:
    """Topics with their arrival time (monotonic): rosout lines, diagnostics, status, controller state."""

    def __init__(self) -> None:
        import rospy
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
        from rosgraph_msgs.msg import Log
        from std_msgs.msg import Float32, String

        self.lock = threading.Lock()
        self.rosout: List[Tuple[float, Any]] = []
        self.diagnostics: List[Tuple[float, Any]] = []
        self.status: List[Tuple[float, Any]] = []
        self.state: List[Tuple[float, str]] = []
        self.battery: List[Tuple[float, float]] = []

        def keep(into, convert=lambda m: m):
            def cb(msg):
                with self.lock:
                    into.append((time.monotonic(), convert(msg)))
            return cb
        rospy.Subscriber("/rosout_agg", Log, keep(self.rosout), queue_size=1000)
        rospy.Subscriber("/diagnostics", DiagnosticArray, keep(self.diagnostics), queue_size=100)
        rospy.Subscriber("/%s/status" % NAME, DiagnosticStatus, keep(self.status), queue_size=100)
        rospy.Subscriber("/%s/controller/state" % NAME, String, keep(self.state, lambda m: m.data), queue_size=100)
        rospy.Subscriber("/%s/battery" % NAME, Float32, keep(self.battery, lambda m: m.data), queue_size=100)

    def since(self, what: str, t0: float) -> List[Tuple[float, Any]]:
        with self.lock:
            return [(t, m) for t, m in getattr(self, what) if t >= t0]


class Truth:
    """The world's truth of the vehicle, sampled over the control channel (None while no world answers)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.samples: List[Tuple[float, Optional[Dict[str, Any]]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="truth", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from crazyflie_driver.sim.air.medium import RemoteMedium
        world = RemoteMedium(SIM_ADDRESS, timeout=1.0)
        period = 1.0 / SAMPLE_HZ
        while not self._stop.wait(period):
            try:
                state = world.control("vehicle_state", uri=NAME)
            except Exception:
                state = None
            with self.lock:
                self.samples.append((time.monotonic(), state))
                if len(self.samples) > 100000:
                    del self.samples[:50000]

    def since(self, t0: float) -> List[Tuple[float, Optional[Dict[str, Any]]]]:
        with self.lock:
            return [s for s in self.samples if s[0] >= t0]

    def latest(self) -> Optional[Dict[str, Any]]:
        with self.lock:
            return self.samples[-1][1] if self.samples else None

    def stop(self) -> None:
        self._stop.set()


def control(op: str, **args) -> Any:
    """One fault operation on the world (the channel ``rosrun crazyflie_tools fault`` uses)."""
    from crazyflie_driver.sim.air.medium import RemoteMedium
    world = RemoteMedium(SIM_ADDRESS, timeout=2.0)
    try:
        return world.control(op, **args)
    finally:
        world.close()


def fault(words: str) -> Any:
    from crazyflie_driver.sim.air.faults import parse_command
    op, args = parse_command(words)
    return control(op, **args)


def node_pid(node: str) -> int:
    """The process id of a ROS node, asked through its own XML-RPC API."""
    import rosgraph
    import xmlrpc.client
    uri = rosgraph.Master("/bench_faults").lookupNode(node)
    code, message, pid = xmlrpc.client.ServerProxy(uri).getPid("/bench_faults")
    if code != 1:
        raise RuntimeError("%s did not give its pid: %s" % (node, message))
    return int(pid)


class Graph:
    """One roslaunch of the stack (on the bench's master) flying the Crazyflie on ``path``."""

    def __init__(self, path: str, work: str) -> None:
        self.path = path
        self.work = work
        self.extra: List[subprocess.Popen] = []      # a sim node started again by a row
        self.world = roslaunch(os.path.join(work, "world.launch"), world_launch_text())
        self.proc = roslaunch(os.path.join(work, "graph_%s.launch" % path), launch_text(path))
        self.mocap_forward = None

    def alive(self) -> bool:
        return self.proc.poll() is None and self.world.poll() is None

    def stop(self) -> None:
        if self.mocap_forward is not None:
            self.mocap_forward.unregister()
            self.mocap_forward = None
        processes = [self.proc, self.world] + self.extra
        for p in processes:
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGINT)
                except OSError:
                    pass
        for p in processes:
            try:
                p.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(5)


def roslaunch(path: str, text: str) -> subprocess.Popen:
    with open(path, "w") as f:
        f.write(text)
    return subprocess.Popen(["roslaunch", "--wait", path], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


@dataclass
class Row:
    key: str
    title: str
    path: str                              # "chapter", "onboard" or KEEPALIVE
    inject: Callable[[Bench], None]
    observe_s: float
    cleanup: Callable[[Bench], None] = lambda b: None
    result: Dict[str, Any] = field(default_factory=dict)


class Bench:
    def __init__(self, work: str) -> None:
        import rospy
        self.rospy = rospy
        self.work = work
        self.graph: Optional[Graph] = None
        self.recorder = Recorder()
        self.truth = Truth()

    # --- bringing the vehicle to a hover ---------------------------------------------------------
    def hovering(self, seconds: float = 1.0) -> bool:
        samples = self.truth.since(time.monotonic() - seconds)
        return len(samples) > seconds * SAMPLE_HZ * 0.5 and all(s is not None and hover_ok(s) for _, s in samples)

    def ready(self, path: str) -> bool:
        g = self.graph
        if g is None or g.path != path or not g.alive() or not self.hovering():
            return False
        status = self.recorder.since("status", time.monotonic() - 3.0)
        if not status or status[-1][1].message != "running":
            return False
        if path == "chapter":
            state = self.recorder.since("state", 0.0)
            return bool(state) and state[-1][1].startswith("Automatic: ok")
        return True

    def fly(self, path: str) -> float:
        """A graph on ``path`` with the vehicle hovering at the goal; returns the seconds it took."""
        t0 = time.monotonic()
        if self.ready(path):
            return 0.0
        if self.graph is not None:
            self.graph.stop()
        # only what the new graph says counts: the stopped graph's status and controller state (its
        # "running", its "Idle: ok") arrive up to its end, and a take-off sent on them reaches the new
        # controller before it has a pose, which refuses it
        t_graph = time.monotonic()
        self.graph = Graph(path, self.work)
        rospy = self.rospy
        from std_srvs.srv import Empty
        rospy.wait_for_service("/%s/update_params" % NAME, 90.0)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            status = self.recorder.since("status", t_graph)
            if status and status[-1][1].message == "running":
                break
            time.sleep(0.1)
        if path == "chapter":
            rospy.wait_for_service("/%s/takeoff" % NAME, 30.0)
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline and not [s for _, s in self.recorder.since("state", t_graph)
                                                       if s == "Idle: ok"]:       # a pose, take-off allowed
                time.sleep(0.1)
            rospy.ServiceProxy("/%s/takeoff" % NAME, Empty)()
        else:
            self.start_onboard_flight()
        deadline = time.monotonic() + 40.0
        while time.monotonic() < deadline:
            if self.hovering(1.5):
                return time.monotonic() - t0
            time.sleep(0.1)
        raise RuntimeError("the Crazyflie did not reach a hover at %s on the %s path (truth: %s)"
                           % (GOAL, path, self.truth.latest()))

    def start_onboard_flight(self) -> None:
        """Onboard: the mocap's pose forwarded as external_position, estimator 2, high-level takeoff."""
        rospy = self.rospy
        from geometry_msgs.msg import PointStamped, TransformStamped

        from crazyflie_driver.srv import Takeoff, UpdateParams
        pub = rospy.Publisher("/%s/external_position" % NAME, PointStamped, queue_size=1, tcp_nodelay=True)

        def forward(msg: TransformStamped) -> None:
            p = PointStamped()
            p.header = msg.header
            t = msg.transform.translation
            p.point.x, p.point.y, p.point.z = t.x, t.y, t.z
            pub.publish(p)
        self.graph.mocap_forward = rospy.Subscriber("/vicon/%s/%s" % (NAME, NAME), TransformStamped, forward,
                                                    queue_size=1, tcp_nodelay=True)
        rospy.set_param("/%s/stabilizer/estimator" % NAME, 2)
        rospy.ServiceProxy("/%s/update_params" % NAME, UpdateParams)(["stabilizer/estimator"])
        time.sleep(1.0)                       # the estimator converges on the first external positions
        rospy.wait_for_service("/%s/takeoff" % NAME, 30.0)
        rospy.ServiceProxy("/%s/takeoff" % NAME, Takeoff)(groupMask=0, height=GOAL[2],
                                                          duration=rospy.Duration(2.0))

    # --- one row -------------------------------------------------------------------------------
    def run(self, row: Row) -> Dict[str, Any]:
        setup_s = self.fly(row.path)
        status0 = self.recorder.since("status", 0.0)
        lost0 = log_packets_lost(status0[-1][1]) if status0 else 0
        time.sleep(0.5)
        t_fault = time.monotonic()
        row.inject(self)
        time.sleep(row.observe_s)
        t_end = time.monotonic()
        result = analyse(self.truth.since(t_fault), t_fault, t_end)
        result["reported"] = reports(self.recorder, t_fault, t_end)
        status = self.recorder.since("status", t_fault)
        lost = []
        if status:
            n = log_packets_lost(status[-1][1]) - lost0
            if n > 0:
                lost.append("%d log packets" % n)
            if status[-1][1].message != "running":
                lost.append("link at the end: %s" % status[-1][1].message)
        end = self.truth.latest()
        if end is not None and end.get("locked"):
            lost.append("firmware locked (%s): reboot to fly" % end["locked"])
        result["lost"] = lost
        result["setup_s"] = setup_s
        try:
            row.cleanup(self)
        except Exception as e:
            result["cleanup_error"] = str(e)
        return result

    def close(self) -> None:
        self.truth.stop()
        if self.graph is not None:
            self.graph.stop()


def log_packets_lost(status) -> int:
    for kv in status.values:
        if kv.key == "log_packets_lost":
            try:
                return int(kv.value)
            except ValueError:
                return 0
    return 0


# --- reading the truth ---------------------------------------------------------------------------
def distance(s: Dict[str, Any]) -> float:
    return math.dist(s["position"], GOAL)


def speed(s: Dict[str, Any]) -> float:
    return math.sqrt(sum(v * v for v in s["velocity"]))


def hover_ok(s: Dict[str, Any]) -> bool:
    return distance(s) < HOVER_TOLERANCE_M and speed(s) < HOVER_SPEED_MS


def floor_off(s: Dict[str, Any]) -> bool:
    return s["position"][2] < FLOOR_Z_M and max(s["motors"]) == 0


def analyse(samples: List[Tuple[float, Optional[Dict[str, Any]]]], t_fault: float, t_end: float) -> Dict[str, Any]:
    """What the vehicle did after the fault, from the truth samples of the row."""
    out: Dict[str, Any] = {}
    known = [(t - t_fault, s) for t, s in samples if s is not None]
    gap = [t - t_fault for t, s in samples if s is None]
    if gap:
        out["world_gone_s"] = (min(gap), max(gap))
    if not known:
        out["does"] = "no truth: the world never answered"
        out["safe"] = None
        return out
    motors_off = next((t for t, s in known if max(s["motors"]) == 0 and s["position"][2] >= FLOOR_Z_M), None)
    floor = next((t for t, s in known if s["position"][2] < FLOOR_Z_M), None)
    max_dev = max(distance(s) for _, s in known)
    min_z = min(s["position"][2] for _, s in known)
    final = known[-1][1]
    # the final stretch the vehicle was safe in, and since when
    safe_kind, safe_at = None, None
    if floor_off(final):
        k = len(known)
        while k > 0 and floor_off(known[k - 1][1]):
            k -= 1
        safe_kind, safe_at = "floor", known[k][0]
    elif hover_ok(final):
        k = len(known)
        while k > 0 and hover_ok(known[k - 1][1]):
            k -= 1
        safe_kind, safe_at = "hover", (0.0 if k == 0 else known[k][0])
    touchdown = None
    if floor is not None:
        before = [s for t, s in known if floor - 0.3 <= t <= floor]
        touchdown = max(-s["velocity"][2] for s in before) if before else None
    parts = []
    if safe_kind == "hover" and safe_at == 0.0:
        parts.append("keeps hovering (max %.3f m from the goal)" % max_dev)
    elif safe_kind == "hover":
        parts.append("leaves the hover (max %.2f m from the goal, down to z %.2f m), back under control" %
                     (max_dev, min_z))
    elif floor is not None:
        how = "falls" if touchdown is not None and touchdown > FALL_SPEED_MS else "descends"
        if motors_off is not None and motors_off <= floor:
            parts.append("motors off at +%.2f s, %s: on the floor at +%.2f s (%.1f m/s)" %
                         (motors_off, how, floor, touchdown or 0.0))
        else:
            parts.append("%s: on the floor at +%.2f s (%.1f m/s)%s" % (
                how, floor, touchdown or 0.0, ", motors off after" if safe_kind == "floor" else ", motors on"))
    else:
        parts.append("still flying after %.0f s: %.2f m from the goal (max %.2f m), z %.2f m" %
                     (t_end - t_fault, distance(final), max_dev, final["position"][2]))
    if gap:
        parts.append("world gone %.1f-%.1f s" % out["world_gone_s"])
    out["does"] = "; ".join(parts)
    out["safe"] = None if safe_kind is None else ("%s %.2f s" % ("hovering after" if safe_kind == "hover"
                                                                  else "on the floor, motors off, after", safe_at))
    out["safe_s"] = safe_at
    out["safe_kind"] = safe_kind
    return out


def reports(rec: Recorder, t_fault: float, t_end: float) -> List[str]:
    """Where the fault showed: first warning/error line per node, non-OK diagnostics, status, controller."""
    out: List[str] = []
    seen_nodes = set()
    for t, m in rec.since("rosout", t_fault):
        if t > t_end or m.level < 4 or m.name in seen_nodes or m.name == "/bench_faults":      # 4: WARN
            continue
        seen_nodes.add(m.name)
        text = m.msg.replace("\n", " ")
        out.append("log %s +%.1fs %s: %s" % ({4: "WARN", 8: "ERROR", 16: "FATAL"}.get(m.level, m.level),
                                            t - t_fault, m.name.lstrip("/"), text[:110]))
    seen_diag = set()
    for t, arr in rec.since("diagnostics", t_fault):
        if t > t_end:
            continue
        for st in arr.status:
            if st.level >= 1 and st.name not in seen_diag:
                seen_diag.add(st.name)
                out.append("diagnostics +%.1fs %s [%s]: %s" % (t - t_fault, st.name,
                                                               ("OK", "WARN", "ERROR", "STALE")[min(st.level, 3)],
                                                               st.message[:90]))
    for t, st in rec.since("status", t_fault):
        if t <= t_end and st.message != "running":
            out.append("/%s/status +%.1fs: %s" % (NAME, t - t_fault, st.message[:90]))
            break
    states = [(t, s) for t, s in rec.since("state", t_fault) if t <= t_end]
    if states:
        out.append("controller state: " + " -> ".join("%s (+%.1fs)" % (s, t - t_fault) for t, s in states[:4]))
    return out


# --- the rows ------------------------------------------------------------------------------------
def kill_node(bench: Bench, node: str, sig: int = signal.SIGKILL) -> None:
    os.kill(node_pid(node), sig)


def restart_world(bench: Bench) -> None:
    """Stop the sim node (Ctrl-C) and start it again with the same parameters (left on the master)."""
    pid = node_pid("/crazyflie_sim")
    os.kill(pid, signal.SIGINT)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except OSError:
            break
        time.sleep(0.05)
    script = os.path.join(REPO, "crazyflie_driver", "scripts", "crazyflie_sim_node")
    bench.graph.extra.append(subprocess.Popen([sys.executable, script, "__name:=crazyflie_sim"],
                                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                              start_new_session=True))


def emergency(bench: Bench) -> None:
    from std_srvs.srv import Empty
    bench.rospy.ServiceProxy("/%s/emergency" % NAME, Empty)()


def remove(bench: Bench) -> None:
    """``/remove_crazyflie`` while it flies (the controller keeps publishing its setpoints)."""
    from crazyflie_driver.srv import RemoveCrazyflie
    bench.rospy.ServiceProxy("/remove_crazyflie", RemoveCrazyflie)(uri=URI)


GO_TO_PERIOD_S = 0.1     # another client's go_to while the server lands the Crazyflie


def go_to_request(goal: Tuple[float, float, float], group_mask: int = 0):
    import rospy
    from crazyflie_driver.srv import GoTo
    req = GoTo._request_class(groupMask=group_mask, relative=False, yaw=0.0, duration=rospy.Duration(1.0))
    req.goal.x, req.goal.y, req.goal.z = goal
    return req


def remove_with_go_to(bench: Bench) -> None:
    """``/remove_crazyflie`` while it flies, and meanwhile another client's go_to (to the goal) every 0.1 s
    until the removal answers: each one during the server's landing must be refused, not end it in the air."""
    from crazyflie_driver.srv import GoTo
    go_to = bench.rospy.ServiceProxy("/%s/go_to" % NAME, GoTo)
    done = threading.Event()
    said: List[str] = []

    def meanwhile() -> None:
        while not done.is_set():
            try:
                go_to(go_to_request(GOAL))
                said.append("ok")
            except (bench.rospy.ServiceException, bench.rospy.ROSException) as e:
                said.append("refused" if "refused" in str(e) else "failed")
            time.sleep(GO_TO_PERIOD_S)
    thread = threading.Thread(target=meanwhile, daemon=True)
    thread.start()
    try:
        remove(bench)
    finally:
        done.set()
        thread.join(2.0)
    print("  go_to during the removal: %s" % ", ".join("%d %s" % (said.count(k), k) for k in ("ok", "refused",
                                                                                           "failed")))


def refused_call(service: str, **fields: Any) -> Callable[[Bench], None]:
    """A ``land`` (height, duration_s) or ``go_to`` (goal, group_mask) of ``/crazyflie1`` that the server
    should refuse, nothing sent: the answer is printed; the row's truth says whether it kept hovering."""
    def act(bench: Bench) -> None:
        from crazyflie_driver.srv import GoTo, Land
        try:
            if service == "go_to":
                bench.rospy.ServiceProxy("/%s/go_to" % NAME, GoTo)(go_to_request(fields["goal"], fields["group_mask"]))
            else:
                bench.rospy.ServiceProxy("/%s/land" % NAME, Land)(
                    groupMask=0, height=fields["height"], duration=bench.rospy.Duration(fields["duration_s"]))
            print("  %s: accepted" % service)
        except bench.rospy.ServiceException as e:
            print("  %s refused: %s" % (service, str(e)[:160]))
    return act


def streamed_then_silent(bench: Bench) -> None:
    """Position setpoints streamed at the goal for 1 s (50 Hz), then none: a setpoint source gone silent."""
    from crazyflie_driver.msg import Position
    pub = bench.rospy.Publisher("/%s/cmd_position" % NAME, Position, queue_size=1, tcp_nodelay=True)
    deadline = time.monotonic() + 5.0
    while pub.get_num_connections() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        pub.publish(Position(x=GOAL[0], y=GOAL[1], z=GOAL[2], yaw=0.0))
        time.sleep(0.02)
    pub.unregister()


def clear(bench: Bench) -> None:
    fault("clear")


def sleep_then(seconds: float, words: str) -> Callable[[Bench], None]:
    def act(bench: Bench) -> None:
        time.sleep(seconds)
        fault(words)
    return act


def both(*acts: Callable[[Bench], None]) -> Callable[[Bench], None]:
    def act(bench: Bench) -> None:
        for a in acts:
            a(bench)
    return act


def inject(words: str) -> Callable[[Bench], None]:
    return lambda bench: fault(words)


def battery_levels() -> Tuple[float, float, float, str]:
    """Voltages for the battery rows (what pm.vbat reads under the hover load right after the fault):
    between the stack's warning and critical levels, below its critical level, and below the firmware's
    cut-off; the stack's levels are its defaults where it has them, else the firmware's own."""
    from crazyflie_driver.sim.world import battery as firmware
    try:
        from crazyflie_driver.server.safety import SafetyConfig
        config = SafetyConfig()
        warning, critical, source = config.battery_warning_v, config.battery_critical_v, "the server's safety"
    except (ImportError, AttributeError):
        warning, critical, source = firmware.LOW_VOLTAGE, firmware.CRITICAL_VOLTAGE, "the firmware's"
    return round((warning + critical) / 2.0, 2), round(critical - 0.05, 2), firmware.CRITICAL_VOLTAGE - 0.05, source


def rows() -> List[Row]:
    warning_v, critical_v, empty_v, source = battery_levels()
    full = lambda b: fault("battery %s 100%%" % NAME)   # noqa: E731
    return [
        Row("loss30", "30 % packet loss", "chapter", inject("loss 0 --packet 0.3"), 6.0, clear),
        Row("loss80", "80 % packet loss", "chapter", inject("loss 0 --packet 0.8"), 6.0, clear),
        Row("ackloss", "50 % ack loss", "chapter", inject("loss 0 --ack 0.5"), 6.0, clear),
        Row("latency", "50 ms radio latency", "chapter", inject("latency 0 50ms"), 6.0, clear),
        Row("unplug1", "dongle unplugged for 1 s", "chapter", both(inject("unplug 0"), sleep_then(1.0, "replug 0")),
            9.0, clear),
        Row("unplug", "dongle unplugged for good", "chapter", inject("unplug 0"), 8.0, clear),
        Row("unplug_onboard", "dongle unplugged for good", "onboard", inject("unplug 0"), 8.0, clear),
        Row("poweroff", "Crazyflie switched off", "chapter", inject("power %s off" % NAME), 4.0,
            lambda b: fault("power %s on" % NAME)),
        Row("controller", "controller killed (SIGKILL): setpoint source silent", "chapter",
            lambda b: kill_node(b, "/%s/controller" % NAME), 10.0),
        Row("server", "server killed (SIGKILL)", "chapter", lambda b: kill_node(b, "/crazyflie_server"), 6.0),
        Row("server_int", "server stopped (Ctrl-C)", "chapter",
            lambda b: kill_node(b, "/crazyflie_server", signal.SIGINT), 10.0),
        Row("server_onboard", "server killed (SIGKILL)", "onboard", lambda b: kill_node(b, "/crazyflie_server"), 8.0),
        Row("server_keepalive", "server killed (SIGKILL)", KEEPALIVE, lambda b: kill_node(b, "/crazyflie_server"),
            8.0),
        Row("unplug_keepalive", "dongle unplugged for good", KEEPALIVE, inject("unplug 0"), 8.0, clear),
        Row("server_int_onboard", "server stopped (Ctrl-C)", "onboard",
            lambda b: kill_node(b, "/crazyflie_server", signal.SIGINT), 8.0),
        Row("silent_onboard", "setpoints streamed for 1 s, then silent (times from the stream start)", "onboard",
            streamed_then_silent, 8.0),
        Row("remove", "/remove_crazyflie while flying", "chapter", remove, 10.0),
        Row("remove_onboard", "/remove_crazyflie while flying", "onboard", remove, 8.0),
        Row("remove_go_to_onboard", "/remove_crazyflie while flying, another client's go_to every 0.1 s", "onboard",
            remove_with_go_to, 8.0),
        Row("land0_onboard", "land with duration 0 (refused: motors off in the air)", "onboard",
            refused_call("land", height=0.0, duration_s=0.0), 4.0),
        Row("land_up_onboard", "land to 1.9 m, above the Crazyflie (refused: a climb, then a fall)", "onboard",
            refused_call("land", height=1.9, duration_s=2.0), 5.0),
        Row("go_to_nobody_onboard", "go_to with a group mask addressing nobody (refused)", "onboard",
            refused_call("go_to", goal=(GOAL[0], GOAL[1], GOAL[2] + 0.5), group_mask=2), 4.0),
        Row("freeze02", "mocap frozen 0.2 s", "chapter", inject("mocap %s --freeze 0.2" % NAME), 5.0, clear),
        Row("freeze2", "mocap frozen 2 s", "chapter", inject("mocap %s --freeze 2" % NAME), 8.0, clear),
        Row("freeze", "mocap frozen for good", "chapter", inject("mocap %s --freeze" % NAME), 10.0, clear),
        Row("hide", "mocap lost for good (body hidden)", "chapter", inject("mocap %s --hide" % NAME), 8.0, clear),
        Row("battery_warn", "battery at warning (%.2f V; levels: %s)" % (warning_v, source), "chapter",
            inject("battery %s %.2f" % (NAME, warning_v)), 8.0, full),
        Row("battery_crit", "battery at critical (%.2f V; levels: %s)" % (critical_v, source), "chapter",
            inject("battery %s %.2f" % (NAME, critical_v)), 12.0, full),
        Row("battery_crit_onboard", "battery at critical (%.2f V; levels: %s)" % (critical_v, source), "onboard",
            inject("battery %s %.2f" % (NAME, critical_v)), 10.0, full),
        Row("battery_empty", "battery below the firmware's cut-off (%.2f V)" % empty_v, "chapter",
            inject("battery %s %.2f" % (NAME, empty_v)), 10.0, full),
        Row("emergency", "emergency while flying", "chapter", emergency, 3.0),
        Row("emergency_onboard", "emergency while flying", "onboard", emergency, 3.0),
        Row("world", "world restarted", "chapter", restart_world, 10.0),
    ]


# --- output --------------------------------------------------------------------------------------
def table(results: List[Tuple[Row, Dict[str, Any]]]) -> List[str]:
    lines = []
    for row, r in results:
        if "error" in r:
            lines += ["%s (%s): bench error: %s" % (row.title, row.path, r["error"]), ""]
            continue
        lines.append("%s (%s path)" % (row.title, row.path))
        lines.append("  does:     %s" % r["does"])
        lines.append("  safe:     %s" % (r["safe"] or "not within the %.0f s observed" % row.observe_s))
        for i, where in enumerate(r["reported"] or ["nowhere"]):
            lines.append("  %s %s" % ("reported:" if i == 0 else "         ", where))
        lines.append("  lost:     %s" % ("; ".join(r["lost"]) or "nothing counted"))
        lines.append("  (bench: %.1f s to a hover before the fault%s)" % (
            r["setup_s"], "" if r["setup_s"] else ": the graph of the row before"))
        lines.append("")
    return lines


def markdown(results: List[Tuple[Row, Dict[str, Any]]]) -> List[str]:
    """The README's short table: one line per row."""
    out = ["| fault | path | what the stack does | safe state after | reported | lost |", "|---|---|---|---|---|---|"]
    for row, r in results:
        if "error" in r:
            out.append("| %s | %s | bench error: %s | | | |" % (row.title, row.path, r["error"]))
            continue
        where = sorted({w.split(" +")[0].replace("log WARN", "log").replace("log ERROR", "log")
                        .replace("log FATAL", "log") for w in r["reported"] if not w.startswith("controller")})
        if any(w.startswith("controller") for w in r["reported"]):
            where.append("controller state")
        safe = "—" if r.get("safe_s") is None else "%.2f s (%s)" % (
            r["safe_s"], "hover" if r["safe_kind"] == "hover" else "floor, motors off")
        out.append("| %s | %s | %s | %s | %s | %s |" % (row.title, row.path, r["does"], safe,
                                                        ", ".join(where) or "nowhere",
                                                        "; ".join(r["lost"]) or "—"))
    return out


# rows that usually leave the vehicle hovering first, so the graph is reused; the table keeps rows()'s order
RUN_FIRST = ("loss30", "loss80", "ackloss", "latency", "freeze02", "freeze2", "battery_warn", "unplug1")

README_TABLE = "README table:"


def previous_table(path: str) -> Tuple[List[str], Dict[str, Tuple[List[str], str]]]:
    """An earlier table file's head lines and its rows by key: (detail lines, README line); empty if none.

    Rows are found by their title and path, as :func:`table` and :func:`markdown` write them."""
    try:
        with open(path) as f:
            text = f.read()
    except OSError:
        return [], {}
    detail, _, short = text.partition("\n%s\n" % README_TABLE)
    blocks = detail.split("\n\n")
    head = blocks[0].split("\n") if blocks else []
    found: Dict[str, Tuple[List[str], str]] = {}
    for r in rows():
        starts = ("%s (%s path)" % (r.title, r.path), "%s (%s): bench error" % (r.title, r.path))
        block = next((b for b in blocks[1:] if b.strip("\n").split("\n")[0].startswith(starts)), None)
        line = next((x for x in short.split("\n") if x.startswith("| %s | %s |" % (r.title, r.path))), None)
        if block is not None and line is not None:
            found[r.key] = (block.strip("\n").split("\n") + [""], line)
    return head, found


def write(args: argparse.Namespace, results: List[Tuple[Row, Dict[str, Any]]], commit: str, took: float,
          partial: bool) -> None:
    """The table of ``results``; with ``--rows``, merged by row key into the table already in ``--out``
    (the rows not run keep their earlier lines, the head says which rows were measured again)."""
    results = sorted(results, key=lambda rr: [r.key for r in rows()].index(rr[0].key))
    if args.rows and args.out != "-":
        previous_head, previous = previous_table(args.out)
        if previous:
            write_merged(args, results, commit, took, partial, previous_head, previous)
            return
    head = ["fault table: one Crazyflie hovering at (0, 0, 0.5) in the full ROS stack (crazyflie_sim_node with "
            "Vicon-style mocap at 100 Hz, crazyflie_server over the fake Crazyradio; path chapter: the chapter's "
            "controller node; path onboard: the high-level commander with the mocap as external_position; "
            "path onboard+keep-alive: the same with the server's emergency-stop watchdog keep-alive on)",
            "safe = on the floor with the motors off, or within %.2f m of the goal and slower than %.1f m/s until "
            "the row ends; times from the fault; truth sampled at %.0f Hz" % (HOVER_TOLERANCE_M, HOVER_SPEED_MS,
                                                                             SAMPLE_HZ),
            "command: flock /tmp/ros.lock bench/bench_faults.py --readme   (%.0f s for %d rows%s)" % (
                took, len(results), ", run still going" if partial else ""),
            "stack at: %s" % commit,
            "machine: %s, %s, Python %s, %d CPUs, load average %s" % (
                platform.machine(), platform.platform(terse=True), platform.python_version(), os.cpu_count() or 0,
                " ".join("%.2f" % x for x in os.getloadavg())),
            ""]
    text = "\n".join(head + table(results) + ["", README_TABLE, ""] + markdown(results)) + "\n"
    if args.out == "-":
        if not partial:
            print("\n".join(markdown(results)))
        return
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        f.write(text)
    if args.readme:
        update_readme(markdown(results))
    if not partial:
        print("written to %s (%.0f s)" % (args.out, took))


def write_merged(args: argparse.Namespace, results: List[Tuple[Row, Dict[str, Any]]], commit: str, took: float,
                 partial: bool, previous_head: List[str], previous: Dict[str, Tuple[List[str], str]]) -> None:
    new = {row.key: (row, r) for row, r in results}
    detail, short = [], markdown([])
    for row in rows():
        if row.key in new:
            detail += table([new[row.key]])
            short += markdown([new[row.key]])[2:]
        elif row.key in previous:
            detail += previous[row.key][0]
            short.append(previous[row.key][1])
    tag = "re-measured (--rows %s):" % args.rows
    head = [line for line in previous_head if line and not line.startswith(tag)]
    head += ["%s stack at %s, %.0f s for %d rows%s, load average %s" % (
        tag, commit, took, len(results), ", run still going" if partial else "",
        " ".join("%.2f" % x for x in os.getloadavg())), ""]
    with open(args.out, "w") as f:
        f.write("\n".join(head + detail + ["", README_TABLE, ""] + short) + "\n")
    if args.readme:
        update_readme(short)
    if not partial:
        print("merged into %s (%.0f s)" % (args.out, took))


README_MARKERS = ("<!-- fault table: bench/bench_faults.py --readme writes below -->", "<!-- fault table end -->")


def update_readme(lines: List[str]) -> None:
    path = os.path.join(REPO, "README.md")
    with open(path) as f:
        text = f.read()
    start, end = text.find(README_MARKERS[0]), text.find(README_MARKERS[1])
    if start < 0 or end < start:
        print("bench_faults: README.md has no fault-table markers; table not copied", file=sys.stderr)
        return
    text = text[:start + len(README_MARKERS[0])] + "\n" + "\n".join(lines) + "\n" + text[end:]
    with open(path, "w") as f:
        f.write(text)
    print("README.md fault table updated")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", help="comma-separated row keys (default: all): " + ",".join(r.key for r in rows()))
    ap.add_argument("--out", default=os.path.join(HERE, "results", "faults.txt"), help="'-' for stdout only")
    ap.add_argument("--readme", action="store_true",
                    help="also put the short table into README.md (between its fault-table markers)")
    args = ap.parse_args()
    chosen = rows()
    if args.rows:
        keys = args.rows.split(",")
        unknown = set(keys) - {r.key for r in chosen}
        if unknown:
            print("bench_faults: error: unknown rows %s" % ", ".join(sorted(unknown)), file=sys.stderr)
            return 1
        chosen = [r for r in chosen if r.key in keys]
    work = tempfile.mkdtemp(prefix="cf_faults_")
    port = free_port()
    os.environ["ROS_MASTER_URI"] = "http://127.0.0.1:%d" % port
    os.environ["ROS_LOG_DIR"] = os.path.join(work, "log")
    os.environ["CRAZYFLIE_TOC_CACHE"] = os.path.join(work, "toc")
    os.environ.setdefault("ROS_IP", "127.0.0.1")
    core = subprocess.Popen(["roscore", "-p", str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    commit = subprocess.run(["git", "-C", REPO, "log", "-1", "--format=%h %s"], stdout=subprocess.PIPE,
                            text=True).stdout.strip()[:100]
    t_start = time.monotonic()
    results: List[Tuple[Row, Dict[str, Any]]] = []
    bench = None
    try:
        import rosgraph
        deadline = time.monotonic() + 30.0
        while not rosgraph.is_master_online() and time.monotonic() < deadline:
            time.sleep(0.2)
        import rospy
        rospy.init_node("bench_faults", disable_signals=True)
        bench = Bench(work)
        order = sorted(chosen, key=lambda r: (r.path != "chapter", r.key not in RUN_FIRST,
                                              RUN_FIRST.index(r.key) if r.key in RUN_FIRST else 0))
        for row in order:
            print("%s (%s path) ..." % (row.title, row.path), flush=True)
            try:
                r = bench.run(row)
            except Exception as e:
                r = {"error": "%s: %s" % (type(e).__name__, e)}
                if bench.graph is not None:
                    bench.graph.stop()
                    bench.graph = None
            results.append((row, r))
            print("\n".join(table([(row, r)])), flush=True)
            if args.out != "-":                  # what is measured so far, should the run be cut short
                write(args, results, commit, time.monotonic() - t_start, partial=True)
    finally:
        if bench is not None:
            bench.close()
        os.killpg(core.pid, signal.SIGINT)
        try:
            core.wait(15)
        except subprocess.TimeoutExpired:
            os.killpg(core.pid, signal.SIGKILL)
    write(args, results, commit, time.monotonic() - t_start, partial=False)
    return 0 if all("error" not in r for _, r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
