#!/usr/bin/env python3
"""Onboard flight of the simulated Crazyflie: hover error under the onboard PID position controller
fed by motion capture, its dependence on the mocap rate, what a mocap outage does, and the world's
real-time factor with 49 vehicles under onboard control.

Every flight goes through the simulated firmware's ports: the world's motion-capture model
(MocapModel defaults: 0.5 mm / 0.2 deg white noise, 8 ms latency; seeded) is sent as port-6
external positions, position setpoints (0, 0, 0.5) as port-7 type 7 at 50 Hz, with
stabilizer.estimator 2 and stabilizer.controller 1. Errors are of the world's true position, over a
10 s hold that starts 12 s after the first setpoint (the take-off from the floor overshoots and the
z integrators ring down first). The world is stepped by this script (speed 0), so runs are
deterministic per seed.
Run: /usr/bin/python3 bench/bench_onboard.py   (writes bench/results/onboard.txt)
"""
from __future__ import annotations

import argparse
import os
import platform
import struct
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))

import bench_support  # noqa: E402,F401  (the sources and the tests' support on the path)
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie  # noqa: E402
from crazyflie_driver.sim.crtp.setpoint_decode import decode_setpoint  # noqa: E402
from crazyflie_driver.sim.crtp.trajectory_memory import MEMORY_TYPE_TRAJECTORY  # noqa: E402
from crazyflie_driver.sim.onboard.planner import Evaluation, Plan, evaluate, figure_eight, online_piece  # noqa: E402
from crazyflie_driver.sim.room.mocap import MocapModel  # noqa: E402
from crazyflie_driver.sim.room.world import World  # noqa: E402

GOAL = (0.0, 0.0, 0.5)
FIG8_HALF_WIDTH, FIG8_HALF_HEIGHT = 1.0, 0.5       # m: x = w sin(ωt), y = h sin(2ωt)
FIG8_PERIOD = 8.0                                  # s: 0.76 m/s average (Crazyswarm flew 0.76)
SETTLE_S = 12.0
HOLD_S = 10.0


def rig(seed: int, controller: int = 1, std_dev: float = 0.01, rate_hz: float = 100.0):
    """A vehicle behind its simulated firmware with mocap as port-6 extpos; estimator 2."""
    world = World(speed=0, seed=seed)
    vehicle = world.add_vehicle("cf1")
    cf = SimulatedCrazyflie(b"\xe7\xe7\xe7\xe7\x01", vehicle)
    mocap = MocapModel(world, rate=rate_hz, seed=seed).attach()
    mocap.add_listener(lambda frames: [cf.handle_crtp(bytes([0x6C]) + struct.pack("<fff", *f.position))
                                       for f in frames])
    for name, value in (("stabilizer.estimator", 2), ("stabilizer.controller", controller),
                        ("locSrv.extPosStdDev", std_dev)):
        vehicle.write_param(name, value)
        cf.params.values[cf.params.ident(name)] = value
    return world, vehicle, cf


def high_level(cf, payload: bytes) -> None:
    cf.handle_crtp(bytes([0x8C]) + payload)


def trajectory_memory_id(cf) -> int:
    """The trajectory memory's id, found as a host finds it (port 4, channel 0: the number of
    memories, then each one's type): ids follow the decks and the EEPROM, so it is not 0."""
    def ask(payload: bytes) -> bytes:
        while cf.pop_outgoing() is not None:
            pass
        cf.handle_crtp(bytes([0x4C]) + payload)
        return cf.pop_outgoing()[1:]
    for ident in range(ask(b"\x01")[1]):
        if ask(bytes([2, ident]))[2] == MEMORY_TYPE_TRAJECTORY:
            return ident
    raise RuntimeError("the simulated Crazyflie lists no trajectory memory")


