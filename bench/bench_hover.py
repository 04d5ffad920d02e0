#!/usr/bin/env python3
"""Hover error of a simulated Crazyflie holding (0, 0, 0.5) for 20 s, flown through the fake radio.

The chapter's position controller (crazyflie_controller.PositionController, gains of
crazyflie2.yaml, default take-off hand-over) reads the world's motion-capture model (MocapModel
defaults: 100 Hz, 0.5 mm and 0.2 deg white noise, 8 ms latency; seeded) and its cmd_vel goes
through crazyflie_server's RPYT mapping into Crazyflie.send_setpoint: RadioLink -> Crazyradio ->
fake USB dongle (instant) -> LocalMedium -> SimulatedCrazyflie -> World (crazyflie_driver/test/support/radio_rig.py).
The benchmark steps the world between setpoints, so the flight is deterministic per seed.

Per run: take-off, then two hold windows of ``--hold`` s, starting ``--early`` and ``--settle`` s after the
controller's setpoint reached the goal (the chapter's Z loop is still ringing down in the early one);
for each it reports the RMS and the maximum of the true 3-D position error and per-axis RMS / mean,
plus the world-time / wall-time factor of the whole loop. The real-time factor of World.step
alone for 1, 10, 49 and 100 vehicles is bench/bench_world.py's job (bench/results/world.txt).
Run: /usr/bin/python3 bench/bench_hover.py   (writes bench/results/hover.txt)
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))

import bench_support as bs  # noqa: E402  (the sources and the tests' support on the path)
from support.radio_rig import RadioRig  # noqa: E402

GOAL = np.array([0.0, 0.0, 0.5])
RUNS = (("current", 50.0), ("current", 100.0), ("2016.02", 50.0))   # firmware, controller rate [Hz]


def controller():
    """The chapter's controller with crazyflie2.yaml's gains, or None when the package is missing."""
    try:
        from crazyflie_controller.position_controller import ControllerConfig, PositionController
    except ImportError:
        return None
    x, y, z, yaw = bs.chapter_gains()
    return PositionController(ControllerConfig(x, y, z, yaw))


def figures(errors: np.ndarray) -> dict:
    norm = np.linalg.norm(errors, axis=1)
    return {"rms": float(np.sqrt(np.mean(norm ** 2))), "max": float(norm.max()),
            "rms_axes": np.sqrt(np.mean(errors ** 2, axis=0)), "mean_axes": errors.mean(axis=0)}


def fly(firmware: str, rate: float, mass: float, windows, hold: float, seed: int, cache_dir: str) -> dict:
    from crazyflie_controller.position_controller import PoseSample, State
    from crazyflie_driver.server.setpoint import setpoint_from_twist

    rig = RadioRig(firmware=firmware, mass=mass, seed=seed)
    cf = rig.connect(cache_dir=cache_dir)
    c = controller()
    period = 1.0 / rate
    wall0 = time.perf_counter()
    unacked = 0

    def cycle() -> None:
        nonlocal unacked
        got = rig.mocap_pose()
        pose = None if got is None else PoseSample.from_quaternion(got[2], tuple(got[0]), tuple(got[1]))
        cmd = c.update(rig.time, pose)
        sp = setpoint_from_twist(cmd.linear_x, cmd.linear_y, cmd.linear_z, cmd.angular_z)
        if not cf.send_setpoint(sp.roll, sp.pitch, sp.yawrate, sp.thrust):
            unacked += 1
        rig.advance(period)

    try:
        for _ in range(int(0.3 * rate)):          # zero setpoints: thrust lock released, first mocap frames
            cycle()
        c.set_goal(*GOAL, yaw=0.0)
        if not c.takeoff(rig.time):
            raise RuntimeError("take-off refused: %s" % c.status_text())
        t_takeoff = rig.time
        while c.state != State.AUTOMATIC or c.ramp_active:
            if rig.time - t_takeoff > 30.0:
                raise RuntimeError("no hover 30 s after take-off: %s" % c.status_text())
            cycle()
        t_arrived = rig.time
        errors = []
        for _ in range(int(round((max(windows) + hold) * rate))):
            cycle()
            errors.append(rig.true_position() - GOAL)
        wall = time.perf_counter() - wall0
        e = np.array(errors)
        out = {"firmware": firmware, "rate": rate, "arrived": t_arrived - t_takeoff, "world_s": rig.time,
               "wall_s": wall, "unacked": unacked, "windows": {}}
        for start in windows:
            k = int(round(start * rate))
            out["windows"][start] = figures(e[k:k + int(round(hold * rate))])
        return out
    finally:
        cf.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mass", type=float, default=0.032, help="vehicle mass in kg (32 g: with mocap markers)")
    ap.add_argument("--early", type=float, default=5.0, help="s after the setpoint reached the goal (window 1)")
    ap.add_argument("--settle", type=float, default=15.0, help="s after the setpoint reached the goal (window 2)")
    ap.add_argument("--hold", type=float, default=20.0, help="s of world time measured")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=os.path.join(HERE, "results", "hover.txt"))
    args = ap.parse_args()
    if controller() is None:
        print("crazyflie_controller is not importable: this benchmark needs its PositionController")
        return 1
    lines = ["hover at (0, 0, 0.5) through the fake radio, crazyflie_controller PositionController "
             "(crazyflie2.yaml gains), mass %.3f kg" % args.mass,
             "mocap: MocapModel defaults (100 Hz, 0.5 mm / 0.2 deg white noise, 8 ms latency), seed %d; "
             "errors of the true position over %.0f s holds" % (args.seed, args.hold),
             "%-8s %5s %8s %7s %8s %8s %22s %22s %10s %6s" % (
                 "firmware", "Hz", "arrive_s", "window", "rms_mm", "max_mm", "rms x/y/z mm", "mean x/y/z mm",
                 "world/wall", "unack")]
    print("\n".join(lines), flush=True)
    with tempfile.TemporaryDirectory() as cache:
        for firmware, rate in RUNS:
            r = fly(firmware, rate, args.mass, (args.early, args.settle), args.hold, args.seed, cache)
            for start, w in r["windows"].items():
                lines.append("%-8s %5.0f %8.2f %7s %8.3f %8.3f %22s %22s %9.2fx %6d" % (
                    r["firmware"], r["rate"], r["arrived"], "+%.0f s" % start, w["rms"] * 1e3, w["max"] * 1e3,
                    "/".join("%.3f" % v for v in w["rms_axes"] * 1e3),
                    "/".join("%+.3f" % v for v in w["mean_axes"] * 1e3),
                    r["world_s"] / r["wall_s"], r["unacked"]))
                print(lines[-1], flush=True)
    lines += ["arrive_s: world time from the take-off call until the controller's setpoint reached the goal;",
              "window: the hold starts this long after arrival (+%.0f s: the Z loop still rings down; +%.0f s: "
              "steady)" % (args.early, args.settle),
              "world/wall: world seconds per wall second of the whole loop (controller, radio stack, world).",
              "World.step real-time factor for 1/10/49/100 vehicles: bench/results/world.txt (bench/bench_world.py).",
              "machine: %s, Python %s, %d CPUs, load average %.1f"
              % (platform.machine(), platform.python_version(), os.cpu_count() or 0, os.getloadavg()[0]),
              "command: /usr/bin/python3 bench/bench_hover.py"]
    for line in lines[-6:]:
        print(line)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
