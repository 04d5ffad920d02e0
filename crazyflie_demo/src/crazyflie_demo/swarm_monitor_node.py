"""``swarm_monitor``: records a simulated swarm flight on the world's truth and judges it.

Polls the world server (``~sim_address``, control ``poses``: every body at one instant of world
time) at ``~rate`` Hz, anchors each phase ``swarm_demo`` announces on ``~phase_topic`` at the world
time it hears of it and then at the world time each Crazyflie's commander began it, and compares
every Crazyflie's true position with its plan (``swarm_flight.Flight``). At ``done``: a summary line
per phase on the console, the plot (``~plot``, PNG) and ``ok`` or the reason in ``~result_file``;
then it exits, which ends the launch (it is the required node of ``swarm.launch monitor:=true``).
``~timeout`` (s) bounds the whole flight; ``~stats_file``: the figures as JSON too (benchmarks). Its
pacing and timeout are in ROS time (``ros_clock``: the world's under ``/use_sim_time``).

Verdict: every Crazyflie above 80 % of the takeoff height when the takeoff has settled, the
figure-8's swarm-mean tracking error below ``~max_figure8_error`` (m, MAX_FIGURE8_ERROR_M), every Crazyflie back on
the ground at the end.
"""
from __future__ import annotations

import json
import threading
from typing import Dict, List, Optional

import rospy
from std_msgs.msg import String

from crazyflie_demo.rosutil import RealTimeFactor
from crazyflie_demo.swarm_flight import Flight, Phase, plot_flight
from crazyflie_driver.clock import WALL, Clock
from crazyflie_driver.nodes.ros_clock import ros_clock
from crazyflie_driver.nodes.ros_signals import init_node, shutting_down
from crazyflie_driver.server.swarm.config import load_swarm_file

LANDED_Z_M = 0.05
MAX_FIGURE8_ERROR_M = 0.08     # m: the onboard Kalman filter tracks it at 4.3-5.4 cm mean for 1-49 (bench_swarm_flight)
START_READ_DELAY_S = 1.0        # world time after an announcement when every Crazyflie has the command


class SwarmRecorder:
    """World truth → ``Flight``; usable from a test (no ROS in the constructor but the subscriber).
    ``clock`` paces the polls and the waits."""

    def __init__(self, initial: Dict[str, tuple], sim_address: str, phase_topic: str, rate: float = 50.0,
                 clock: Clock = WALL) -> None:
        from crazyflie_driver.sim.air.medium import RemoteMedium, parse_address

        host, port = parse_address(sim_address)
        self.medium = RemoteMedium(host, port)
        self.flight = Flight(initial)
        self.rate = float(rate)
        self.clock = clock
        self.lock = threading.Lock()
        self.phases: List[Phase] = []
        self.done = threading.Event()
        self.starts_known = threading.Event()
        self._stop = threading.Event()
        self.last_poses: Optional[dict] = None
        self._thread = threading.Thread(target=self._poll, name="swarm-monitor", daemon=True)
        self._thread.start()
        self._sub = rospy.Subscriber(phase_topic, String, self._on_phase, queue_size=10)

    def _world_time(self) -> float:
        return float(self.medium.control("time"))

    def _on_phase(self, msg) -> None:
        phase = Phase.from_json(msg.data)
        anchor = self._world_time()
        with self.lock:
            index = self.flight.phase(phase, anchor)
            self.phases.append(phase)
        if phase.name == "done":
            self.clock.wait(self.starts_known, 5.0)
            self.done.set()
        else:
            self.starts_known.clear()
            threading.Thread(target=self._read_starts, args=(index, anchor), daemon=True).start()

    def _read_starts(self, index: int, anchor: float) -> None:
        """Once the command had time to arrive: when each Crazyflie's commander began it (world time)."""
        try:
            while self._world_time() < anchor + START_READ_DELAY_S and not self._stop.is_set():
                self.clock.sleep(0.05)
            for name in list(self.flight.tracks):
                begin = float(self.medium.control("vehicle_state", uri=name)["plan_begin"])
                if begin >= anchor - 1e-3:           # else the command never reached it: the anchor stays
                    with self.lock:
                        self.flight.set_start(index, name, begin)
        except Exception as e:
            if not shutting_down():
                rospy.logwarn("swarm_monitor: cannot read when the Crazyflies began a phase: %s", e)
        finally:
            self.starts_known.set()

    def _poll(self) -> None:
        period = 1.0 / self.rate
        while not self._stop.is_set():
            t0 = self.clock.now()
            try:
                poses = self.medium.control("poses")
            except Exception as e:           # the world went away: the flight is over for us
                if not self._stop.is_set() and not shutting_down():
                    rospy.logwarn_throttle(5.0, "swarm_monitor: cannot read the world: %s" % e)
                self.clock.wait(self._stop, 0.5)
                continue
            with self.lock:
                self.last_poses = poses
                self.flight.sample(poses["time"], dict(zip(poses["names"], poses["positions"])))
            self.clock.wait(self._stop, max(0.0, period - (self.clock.now() - t0)))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._sub.unregister()
        self.medium.close()

    def verdict(self, takeoff_height: float, max_figure8_error: float) -> str:
        """``ok`` or what went wrong (see the module's docstring)."""
        with self.lock:
            flight = self.flight
            tracks = flight.tracks
            takeoff = next((w for w in flight.windows if w[0] == "takeoff"), None)
            if takeoff is None:
                return "no takeoff announced"
            low = [n for n, tr in tracks.items()
                   if not any(t >= takeoff[2] - 0.2 and p[2] > 0.8 * takeoff_height
                              for t, p in zip(tr.times, tr.positions) if t <= takeoff[2] + 0.5)]
            if low:
                return "%d Crazyflies did not take off: %s" % (len(low), ", ".join(sorted(low)[:8]))
            fig = flight.phase_stats("figure8")
            if fig is None:
                return "no figure-8 flown"
            if fig["mean"] > max_figure8_error:
                return "figure-8 tracking error %.1f cm above %.1f cm" % (100 * fig["mean"], 100 * max_figure8_error)
            up = [n for n, tr in tracks.items() if not tr.positions or tr.positions[-1][2] > LANDED_Z_M]
            if up:
                return "%d Crazyflies did not land: %s" % (len(up), ", ".join(sorted(up)[:8]))
        return "ok"


