"""The fault table's harness: the ROS graph around one simulated Crazyflie, the recorders of its topics
and of the world's truth, ``Bench.run`` (one row: hover, inject, observe) and the reading of the truth."""
from __future__ import annotations

import contextlib
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Iterator, List, Optional, Tuple

from bench_support import REPO  # noqa: E402,F401  (the repository root, for the rows and the report)

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
    import xmlrpc.client

    import rosgraph
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
        return cleaned_up(row, self, result)

    def close(self) -> None:
        self.truth.stop()
        if self.graph is not None:
            self.graph.stop()


def cleaned_up(row: Any, bench: Any, result: Dict[str, Any]) -> Dict[str, Any]:
    """``result`` after the row's cleanup (a failed cleanup is noted in it, not raised)."""
    try:
        row.cleanup(bench)
    except Exception as e:
        result["cleanup_error"] = str(e)
    return result


def log_packets_lost(status) -> int:
    for kv in status.values:
        if kv.key == "log_packets_lost":
            try:
                return int(kv.value)
            except ValueError:
                return 0
    return 0


# --- reading the truth ---------------------------------------------------------------------------
def distance(s: Dict[str, Any], goal: Tuple[float, float, float] = GOAL) -> float:
    return math.dist(s["position"], goal)


def speed(s: Dict[str, Any]) -> float:
    return math.sqrt(sum(v * v for v in s["velocity"]))


def hover_ok(s: Dict[str, Any], goal: Tuple[float, float, float] = GOAL) -> bool:
    return distance(s, goal) < HOVER_TOLERANCE_M and speed(s) < HOVER_SPEED_MS


def floor_off(s: Dict[str, Any]) -> bool:
    return s["position"][2] < FLOOR_Z_M and max(s["motors"]) == 0


def analyse(samples: List[Tuple[float, Optional[Dict[str, Any]]]], t_fault: float, t_end: float,
            goal: Tuple[float, float, float] = GOAL) -> Dict[str, Any]:
    """What the vehicle did after the fault, from the truth samples of the row (hovering at ``goal``)."""
    out: Dict[str, Any] = {}
    known = [(t - t_fault, s) for t, s in samples if s is not None]
    gap = [t - t_fault for t, s in samples if s is None]
    if gap:
        out["world_gone_s"] = (min(gap), max(gap))
    if not known:
        out["does"] = "no truth: the world never answered"
        out["safe"] = None
        return out
    max_dev = max(distance(s, goal) for _, s in known)
    safe_kind, safe_at = safe_stretch(known, goal)
    parts = [outcome(known, goal, safe_kind, safe_at, max_dev, t_end - t_fault)]
    if gap:
        parts.append("world gone %.1f-%.1f s" % out["world_gone_s"])
    out["does"] = "; ".join(parts)
    out["max_dev"] = max_dev
    out["safe"] = None if safe_kind is None else ("%s %.2f s" % ("hovering after" if safe_kind == "hover"
                                                                  else "on the floor, motors off, after", safe_at))
    out["safe_s"] = safe_at
    out["safe_kind"] = safe_kind
    return out


Known = List[Tuple[float, Dict[str, Any]]]      # (s after the fault, truth sample)


def safe_stretch(known: Known, goal: Tuple[float, float, float]) -> Tuple[Optional[str], Optional[float]]:
    """The final stretch the vehicle was safe in and since when (s after the fault): ("floor", t) resting
    with its motors off, ("hover", t) back at ``goal`` (t 0.0: it never left), or (None, None)."""
    final = known[-1][1]
    if floor_off(final):
        k = len(known)
        while k > 0 and floor_off(known[k - 1][1]):
            k -= 1
        return "floor", known[k][0]
    if hover_ok(final, goal):
        k = len(known)
        while k > 0 and hover_ok(known[k - 1][1], goal):
            k -= 1
        return "hover", (0.0 if k == 0 else known[k][0])
    return None, None


def touchdown_speed(known: Known, floor: float) -> Optional[float]:
    """The highest sink rate (m/s) in the 0.3 s before the vehicle reached the floor at ``floor`` s."""
    before = [s for t, s in known if floor - 0.3 <= t <= floor]
    return max(-s["velocity"][2] for s in before) if before else None


