#!/usr/bin/env python3
"""Goal changes with the chapter's gains: the original controller, the previous defaults and the fixed one.

Flies crazyflie_controller's PositionController against the simulated world (sim.room, fast mode,
in process, no ROS; see crazyflie_controller/test/controller_support/world_flight.py): cmd_vel → crazyflie_server's RPYT
mapping → Vehicle.set_rpyt; pose from a 100 Hz motion-capture model with 10 ms latency and
0.5 mm noise; controller at 50 Hz; 32 g Crazyflie. Each variant takes off to (0, 0, 0.5), hovers,
then flies, each from a settled hover:
  step up     goal 0.5 → 0.7 m: overshoot past 0.7 m, time until within 2 cm for good
  step down   goal 0.7 → 0.5 m: undershoot below 0.5 m
  move x      goal (0, 0, 0.5) → (0.5, 0, 0.5): sag below 0.5 m, largest |z − 0.5|, x overshoot,
              time until within 5 cm (3-D) for good
  demo1       crazyflie_demo's demo1.py waypoints with the demo node's rule (0.3 m / 10°, 2 s hold):
              when each waypoint was reached (s after lift-off), the mission summary's hold RMS
              (3-D distance from first coming within 0.1 m of a waypoint until the next), the
              largest |z − waypoint z| while holding a waypoint (after the first).
Variants (ControllerConfig fields; the rest are the defaults):
  original   the original controller (ControllerConfig.original)
  before     the defaults before the goal-change fix: smooth take-off, D on measurement, goals as
             steps, no tilt compensation, z integrator always on, no hover-thrust fit after the
             take-off glide (hover_refine_time 0; also in glide, glide+aw and glide+tilt)
  glide      before + goals glide (goalChange smooth)
  glide+aw   glide + conditional z integration (zIntegration conditional)
  glide+tilt glide + tilt compensation
  fixed      the defaults (all of the above)
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

import bench_support as bs  # noqa: E402
from crazyflie_controller.position_controller import ControllerConfig, PositionController, State  # noqa: E402

X, Y, Z, YAW = bs.chapter_gains()   # config/crazyflie2.yaml, as the node loads it
BEFORE = dict(goal_change="step", tilt_compensation=False, z_integration="always", hover_refine_time=0.0)
VARIANTS = {
    "original": None,
    "before": BEFORE,
    "glide": dict(BEFORE, goal_change="smooth"),
    "glide+aw": dict(BEFORE, goal_change="smooth", z_integration="conditional"),
    "glide+tilt": dict(BEFORE, goal_change="smooth", tilt_compensation=True),
    "fixed": {},
}


def make_controller(variant: str, extra: dict) -> PositionController:
    kw = VARIANTS[variant]
    if kw is None:
        return PositionController(ControllerConfig.original(X, Y, Z, YAW, **extra))
    return PositionController(ControllerConfig(X, Y, Z, YAW, **dict(kw, **extra)))


def hovering(variant: str, extra: dict, seed: int, goal=(0.0, 0.0, 0.5), settle: float = 12.0):
    """A flight that took off to ``goal`` and has hovered there for ``settle`` s after lift-off."""
    from controller_support.world_flight import WorldFlight

    c = make_controller(variant, extra)
    f = WorldFlight(c, mass=0.032, seed=seed)
    f.wait_for_pose()
    c.set_goal(*goal, 0.0)
    f.run(0.2)
    if not f.takeoff():
        raise RuntimeError("take-off refused")
    while c.state == State.TAKING_OFF:
        f.run(0.02)
    f.run(settle)
    return c, f


def settle_time(samples, t0: float, error, bound: float) -> float:
    """Time from t0 until ``error(sample)`` stays within ``bound``."""
    outside = [s.t for s in samples if error(s) > bound]
    return (max(outside) - t0) if outside else 0.0


def step_figures(variant: str, extra: dict, seed: int, seconds: float = 6.0) -> dict:
    c, f = hovering(variant, extra, seed)
    t0 = f.world.time
    c.set_goal(0.0, 0.0, 0.7, 0.0)
    f.run(seconds)
    up = [s for s in f.log if s.t > t0]
    t1 = f.world.time
    c.set_goal(0.0, 0.0, 0.5, 0.0)
    f.run(seconds)
    down = [s for s in f.log if s.t > t1]
    return {"up_overshoot": max(s.z for s in up) - 0.7,
            "up_settle": settle_time(up, t0, lambda s: abs(s.z - 0.7), 0.02),
            "down_undershoot": 0.5 - min(s.z for s in down),
            "down_settle": settle_time(down, t1, lambda s: abs(s.z - 0.5), 0.02)}


def move_figures(variant: str, extra: dict, seed: int, seconds: float = 6.0) -> dict:
    c, f = hovering(variant, extra, seed)
    t0 = f.world.time
    c.set_goal(0.5, 0.0, 0.5, 0.0)
    f.run(seconds)
    move = [s for s in f.log if s.t > t0]
    return {"sag": 0.5 - min(s.z for s in move), "z_dev": max(abs(s.z - 0.5) for s in move),
            "x_overshoot": max(s.x for s in move) - 0.5,
            "move_settle": settle_time(move, t0, lambda s: math.sqrt((s.x - 0.5) ** 2 + s.y ** 2 + (s.z - 0.5) ** 2),
                                       0.05)}


def mission_figures(variant: str, extra: dict, seed: int) -> dict:
    from controller_support.world_flight import DEMO1, WorldFlight, fly_waypoints, goal_segments, hold_rms

    c = make_controller(variant, extra)
    f = WorldFlight(c, mass=0.032, seed=seed)
    f.wait_for_pose()
    c.set_goal(0.0, 0.0, 0.5, 0.0)
    f.run(0.2)
    if not f.takeoff():
        raise RuntimeError("take-off refused")
    while c.state == State.TAKING_OFF:
        f.run(0.02)
    t_liftoff = f.world.time
    reached = fly_waypoints(f, DEMO1)
    segments = goal_segments(f.log)
    return {"reached": [t - t_liftoff for t in reached], "hold_rms": hold_rms(segments),
            "hold_z_max": max(seg.hold_z_max for seg in segments[1:]), "segments": segments}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma separated, of: " + ", ".join(VARIANTS))
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="override a ControllerConfig field in every variant (Python literal), e.g. goal_accel=0.8")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=os.path.join(HERE, "results", "goal_steps.txt"),
                    help="results file ('' to only print)")
    args = ap.parse_args()
    try:
        import crazyflie_driver.sim.room.world  # noqa: F401
    except ImportError as e:
        print("sim.room is not available (%s): benchmark pending" % e)
        return 1
    import ast
    extra = {}
    for item in args.set:
        name, _, value = item.partition("=")
        extra[name.strip()] = ast.literal_eval(value.strip())
    lines = ["goal changes, chapter gains, 32 g, sim.room fast mode, mocap 100 Hz / 10 ms / 0.5 mm, controller 50 Hz"
             + (" (overrides %s)" % extra if extra else ""),
             "%-10s | %7s %6s %7s %6s | %6s %6s %7s %6s | %-25s %7s %6s" % (
                 "variant", "up-over", "settle", "dn-undr", "settle", "sag", "|dz|", "x-over", "settle",
                 "demo1 waypoints reached", "holdRMS", "hold|dz|"),
             "%-10s | %7s %6s %7s %6s | %6s %6s %7s %6s | %-25s %7s %6s" % (
                 "", "m", "s", "m", "s", "m", "m", "m", "s", "at s after lift-off", "m", "m")]
    print("\n".join(lines), flush=True)
    start = time.time()
    for variant in [v.strip() for v in args.variants.split(",") if v.strip()]:
        st = step_figures(variant, extra, args.seed)
        mv = move_figures(variant, extra, args.seed)
        ms = mission_figures(variant, extra, args.seed)
        line = "%-10s | %7.3f %6.2f %7.3f %6.2f | %6.3f %6.3f %7.3f %6.2f | %-25s %7.3f %6.3f" % (
            variant, st["up_overshoot"], st["up_settle"], st["down_undershoot"], st["down_settle"],
            mv["sag"], mv["z_dev"], mv["x_overshoot"], mv["move_settle"],
            " ".join("%.1f" % t for t in ms["reached"]), ms["hold_rms"], ms["hold_z_max"])
        print(line, flush=True)
        lines.append(line)
    wall = time.time() - start
    tail = ["up/dn: 0.2 m step of the goal height from a settled hover (overshoot past the new height, time until "
            "within 2 cm for good); sag: lowest point below 0.5 m during and after a 0.5 m move along x, |dz| the "
            "largest height error, x-over how far past x = 0.5 m, settle until within 5 cm (3-D) for good;",
            "demo1: demo1.py's waypoints flown with the demo node's rule; holdRMS as the mission summary; hold|dz| the "
            "largest height error while holding waypoints 2-5.",
            "%.1f s wall, python %s, %s" % (wall, platform.python_version(), platform.machine()),
            "command: /usr/bin/python3 bench/bench_goal_steps.py"]
    print("\n".join(tail))
    if args.out:
        bs.write_lines(args.out, lines + tail)
    return 0


if __name__ == "__main__":
    sys.exit(main())