def takeoff_and_figure_eight(controller: int, seed: int):
    """HL takeoff to 0.5 m in 2 s (true z against the planner's polynomial), then a figure-8 at
    Crazyswarm's average speed (true position against the trajectory, first to last point)."""
    world, vehicle, cf = rig(seed, controller)
    high_level(cf, struct.pack("<BBff?f", 7, 0, 0.5, 0.0, False, 2.0))
    piece = online_piece(2.0, Evaluation(np.zeros(3), np.zeros(3), np.zeros(3), 0.0, 0.0), (0, 0, 0.5), 0.0)
    takeoff_err = []
    for _ in range(300):
        world.step(10)
        takeoff_err.append(abs(vehicle.pose()[0][2] - evaluate(piece, world.time)[0][2]))
    world.step(2000)
    pieces = figure_eight(FIG8_HALF_WIDTH, FIG8_HALF_HEIGHT, FIG8_PERIOD, 12, 0.5)
    data = b"".join(struct.pack("<33f", *p.coeffs.reshape(-1), p.duration) for p in pieces)
    memory = trajectory_memory_id(cf)
    for offset in range(0, len(data), 24):
        cf.handle_crtp(bytes([0x4E, memory]) + struct.pack("<I", offset) + data[offset:offset + 24])
    high_level(cf, struct.pack("<BBBBIB", 6, 1, 1, 0, 0, len(pieces)))
    high_level(cf, struct.pack("<BBBBBBf", 13, 0, 0, 0, 0, 1, 1.0))
    plan = Plan(1, pieces, world.time)
    err, speeds = [], []
    while world.time < plan.t_begin + plan.duration:
        world.step(10)
        ev = plan.evaluate(world.time)
        err.append(np.linalg.norm(vehicle.pose()[0] - ev.pos))
        speeds.append(np.linalg.norm(ev.vel))
    return {"takeoff_max_mm": 1000 * max(takeoff_err), "takeoff_end_mm": 1000 * takeoff_err[-1],
            "fig8_mean_mm": 1000 * float(np.mean(err)), "fig8_max_mm": 1000 * float(np.max(err)),
            "speed_mean": float(np.mean(speeds)), "speed_max": float(np.max(speeds))}


def flight(rate_hz: float, std_dev: float, seed: int, outage_s: float = 0.0, controller: int = 1):
    world = World(speed=0, seed=seed)
    vehicle = world.add_vehicle("cf1")
    cf = SimulatedCrazyflie(b"\xe7\xe7\xe7\xe7\x01", vehicle)
    mocap = MocapModel(world, rate=rate_hz, seed=seed).attach()
    blackout = [None, None]

    def on_frames(frames):
        if blackout[0] is not None and blackout[0] <= world.time < blackout[1]:
            return
        for f in frames:
            cf.handle_crtp(bytes([0x6C]) + struct.pack("<fff", *f.position))

    mocap.add_listener(on_frames)
    setpoint = bytes([0x7C, 7]) + struct.pack("<ffff", GOAL[0], GOAL[1], GOAL[2], 0.0)
    world.add_tick_listener(lambda now: cf.handle_crtp(setpoint), 0.02)
    for name, value in (("stabilizer.estimator", 2), ("stabilizer.controller", controller),
                        ("locSrv.extPosStdDev", std_dev)):
        vehicle.write_param(name, value)
        cf.params.values[cf.params.ident(name)] = value
    t0 = time.perf_counter()
    world.step(int(SETTLE_S * 1000))
    errors, path = [], []
    if outage_s:
        blackout[:] = [world.time, world.time + outage_s]
    for _ in range(int(HOLD_S * 100)):
        world.step(10)
        p = vehicle.pose()[0]
        errors.append(p - GOAL)
        path.append(world.time)
    wall = time.perf_counter() - t0
    e = np.array(errors)
    norm = np.linalg.norm(e, axis=1)
    out = {"mean_mm": 1000 * norm.mean(), "rms_mm": 1000 * np.sqrt((norm ** 2).mean()), "max_mm": 1000 * norm.max(),
           "rtf": (SETTLE_S + HOLD_S) / wall, "halted": cf.state.halted}
    if outage_s:
        horizontal = np.linalg.norm(e[:, :2], axis=1)
        t = np.array(path) - blackout[0]
        during = horizontal[t < outage_s]
        after = horizontal[(t >= outage_s + 3.0)]
        out.update(outage_max_mm=1000 * during.max(), outage_end_mm=1000 * during[-1],
                   recovered_mm=1000 * after.max() if len(after) else float("nan"))
    return out


