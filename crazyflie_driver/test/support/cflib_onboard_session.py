#!/usr/bin/env python3
"""Bitcraze's cflib flies a simulated Crazyflie with onboard estimation and control; JSON on stdout.

Run like ``cflib_session.py`` (cflib's interpreter, ``crazyflie_driver/src`` and this test directory on
PYTHONPATH, CRAZYFLIE_SIM_ADDRESS naming the world server). cflib's public API only:

  connect -> stabilizer.estimator / stabilizer.controller -> motion capture streamed with
  ``extpos.send_extpos`` (or ``send_extpose``) at 100 Hz, positions taken from the world's true state
  as a motion-capture system would measure them -> position setpoints -> hover setpoints ->
  velocity-world setpoints -> notify-setpoint-stop -> disconnect; or, with --high-level, trajectory
  upload (Poly4D, write_data_sync) -> define -> takeoff -> go_to -> trajectory -> land; or, with
  --compressed, a compressed trajectory uploaded with cflib's CompressedStart / CompressedSegment,
  defined, takeoff, the trajectory started and the landing sent to the broadcast address by our own
  ``BroadcastLink`` on a second fake Crazyradio (cflib 0.1.34 has no broadcasts), with group mask 1
  (set through cflib as ``hlCommander.groupmask``) so that other Crazyflies on the channel stay down.

The world's true position is sampled through the world server's control API during every phase and
reported per phase, so the test judges the flight on the truth. Every duration here (the 100 Hz of
the motion capture, each phase, the estimator's settling) is counted in the world's seconds, so a
world that runs slower than real time (a busy machine) gets the same flight, only slower.
"""
from __future__ import annotations

import argparse
import os
import threading
import time

from support.cflib_session import RESULT, Step, emit, install_fake_dongle, start_watchdog  # noqa: E402

MOCAP_PERIOD_S = 0.01
GROUP = 1                  # the group mask of the Crazyflie flown by broadcasts
SETPOINT_PERIOD_S = 0.02


class Mocap(threading.Thread):
    """Streams the world's true pose to the Crazyflie at 100 Hz of world time and keeps the samples."""

    def __init__(self, cf, control, uri: str, pose: bool) -> None:
        super().__init__(daemon=True)
        self.cf, self.control, self.uri, self.pose = cf, control, uri, pose
        self.samples: list = []
        self.sent = 0
        self.stop = threading.Event()
        self.started = threading.Event()

    def world_time(self) -> float:
        """World time [s] of the newest sample (the world's clock, without another round trip)."""
        return self.samples[-1][0]

    def run(self) -> None:
        due = None
        while not self.stop.is_set():
            state = self.control.control("vehicle_state", uri=self.uri)
            now = state["time"]
            if due is not None and now < due:
                # the world runs at most at real time: its seconds to go, slept on the wall, never oversleep
                self.stop.wait(due - now)
                continue
            p, q = state["position"], state["quaternion"]
            self.samples.append([now] + list(p) + [max(state["motors"])])
            self.started.set()
            if self.pose:
                self.cf.extpos.send_extpose(p[0], p[1], p[2], q[0], q[1], q[2], q[3])
            else:
                self.cf.extpos.send_extpos(p[0], p[1], p[2])
            self.sent += 1
            due = (now if due is None else due) + MOCAP_PERIOD_S
            if due <= now:                  # this thread was held up: go on from now, do not burst
                due = now + MOCAP_PERIOD_S

    def wait_world(self, seconds: float, send=None) -> None:
        """Let ``seconds`` of world time pass, calling ``send()`` every SETPOINT_PERIOD_S of wall time."""
        self.started.wait(10.0)
        end = self.world_time() + seconds
        while self.world_time() < end:
            if send is not None:
                send()
            time.sleep(SETPOINT_PERIOD_S)


def phase(name: str, seconds: float, send, mocap: Mocap, out: dict) -> None:
    start = len(mocap.samples)
    with Step(name):
        mocap.wait_world(seconds, send)
    out[name] = mocap.samples[start:]