def outcome(known: Known, goal: Tuple[float, float, float], safe_kind: Optional[str], safe_at: Optional[float],
            max_dev: float, span_s: float) -> str:
    """What the vehicle did in words: kept or regained the hover, came down (how, when), or still flies."""
    floor = next((t for t, s in known if s["position"][2] < FLOOR_Z_M), None)
    if safe_kind == "hover" and safe_at == 0.0:
        return "keeps hovering (max %.3f m from the goal)" % max_dev
    if safe_kind == "hover":
        return "leaves the hover (max %.2f m from the goal, down to z %.2f m), back under control" % (
            max_dev, min(s["position"][2] for _, s in known))
    if floor is not None:
        motors_off = next((t for t, s in known if max(s["motors"]) == 0 and s["position"][2] >= FLOOR_Z_M), None)
        return landing_text(motors_off, floor, touchdown_speed(known, floor), safe_kind == "floor")
    final = known[-1][1]
    return "still flying after %.0f s: %.2f m from the goal (max %.2f m), z %.2f m" % (
        span_s, distance(final, goal), max_dev, final["position"][2])


def landing_text(motors_off: Optional[float], floor: float, touchdown: Optional[float], off_after: bool) -> str:
    """How it came down: motors off in the air first (``motors_off`` s) or not, fell or descended (by the
    ``touchdown`` speed), on the floor at ``floor`` s, its motors off after (``off_after``) or on."""
    how = "falls" if touchdown is not None and touchdown > FALL_SPEED_MS else "descends"
    if motors_off is not None and motors_off <= floor:
        return "motors off at +%.2f s, %s: on the floor at +%.2f s (%.1f m/s)" % (
            motors_off, how, floor, touchdown or 0.0)
    return "%s: on the floor at +%.2f s (%.1f m/s)%s" % (
        how, floor, touchdown or 0.0, ", motors off after" if off_after else ", motors on")


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


# --- a bench run's ROS master --------------------------------------------------------------------
def chosen(all_rows: List[Any], keys: Optional[str], prog: str) -> Optional[List[Any]]:
    """The rows ``--rows`` names (all without it), in ``all_rows``' order; None (said on stderr) for an
    unknown key."""
    if not keys:
        return list(all_rows)
    wanted = keys.split(",")
    unknown = set(wanted) - {r.key for r in all_rows}
    if unknown:
        print("%s: error: unknown rows %s" % (prog, ", ".join(sorted(unknown))), file=sys.stderr)
        return None
    return [r for r in all_rows if r.key in wanted]


def commit_line() -> str:
    """The stack's commit, for the table's head."""
    return subprocess.run(["git", "-C", REPO, "log", "-1", "--format=%h %s"], stdout=subprocess.PIPE,
                          text=True).stdout.strip()[:100]


@contextlib.contextmanager
def bench_master(prefix: str, node: str) -> Iterator[str]:
    """A private roscore on a free port (logs and TOC cache in a fresh work folder, yielded) with this
    process as the node ``node``; the master is stopped on the way out."""
    from bench_support import free_port
    work = tempfile.mkdtemp(prefix=prefix)
    port = free_port()
    os.environ["ROS_MASTER_URI"] = "http://127.0.0.1:%d" % port
    os.environ["ROS_LOG_DIR"] = os.path.join(work, "log")
    os.environ["CRAZYFLIE_TOC_CACHE"] = os.path.join(work, "toc")
    os.environ.setdefault("ROS_IP", "127.0.0.1")
    core = subprocess.Popen(["roscore", "-p", str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        import rosgraph
        deadline = time.monotonic() + 30.0
        while not rosgraph.is_master_online() and time.monotonic() < deadline:
            time.sleep(0.2)
        import rospy
        rospy.init_node(node, disable_signals=True)
        yield work
    finally:
        os.killpg(core.pid, signal.SIGINT)
        try:
            core.wait(15)
        except subprocess.TimeoutExpired:
            os.killpg(core.pid, signal.SIGKILL)


Results = List[Tuple[Any, Dict[str, Any]]]


def run_rows(make_bench: Callable[[str], Any], rows: List[Any], prefix: str, node: str,
             announce: Callable[[Any], str], show: Callable[[Any, Dict[str, Any]], List[str]],
             after_each: Callable[[Results], None] = lambda results: None) -> Results:
    """Each row on one bench (``make_bench(work folder)``) under a private master, in the given order.
    A row that raises is recorded as ``{"error": ...}``, its ROS graph stopped, and the run goes on;
    ``after_each`` sees the results so far (to write what is measured should the run be cut short)."""
    results: Results = []
    bench = None
    with bench_master(prefix, node) as work:
        try:
            bench = make_bench(work)
            for row in rows:
                print(announce(row), flush=True)
                try:
                    r = bench.run(row)
                except Exception as e:
                    r = {"error": "%s: %s" % (type(e).__name__, e)}
                    if bench.graph is not None:
                        bench.graph.stop()
                        bench.graph = None
                results.append((row, r))
                print("\n".join(show(row, r)), flush=True)
                after_each(results)
        finally:
            if bench is not None:
                bench.close()
    return results
