#!/usr/bin/env python3
"""Take-off to 0.5 m with the chapter's gains: the original controller vs the fixed one.

Flies crazyflie_controller's PositionController against the simulated world (sim.room, fast mode,
in process, no ROS): cmd_vel → crazyflie_server's RPYT mapping → Vehicle.set_rpyt; pose from a
100 Hz motion-capture model with 10 ms latency and 0.5 mm noise; controller at 50 Hz. For each
variant and vehicle mass it prints the lift-off thrust, the Z integrator preload, the peak height,
the overshoot past 0.5 m, the time from lift-off until the height stays within 5 cm, the hover
RMS error 5-10 s after lift-off (the chapter's slow Z mode rings there when the hover thrust is off)
and 15-20 s after lift-off. Variants:
  original   takeoffHandover=original, derivative=error (the original's behaviour)
  d-meas     takeoffHandover=original, derivative=measurement (no D kick only)
  no-fit     the defaults without the hover-thrust fit after the take-off glide (hoverRefineTime=0)
  fixed      takeoffHandover=smooth,   derivative=measurement (the defaults)
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

import bench_support as bs  # noqa: E402
from crazyflie_controller.position_controller import ControllerConfig, PositionController  # noqa: E402

X, Y, Z, YAW = bs.chapter_gains()   # config/crazyflie2.yaml, as the node loads it
ORIGINAL_GOALS = dict(goal_change="step", z_integration="always", tilt_compensation=False)
VARIANTS = {
    "original": dict(ORIGINAL_GOALS, takeoff_handover="original", derivative="error"),
    "d-meas": dict(ORIGINAL_GOALS, takeoff_handover="original", derivative="measurement"),
    "no-fit": dict(takeoff_handover="smooth", derivative="measurement", hover_refine_time=0.0),
    "fixed": dict(takeoff_handover="smooth", derivative="measurement"),
}
GOAL_Z = 0.5


def fly(variant: str, mass: float, seconds: float, seed: int):
    from controller_support.world_flight import WorldFlight, takeoff_figures

    c = PositionController(ControllerConfig(X, Y, Z, YAW, **VARIANTS[variant]))
    f = WorldFlight(c, mass=mass, seed=seed)
    f.wait_for_pose()
    c.set_goal(0.0, 0.0, GOAL_Z, 0.0)
    f.run(0.2)
    if not f.takeoff():
        raise RuntimeError("take-off refused")
    f.run(seconds)
    fig = takeoff_figures(f.log, GOAL_Z, (15.0, 20.0))
    fig["early_rms_z"] = takeoff_figures(f.log, GOAL_Z, (5.0, 10.0))["hover_rms_z"]
    fig.update(liftoff=c.liftoff_thrust, preload=c.preload_thrust, refined=c.refined_thrust)
    return fig


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--masses", default="0.027,0.032,0.034", help="vehicle masses in kg, comma separated")
    ap.add_argument("--seconds", type=float, default=21.0, help="flight time after the take-off call")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=os.path.join(HERE, "results", "takeoff.txt"))
    args = ap.parse_args()
    try:
        import crazyflie_driver.sim.room.world  # noqa: F401
    except ImportError as e:
        print("sim.room is not available (%s): benchmark pending" % e)
        return 1
    lines = ["take-off to %.1f m, chapter gains, sim.room fast mode, mocap 100 Hz / 10 ms / 0.5 mm, "
             "controller 50 Hz" % GOAL_Z,
             "%-9s %6s %8s %8s %8s %7s %9s %8s %9s %9s %9s" % (
                 "variant", "mass", "liftoff", "preload", "fitted", "peak", "overshoot", "settle5", "rms_z5-10",
                 "rms_z", "rms_xy"),
             "%-9s %6s %8s %8s %8s %7s %9s %8s %9s %9s %9s" % ("", "kg", "counts", "counts", "counts", "m", "m", "s",
                                                             "mm", "mm", "mm")]
    print("\n".join(lines), flush=True)
    start = time.time()
    world_seconds = 0.0
    for mass in [float(m) for m in args.masses.split(",")]:
        for variant in VARIANTS:
            fig = fly(variant, mass, args.seconds, args.seed)
            world_seconds += args.seconds + 0.2
            line = "%-9s %6.3f %8.0f %8.0f %8s %7.3f %9.3f %8.2f %9.2f %9.2f %9.2f" % (
                variant, mass, fig["liftoff"], fig["preload"],
                "-" if fig["refined"] is None else "%.0f" % fig["refined"],
                fig["peak_z"], fig["overshoot"], fig["settle_5cm"], fig["early_rms_z"] * 1000,
                fig["hover_rms_z"] * 1000, fig["hover_rms_xy"] * 1000)
            print(line, flush=True)
            lines.append(line)
    wall = time.time() - start
    tail = ["fitted: hover thrust fitted over the first %.1f s after the take-off glide (hover_thrust.py); "
            "true hover command of sim.physics: 36344 / 40922 / 42666 for 27 / 32 / 34 g"
            % ControllerConfig(X, Y, Z, YAW).hover_refine_time,
            "settle5: time from lift-off until the height stays within 5 cm of the goal; rms_z5-10: 5-10 s after "
            "lift-off; rms: 15-20 s after lift-off (true position).",
            "%.0f s of world time in %.1f s wall (%.1fx real time), python %s, %s" % (
                world_seconds, wall, world_seconds / wall, platform.python_version(), platform.machine()),
            "command: /usr/bin/python3 bench/bench_takeoff.py"]
    print("\n".join(tail))
    bs.write_lines(args.out, lines + tail)
    return 0


if __name__ == "__main__":
    sys.exit(main())
