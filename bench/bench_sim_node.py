#!/usr/bin/env python3
"""CPU share of the ROS node ``crazyflie_sim_node`` (world + world server + motion-capture publishing).

For each fleet size the bench starts its own roscore (port 11611) and one ``crazyflie_sim_node``
with the vehicles on the floor of a grid, vicon-style motion capture at 100 Hz (tf and the
/vicon/<name>/<name> topics) and a subscriber to /tf in this process, so the node serialises and
sends every frame as it does when a controller listens. Over a window of ``--seconds`` of wall time
it reads the node's CPU time from /proc/<pid>/stat (user + system, all its threads) and the world
time from the world server, and prints the share of one core and the real-time factor the world
kept. CPU time, not wall time: a busy machine does not inflate the share.
The "flying" rows command every vehicle through the world server's radio (fake Crazyradio,
RemoteMedium) at 100 Hz from this process, as crazyflie_server would, with 2 % more than its hover
thrust, so all are airborne (climbing slowly) with motors, PIDs and radio traffic at work.
ROS runs take the machine-wide lock: flock /tmp/ros.lock /usr/bin/python3 bench/bench_sim_node.py
Writes bench/results/sim_node.txt.
"""
from __future__ import annotations

import argparse
import os
import platform
import signal
import subprocess
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
import bench_support  # noqa: E402,F401  (the sources and the tests' support on the path)

ROOT = os.path.join(HERE, "..")

MASTER_PORT = 11611
WORLD_ADDRESS = "127.0.0.1:19881"
CLK_TCK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (all threads) from /proc."""
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def vehicles_yaml(n: int) -> str:
    items = []
    for i in range(n):
        dongle, index = divmod(i, 8)          # eight Crazyflies per simulated dongle
        items.append("{uri: 'radio://%d/%d/2M/E7E7E7E7%02X', name: cf%d, x: %.1f, y: %.1f}"
                     % (dongle, 10 + 2 * index, 1 + i, i + 1, 0.5 * (i % 10), 0.5 * (i // 10)))
    return "[" + ", ".join(items) + "]"


def wait_for(predicate, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.1)
    raise RuntimeError("timed out waiting for %s" % what)


class Flyer:
    """Hover setpoints at 100 Hz for every vehicle through the world server's fake radio."""

    def __init__(self, n: int) -> None:
        from crazyflie_driver.protocol.commander import rpyt_packet
        from crazyflie_driver.sim.air.medium import RemoteMedium
        from crazyflie_driver.sim.room.physics import VehicleParams

        self.medium = RemoteMedium(WORLD_ADDRESS)
        hover = int(round(VehicleParams().hover_command() * 1.02))
        self._packets = []
        for i in range(n):
            dongle, index = divmod(i, 8)
            address = bytes.fromhex("E7E7E7E7%02X" % (1 + i))
            zero = rpyt_packet(0.0, 0.0, 0.0, 0)
            up = rpyt_packet(0.0, 0.0, 0.0, hover)
            self._packets.append((dongle, 10 + 2 * index, address, zero, up))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _send(self, dongle, channel, address, packet) -> None:
        data = packet.to_bytes() if hasattr(packet, "to_bytes") else bytes(packet)
        self.medium.transmit(dongle, channel, 2, address, data, True, 3)

    def start(self) -> None:
        for dongle, channel, address, zero, _ in self._packets:    # unlock the thrust
            self._send(dongle, channel, address, zero)
        self._thread.start()

    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            for dongle, channel, address, _, up in self._packets:
                self._send(dongle, channel, address, up)
            next_t += 0.01
            self._stop.wait(max(0.0, next_t - time.monotonic()))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.medium.close()