def run(args: argparse.Namespace) -> None:
    import cflib.crtp
    from cflib.crazyflie import Crazyflie
    from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

    from crazyflie_driver.sim.air.medium import RemoteMedium

    backend = install_fake_dongle(2 if args.compressed else 1) if args.uri.startswith("radio://") else None
    cflib.crtp.init_drivers()
    control = RemoteMedium()
    cf = Crazyflie(rw_cache=None)
    scf = SyncCrazyflie(args.uri, cf=cf)
    with Step("connect"):
        scf.open_link()
        scf.wait_for_params()
    settings = [("stabilizer.estimator", args.estimator), ("stabilizer.controller", args.controller)]
    if args.compressed:
        settings.append(("hlCommander.groupmask", GROUP))
    for name, value in settings:
        cf.param.set_value(name, str(value))
    mocap = Mocap(cf, control, args.sim_uri, args.pose)
    mocap.start()
    mocap.wait_world(0.5)                 # the estimator settles on the first measurements
    x, y, z = args.goal
    phases: dict = {}
    if args.high_level:
        fly_high_level(cf, control, mocap, args, phases)
    elif args.compressed:
        fly_compressed_broadcast(cf, control, mocap, args, phases, backend)
    else:
        fly_setpoints(cf, mocap, args, phases, x, y, z)
    mocap.stop.set()
    mocap.join(1.0)
    RESULT["phases"] = phases
    RESULT["extpos_sent"] = mocap.sent
    RESULT["params"] = {n: cf.param.get_value(n) for n, _ in settings}
    with Step("disconnect"):
        scf.close_link()
    control.close()


def plan_begin(mocap: Mocap) -> float:
    """World time [s] the firmware began its current high-level plan: when the start command arrived,
    which on a busy machine may be well after the ping taken before sending it."""
    return float(mocap.control.control("vehicle_state", uri=mocap.uri)["plan_begin"])


def fly_high_level(cf, control, mocap: Mocap, args: argparse.Namespace, phases: dict) -> None:
    """Upload the trajectory (Poly4D, write_data_sync), define it, take off, go_to, fly it, land."""
    import json

    from cflib.crazyflie.mem import MemoryElement, Poly4D

    with open(args.high_level) as f:
        pieces = json.load(f)
    memory = cf.mem.get_mems(MemoryElement.TYPE_TRAJ)[0]
    memory.trajectory = [Poly4D(p["duration"], Poly4D.Poly(p["x"]), Poly4D.Poly(p["y"]), Poly4D.Poly(p["z"]),
                                Poly4D.Poly(p["yaw"])) for p in pieces]
    with Step("upload"):
        RESULT["upload_ok"] = bool(memory.write_data_sync())
    hlc = cf.high_level_commander
    hlc.define_trajectory(1, 0, len(pieces))
    total = sum(p["duration"] for p in pieces)
    idle = lambda: None    # noqa: E731
    hlc.takeoff(0.5, 2.0)
    phase("takeoff", 3.0, idle, mocap, phases)
    hlc.go_to(0.3, 0.2, 0.6, 0.0, 2.0)
    phase("go_to", 3.0, idle, mocap, phases)
    hlc.go_to(0.0, 0.0, 0.5, 0.0, 2.0)
    phase("back", 3.0, idle, mocap, phases)
    RESULT["trajectory_start"] = control.ping()
    hlc.start_trajectory(1, 1.0, False)
    phase("trajectory", total + 2.0, idle, mocap, phases)
    RESULT["trajectory_begin"] = plan_begin(mocap)
    hlc.land(0.0, 2.0)
    phase("land", 3.0, idle, mocap, phases)


