"""What the benchmarks share: the source tree on the path, their common arguments, header lines and tables,
percentiles, a world server served in this process, and one ROS graph per case in a child process
with the simulated world (the unmodified ``crazyflie_sim`` node) running inside it, where a bench
can tap the simulated air.

Import it first thing in a bench (``import bench_support``: it puts the packages' sources on the
path and the tests' ``support`` package, whose ``served_world`` and ``free_port`` it passes on).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import threading
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
RESULTS = os.path.join(HERE, "results")
PACKAGES = ("crazyflie_driver", "crazyflie_controller", "crazyflie_demo", "crazyflie_tools")
for _package in PACKAGES:          # the catkin devel space (messages, services) when sourced, else the sources
    if importlib.util.find_spec(_package) is None:
        sys.path.insert(0, os.path.join(REPO, _package, "src"))
# the tests' helper packages: ``support`` (driver) and ``controller_support`` (world flights)
TEST_SUPPORT = os.path.join(REPO, "crazyflie_driver", "test")
for _support in (TEST_SUPPORT, os.path.join(REPO, "crazyflie_controller", "test")):
    if _support not in sys.path:
        sys.path.append(_support)

from support.ports import free_port  # noqa: E402,F401  (one home for tests and benches; benches take it from here)
from support.served_world import served_world  # noqa: E402,F401  (likewise)

# --- the chapter's controller gains ---------------------------------------------------------------
CONTROLLER_CONFIG = os.path.join(REPO, "crazyflie_controller", "config", "crazyflie2.yaml")


def chapter_gains() -> tuple:
    """(X, Y, Z, Yaw) ``PidGains`` of crazyflie_controller/config/crazyflie2.yaml: read from the file the
    controller node loads, so a figure is never measured with gains that drifted from the ones users fly."""
    import yaml

    from crazyflie_controller.pid import PidGains
    with open(CONTROLLER_CONFIG) as f:
        pids = yaml.safe_load(f)["PIDs"]
    return tuple(PidGains.from_params(pids[axis], axis) for axis in ("X", "Y", "Z", "Yaw"))


# --- arguments and reports ---------------------------------------------------------------------
def parser(doc: str, result_name: str, seconds: float, counts: Optional[str] = None) -> argparse.ArgumentParser:
    """``--seconds`` (measured time per case), ``--counts`` (Crazyflies per case, comma separated,
    when the bench has cases by count) and ``--out`` (bench/results/<result_name>)."""
    ap = argparse.ArgumentParser(description=doc.strip().split("\n")[0])
    ap.add_argument("--seconds", type=float, default=seconds, help="measured time per case, s")
    if counts is not None:
        ap.add_argument("--counts", default=counts, help="Crazyflies per case, comma separated")
    ap.add_argument("--out", default=os.path.join(RESULTS, result_name), help="where the table goes")
    return ap


def counts_of(text: str) -> List[int]:
    return [int(x) for x in text.split(",") if x.strip()]


def machine_line() -> str:
    return "machine: %s, %s, Python %s, %d CPUs, load average %s" % (
        platform.machine(), platform.platform(terse=True), platform.python_version(), os.cpu_count() or 0,
        " ".join("%.2f" % x for x in os.getloadavg()))


def write_lines(path: str, lines: Sequence[str]) -> None:
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("written to %s" % path)


class Table:
    """A bench's table, printed a row at a time as its cases finish (a long run shows its progress, a run cut
    short keeps what it measured), then written whole with its heading and notes.

    ``columns`` are (title, cell format) pairs; a cell format is a ``format()`` spec with a width: ``"14.2f"``,
    ``"10.0%"`` (a share shown in percent), ``"<6"`` (text on the left). Cells and titles sit on the right
    unless the spec says otherwise; a title takes its column's width and side, a cell of None shows ``-``.
    """

    def __init__(self, heading: Sequence[str], columns: Sequence[Tuple[str, str]]) -> None:
        self._specs = [spec if spec[:1] in "<>^" else ">" + spec for _, spec in columns]
        self._blanks = [re.match(r"[<>^]\d+", spec).group(0) for spec in self._specs]
        self.lines = list(heading) + [self._join(title for title, _ in columns)]
        print("\n".join(self.lines), flush=True)

    def _join(self, cells) -> str:
        return " ".join(format(cell, blank) for cell, blank in zip(cells, self._blanks))

    def row(self, *cells) -> str:
        """Formats one row (a cell per column), prints and keeps it; returns the line."""
        if len(cells) != len(self._specs):
            raise ValueError("a row of %d cells in a table of %d columns" % (len(cells), len(self._specs)))
        return self.add(" ".join(format("-", blank) if cell is None else format(cell, spec)
                                 for cell, spec, blank in zip(cells, self._specs, self._blanks)))

    def add(self, line: str) -> str:
        """A line of its own in the table (a case that failed, a warning): printed and kept."""
        print(line, flush=True)
        self.lines.append(line)
        return line

    def write(self, path: str, notes: Sequence[str] = ()) -> None:
        """Writes heading, rows and, after a blank line, ``notes``."""
        write_lines(path, self.lines + ([""] + list(notes) if notes else []))


def percentile(values: Sequence[float], p: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(round(p / 100.0 * (len(s) - 1))))]


def process_cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (all its threads), from /proc."""
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# --- a world server in this process ------------------------------------------------------------
class IdleVehicle:
    """A vehicle that accepts everything and does nothing (its clock: the wall clock)."""

    name = "bench"

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def time(self) -> float:
        return time.monotonic() - self._t0

    def read(self, name: str) -> float:
        return 0.0

    def param_defaults(self) -> Dict[str, float]:
        return {}

    def write_param(self, name: str, value: float) -> None:
        pass

    def set_rpyt(self, roll: float, pitch: float, yaw: float, thrust: int) -> None:
        pass

    def emergency_stop(self) -> None:
        pass