def measure(n: int, seconds: float, fly: bool, mocap: str) -> dict:
    import rospy
    from tf2_msgs.msg import TFMessage

    from crazyflie_driver.sim.air.medium import RemoteMedium

    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % MASTER_PORT)
    node = subprocess.Popen(["rosrun", "crazyflie_driver", "crazyflie_sim_node", "__name:=crazyflie_sim",
                             "_address:=%s" % WORLD_ADDRESS, "_vehicles:=%s" % vehicles_yaml(n),
                             "_mocap:=%s" % mocap, "_mocap_rate:=100.0"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    frames = [0]
    sub = rospy.Subscriber("/tf", TFMessage, lambda m: frames.__setitem__(0, frames[0] + 1), queue_size=100)
    control = RemoteMedium(WORLD_ADDRESS)
    flyer = None
    try:
        def world_up() -> bool:
            try:
                return control.control("time") > 0.5
            except Exception:
                return False
        wait_for(world_up, 30.0, "the sim node's world server")
        wait_for(lambda: frames[0] > 10, 30.0, "tf frames")
        pid = int(subprocess.check_output(["pgrep", "-f", "-n", "-s", str(os.getpgid(node.pid)),
                                           "crazyflie_sim_node"]).split()[0])
        if fly:
            flyer = Flyer(n)
            flyer.start()
        time.sleep(2.0)                                   # settle
        c0, w0, t0, f0 = cpu_seconds(pid), control.control("time"), time.monotonic(), frames[0]
        time.sleep(seconds)
        c1, w1, t1, f1 = cpu_seconds(pid), control.control("time"), time.monotonic(), frames[0]
        flying = None
        if fly:
            flying = sum(1 for i in range(n)
                         if control.control("vehicle_state", uri="radio://%d/%d/2M/E7E7E7E7%02X"
                                            % (i // 8, 10 + 2 * (i % 8), 1 + i))["position"][2] > 0.2)
        return {"n": n, "core": 100.0 * (c1 - c0) / (t1 - t0), "rtf": (w1 - w0) / (t1 - t0),
                "tf_hz": (f1 - f0) / (t1 - t0), "flying": flying}
    finally:
        if flyer is not None:
            flyer.stop()
        control.close()
        sub.unregister()
        os.killpg(os.getpgid(node.pid), signal.SIGINT)
        try:
            node.wait(10.0)
        except subprocess.TimeoutExpired:
            os.killpg(os.getpgid(node.pid), signal.SIGKILL)
            node.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fleets", default="2,10,49", help="comma-separated fleet sizes")
    ap.add_argument("--seconds", type=float, default=10.0, help="measuring window (wall seconds)")
    ap.add_argument("--mocap", default="vicon", help="~mocap of the node (vicon, vrpn, both, none)")
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    fleets = [int(x) for x in args.fleets.split(",") if x.strip()]
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % MASTER_PORT)
    os.environ["ROS_MASTER_URI"] = env["ROS_MASTER_URI"]
    core = subprocess.Popen(["roscore", "-p", str(MASTER_PORT)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    lines = ["crazyflie_sim_node CPU share (one process: world, world server, %s motion capture at 100 Hz with a /tf "
             "subscriber; %.0f s windows; CPU time from /proc)" % (args.mocap, args.seconds),
             "machine: %s, Python %s, %d CPUs, load average %.1f"
             % (platform.machine(), platform.python_version(), os.cpu_count() or 0, os.getloadavg()[0]),
             "%8s %8s %16s %14s %10s %8s" % ("vehicles", "state", "% of one core", "world/wall", "tf msg/s",
                                              "flying")]
    print("\n".join(lines), flush=True)
    try:
        import rospy
        wait_for(lambda: subprocess.run(["rosnode", "list"], env=env, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL).returncode == 0, 30.0, "roscore")
        rospy.init_node("bench_sim_node", anonymous=True, disable_signals=True)
        for n in fleets:
            for fly in (False, True):
                r = measure(n, args.seconds, fly, args.mocap)
                lines.append("%8d %8s %16.1f %13.2fx %10.1f %8s" % (
                    r["n"], "flying" if fly else "floor", r["core"], r["rtf"], r["tf_hz"],
                    "-" if r["flying"] is None else r["flying"]))
                print(lines[-1], flush=True)
    finally:
        os.killpg(os.getpgid(core.pid), signal.SIGINT)
        core.wait(20.0)
    lines.append("command: flock /tmp/ros.lock /usr/bin/python3 bench/bench_sim_node.py")
    if not args.no_write:
        with open(os.path.join(HERE, "results", "sim_node.txt"), "w") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