def fly_compressed_broadcast(cf, control, mocap: Mocap, args: argparse.Namespace, phases: dict, backend) -> None:
    """Compressed upload through cflib, cflib's takeoff, then start and land as broadcasts to group 1."""
    import json

    from cflib.crazyflie.mem import CompressedSegment, CompressedStart, MemoryElement

    from crazyflie_driver.protocol import high_level as hl
    from crazyflie_driver.radio.broadcast import BroadcastLink
    from crazyflie_driver.radio.shared_radio import RadioManager

    with open(args.compressed) as f:
        spec = json.load(f)
    memory = cf.mem.get_mems(MemoryElement.TYPE_TRAJ)[0]
    memory.trajectory = [CompressedStart(*spec["start"])] + [CompressedSegment(*seg) for seg in spec["segments"]]
    with Step("upload"):
        RESULT["upload_ok"] = bool(memory.write_data_sync())
    hlc = cf.high_level_commander
    hlc.define_trajectory(2, 0, len(spec["segments"]), type=hlc.TRAJECTORY_TYPE_POLY4D_COMPRESSED)
    total = sum(segment[0] for segment in spec["segments"])
    idle = lambda: None    # noqa: E731
    hlc.takeoff(0.5, 2.0)
    phase("takeoff", 2.5, idle, mocap, phases)
    version = cf.platform.get_protocol_version()
    with BroadcastLink(1, args.channel, manager=RadioManager(backend)) as broadcast:
        RESULT["trajectory_start"] = control.ping()
        broadcast.send_repeated(hl.start_trajectory_packet(2, version, group_mask_=GROUP))
        phase("trajectory", total + 1.0, idle, mocap, phases)
        RESULT["trajectory_begin"] = plan_begin(mocap)
        broadcast.send_repeated(hl.land_packet(0.0, 2.0, version, group_mask=GROUP))
        phase("land", 2.5, idle, mocap, phases)


def fly_setpoints(cf, mocap: Mocap, args: argparse.Namespace, phases: dict, x: float, y: float, z: float) -> None:
    phase("position", args.seconds, lambda: cf.commander.send_position_setpoint(x, y, z, 0.0), mocap, phases)
    if not args.trap:
        phase("hover", 2.0, lambda: cf.commander.send_hover_setpoint(0.0, 0.0, 0.0, z), mocap, phases)
        phase("velocity", 2.0, lambda: cf.commander.send_velocity_world_setpoint(0.3, 0.0, 0.0, 0.0), mocap, phases)
        phase("hold", 1.0, lambda: cf.commander.send_hover_setpoint(0.0, 0.0, 0.0, z), mocap, phases)
    cf.commander.send_notify_setpoint_stop()
    phase("after_stop", 0.5, lambda: None, mocap, phases)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--uri", required=True, help="cflib's URI (radio:// through the fake Crazyradio, or udp://)")
    p.add_argument("--sim-uri", required=True, help="the Crazyflie's radio URI in the world server")
    p.add_argument("--estimator", type=int, default=2)
    p.add_argument("--controller", type=int, default=1)
    p.add_argument("--pose", action="store_true", help="send extpose instead of extpos")
    p.add_argument("--goal", type=float, nargs=3, default=(0.0, 0.0, 0.5))
    p.add_argument("--seconds", type=float, default=6.0, help="duration of the position phase")
    p.add_argument("--trap", action="store_true", help="position phase only (estimator-1 trap)")
    p.add_argument("--high-level", default="", help="JSON file of poly4d pieces: fly with the high-level commander")
    p.add_argument("--compressed", default="", help="JSON file {start, segments} of a compressed trajectory: fly "
                   "it with broadcasts (radio:// only)")
    p.add_argument("--channel", type=int, default=80, help="radio channel of the broadcasts")
    p.add_argument("--timeout", type=float, default=40.0)
    args = p.parse_args()
    logging_level = os.environ.get("CFLIB_PEER_LOG")
    if logging_level:
        import logging
        logging.basicConfig(level=logging_level)
    start_watchdog(args.timeout)
    try:
        run(args)
    except Exception as e:
        import traceback
        traceback.print_exc()
        RESULT["error"] = "%s: %s" % (type(e).__name__, e)
        emit(2)
    emit(0)


if __name__ == "__main__":
    main()