def main() -> None:
    init_node("swarm_monitor")
    try:
        config = load_swarm_file(str(rospy.get_param("~swarm_file", "")))
    except Exception as e:
        rospy.logfatal("swarm_monitor: %s", e)
        raise SystemExit(1) from None
    initial = {cf.name: cf.initial_position for cf in config.crazyflies}
    recorder = SwarmRecorder(initial, str(rospy.get_param("~sim_address", "127.0.0.1:19840")),
                             str(rospy.get_param("~phase_topic", "/swarm_demo/phase")),
                             float(rospy.get_param("~rate", 50.0)), ros_clock())
    timeout = float(rospy.get_param("~timeout", 300.0))
    plot = str(rospy.get_param("~plot", ""))
    result_file = str(rospy.get_param("~result_file", ""))
    clock = recorder.clock
    started = clock.now()
    pace = RealTimeFactor()
    while not clock.wait(recorder.done, 0.5):
        if shutting_down():
            recorder.stop()
            return
        if clock.now() - started > timeout:
            break
    clock.sleep(0.5)                # the last samples after touchdown
    recorder.stop()
    result = recorder.verdict(float(rospy.get_param("~height", 1.0)),
                              float(rospy.get_param("~max_figure8_error", MAX_FIGURE8_ERROR_M))) \
        if recorder.done.is_set() else "the flight did not finish within %.0f s" % timeout
    for line in recorder.flight.summary_lines() + [pace.line()]:
        print("swarm: " + line, flush=True)
    if plot:
        try:
            plot_flight(recorder.flight, plot, "%d simulated Crazyflies on %d Crazyradios: takeoff, figure-8, "
                        "formation, land" % (len(initial), config.dongles_needed))
            print("swarm: plot written to %s" % plot, flush=True)
        except Exception as e:       # a missing matplotlib must not hide the verdict
            rospy.logerr("swarm_monitor: plot failed: %s", e)
    print("swarm: result: %s" % result, flush=True)
    if result_file:
        with open(result_file, "w") as f:
            f.write(result + "\n")
    stats_file = str(rospy.get_param("~stats_file", ""))
    if stats_file:
        with open(stats_file, "w") as f:
            json.dump(dict(recorder.flight.stats(), result=result), f)