class IdleWorld:
    """The world contract without physics or ticks: for figures of the air and the server alone."""

    time = 0.0
    speed = 1.0

    def add_vehicle(self, name: str, **kw) -> IdleVehicle:
        return IdleVehicle()

    def add_tick_listener(self, fn, period) -> None:
        pass


# --- one ROS graph per case, the simulated world inside the bench's child process ---------------
def run_child(script: str, args: Sequence[str], timeout: float) -> dict:
    """Runs ``script --child OUT args`` (one ROS graph per case) and returns the JSON it left in OUT."""
    fd, out = tempfile.mkstemp(prefix="cf_bench_", suffix=".json")
    os.close(fd)
    os.unlink(out)
    result: dict = {}
    try:
        subprocess.run([sys.executable, os.path.abspath(script), "--child", out] + list(args), check=False,
                       timeout=timeout)
    except subprocess.TimeoutExpired:
        result["error"] = "the case did not finish in %.0f s" % timeout
    if os.path.exists(out):
        with open(out) as f:
            result.update(json.load(f))
        os.unlink(out)
    return result


def ros_graph_with_sim_node(launch_text: str, measure: Callable[[dict, subprocess.Popen], None], out: str,
                            prefix: str = "cf_bench_", env: Optional[Dict[str, str]] = None) -> None:
    """In the child: roslaunch ``launch_text`` on a free master port, then the ``crazyflie_sim`` node in
    this process (its parameters in the launch text, under ``crazyflie_sim/``), ``measure(result,
    roslaunch)`` in a thread of its own; ``measure`` ends the case with ``rospy.signal_shutdown``.
    The result dict is written to ``out`` as JSON; a graph that dies early ends the case with an error."""
    port = free_port()
    os.environ["ROS_MASTER_URI"] = "http://127.0.0.1:%d" % port
    work = tempfile.mkdtemp(prefix=prefix)
    launch = os.path.join(work, "bench.launch")
    with open(launch, "w") as f:
        f.write(launch_text)
    full_env = dict(os.environ, ROS_LOG_DIR=os.path.join(work, "log"),
                    CRAZYFLIE_TOC_CACHE=os.path.join(work, "toc"))
    full_env.update(env or {})
    roslaunch = subprocess.Popen(["roslaunch", "--port", str(port), launch], env=full_env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    result: dict = {"work": work}
    finished = threading.Event()
    try:
        import rosgraph
        deadline = time.monotonic() + 30.0
        while not rosgraph.is_master_online() and time.monotonic() < deadline:
            time.sleep(0.2)

        def watch() -> None:     # the graph died (e.g. a required node): end the case, do not hang
            roslaunch.wait()
            if finished.is_set():
                return
            import rospy
            result.setdefault("error", "roslaunch ended early (exit %s); logs in %s" % (roslaunch.returncode, work))
            rospy.signal_shutdown("roslaunch ended")

        def guarded() -> None:
            try:
                measure(result, roslaunch)
            except Exception as e:          # reported in the result
                result.setdefault("error", repr(e))
            finally:
                import rospy
                rospy.signal_shutdown("bench done")
        threading.Thread(target=watch, daemon=True).start()
        sys.argv = [sys.argv[0], "__name:=crazyflie_sim"]
        threading.Thread(target=guarded, daemon=True).start()
        from crazyflie_driver.nodes import sim_node
        sim_node.main()
    finally:
        finished.set()
        roslaunch.terminate()
        try:
            roslaunch.wait(20)
        except subprocess.TimeoutExpired:
            roslaunch.kill()
        with open(out, "w") as f:
            json.dump(result, f)


def wait_for_ros(seconds: float = 30.0) -> None:
    """In a measuring thread: until the in-process node has initialised rospy."""
    import rospy
    deadline = time.monotonic() + seconds
    while not rospy.core.is_initialized() and time.monotonic() < deadline:
        time.sleep(0.05)