def fleet_rtf(n: int, onboard: bool, seconds: float = 2.0) -> float:
    """World.step alone (no radio) for n vehicles, RPYT hover thrust or onboard PID with extpos."""
    world = World(speed=0, seed=1)
    vehicles = [world.add_vehicle("cf%d" % i, position=(i % 7 * 0.5, i // 7 * 0.5, 0.0)) for i in range(n)]
    for v in vehicles:
        if onboard:
            v.write_param("stabilizer.estimator", 2)
            p = v.pose()[0]
            v.set_setpoint(decode_setpoint(bytes([7]) + struct.pack("<ffff", p[0], p[1], 0.5, 0.0)))
        else:
            v.set_rpyt(0.0, 0.0, 0.0, 0)
            v.set_rpyt(0.0, 0.0, 0.0, 36000)

    def feed(now):
        if onboard:
            for v in vehicles:
                v.external_measurement(v.pose()[0])
    world.add_tick_listener(feed, 0.01)
    world.step(500)
    t0 = time.perf_counter()
    world.step(int(seconds * 1000))
    return seconds / (time.perf_counter() - t0)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default=os.path.join(HERE, "results", "onboard.txt"))
    args = p.parse_args()
    lines = ["onboard hover at (0, 0, 0.5): estimator 2 + PID position controller (controller 1), firmware defaults",
             "mocap: MocapModel (0.5 mm / 0.2 deg noise, 8 ms latency) sent as port-6 extpos; "
             "setpoints type 7 at 50 Hz",
             "errors of the true position over %.0f s, from %.0f s after the first setpoint; seed %d"
             % (HOLD_S, SETTLE_S, args.seed),
             "%-8s %-12s %9s %9s %9s %9s" % ("mocap Hz", "extPosStdDev", "mean_mm", "rms_mm", "max_mm", "world/wall")]
    for rate, std in ((100.0, 0.01), (100.0, 0.001), (10.0, 0.01), (2.0, 0.01)):
        r = flight(rate, std, args.seed)
        lines.append("%-8g %-12g %9.2f %9.2f %9.2f %8.2fx"
                     % (rate, std, r["mean_mm"], r["rms_mm"], r["max_mm"], r["rtf"]))
        print(lines[-1], flush=True)
    r = flight(100.0, 0.01, args.seed, controller=2)
    lines.append("%-8s %-12s %9.2f %9.2f %9.2f %8.2fx   (Mellinger, controller 2)"
                 % ("100", "0.01", r["mean_mm"], r["rms_mm"], r["max_mm"], r["rtf"]))
    print(lines[-1], flush=True)
    lines.append("high-level commander: takeoff to 0.5 m in 2 s (true z - planner polynomial) and a %.0f x %.0f m "
                 "figure-8 in %.0f s (true position - trajectory)" % (2 * FIG8_HALF_WIDTH, 2 * FIG8_HALF_HEIGHT,
                                                                     FIG8_PERIOD))
    lines.append("%-11s %16s %16s %14s %14s %18s" % ("controller", "takeoff max mm", "takeoff end mm", "fig8 mean mm",
                                                     "fig8 max mm", "speed mean/max m/s"))
    for controller, label in ((1, "1 PID"), (2, "2 Mellinger")):
        r = takeoff_and_figure_eight(controller, args.seed)
        lines.append("%-11s %16.1f %16.1f %14.1f %14.1f %13.2f/%.2f" % (
            label, r["takeoff_max_mm"], r["takeoff_end_mm"], r["fig8_mean_mm"], r["fig8_max_mm"], r["speed_mean"],
            r["speed_max"]))
        print(lines[-1], flush=True)
    lines.append("mocap outage while hovering (100 Hz before and after): horizontal error of the true position")
    lines.append("%-8s %16s %16s %22s" % ("outage s", "max during mm", "at its end mm", "max from +3 s after mm"))
    for outage in (1.0, 5.0):
        r = flight(100.0, 0.01, args.seed, outage)
        lines.append("%-8g %16.1f %16.1f %22.1f" % (outage, r["outage_max_mm"], r["outage_end_mm"], r["recovered_mm"]))
        print(lines[-1], flush=True)
    lines.append("World.step real-time factor "
                 "(no radio; onboard: extpos for every vehicle at 100 Hz via the Vehicle API)")
    lines.append("%-9s %10s %10s" % ("vehicles", "RPYT", "onboard PID"))
    for n in (1, 10, 49):
        lines.append("%-9d %9.2fx %9.2fx" % (n, fleet_rtf(n, False), fleet_rtf(n, True)))
        print(lines[-1], flush=True)
    lines.append("machine: %s, Python %s, %d CPUs, load average %.1f"
                 % (platform.machine(), platform.python_version(), os.cpu_count() or 0, os.getloadavg()[0]))
    lines.append("command: /usr/bin/python3 bench/bench_onboard.py")
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
