#!/usr/bin/env python3
"""One session of Bitcraze's cflib against the simulated world, reported as JSON on stdout.

Run with cflib's interpreter (cflib >= 0.1.28 needs Python >= 3.10), ``crazyflie_driver/src`` on
PYTHONPATH and CRAZYFLIE_SIM_ADDRESS naming a running world server. For radio URIs this process
wraps ``usb.core.find`` so that cflib's own Crazyradio driver talks to our fake Crazyradio
(``sim.air.fake_usb.FakeUsbBackend`` on a ``sim.air.medium.RemoteMedium``); for udp:// URIs cflib's UDP driver
talks to the server's UDP endpoint directly. Everything after that is cflib's public API:

  scan (radio only) -> SyncCrazyflie connect -> both TOCs -> every parameter value ->
  write one parameter and read it back from the Crazyflie -> one log block for a while ->
  RPYT setpoints -> disconnect.

With several --uri the sessions run at the same time, one thread each, sharing cflib's dongle.

Each step is timed; a step that hangs (cflib's connect has no timeout of its own) makes the
session print what it has so far with "error" set and exit with status 3.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import threading
import time

RESULT: dict = {"steps": {}, "error": None}
_active_steps: set = set()
_emit_lock = threading.Lock()
_emitted = [False]


def emit(status: int) -> None:
    """Print the result once (from the main thread or the watchdog) and leave."""
    with _emit_lock:
        if _emitted[0]:
            return
        _emitted[0] = True
        sys.stdout.write(json.dumps(RESULT, sort_keys=True) + "\n")
        sys.stdout.flush()
    if status:
        os._exit(status)


class Step:
    """Times one step; the watchdog reports the step that was running when it fired."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __enter__(self) -> Step:
        _active_steps.add(self.name)
        self.t0 = time.monotonic()
        return self

    def __exit__(self, *exc) -> None:
        RESULT["steps"][self.name] = round(time.monotonic() - self.t0, 3)
        _active_steps.discard(self.name)


def start_watchdog(seconds: float) -> None:
    def fire() -> None:
        RESULT["error"] = "steps %s did not finish within the session's %.0f s" % (sorted(_active_steps), seconds)
        emit(3)
    t = threading.Timer(seconds, fire)
    t.daemon = True
    t.start()


def install_fake_dongle(dongles: int):
    """Make every usb.core.find (cflib passes its own backend=) see our fake Crazyradios."""
    from crazyflie_driver.sim.air.dongle_timing import DongleTiming
    from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
    from crazyflie_driver.sim.air.medium import RemoteMedium
    from support.cflib_find_patch import install_find_patch
    timing = DongleTiming.instant() if os.environ.get("CFLIB_PEER_TIMING") == "instant" else DongleTiming()
    backend = FakeUsbBackend(RemoteMedium(), dongles=dongles, timing=timing)
    install_find_patch(backend)
    return backend


def wait_for(event: threading.Event, seconds: float, what: str) -> None:
    if not event.wait(seconds):
        raise TimeoutError("no %s within %.1f s" % (what, seconds))


def world_time() -> float:
    """The world server's clock (world time may run in bursts when the world catches up on lag)."""
    from crazyflie_driver.sim.air.medium import RemoteMedium
    control = RemoteMedium()
    try:
        return control.ping()
    finally:
        control.close()


def sleep_world(seconds: float) -> None:
    """Until ``seconds`` of world time passed: the log block's samples follow the firmware's clock,
    which on a busy machine runs slower than the host's."""
    from crazyflie_driver.sim.air.medium import RemoteMedium
    from crazyflie_driver.sim.world_clock import WorldClock
    control = RemoteMedium()
    try:
        WorldClock(control.ping).sleep(seconds)
    finally:
        control.close()


def session(uri: str, param: str, sim_name: str, args: argparse.Namespace, out: dict) -> None:
    """One Crazyflie from connect to disconnect; fills ``out``."""
    from cflib.crazyflie import Crazyflie
    from cflib.crazyflie.log import LogConfig
    from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

    tag = uri + ": "
    console: list = []
    cf = Crazyflie(rw_cache=None)
    cf.console.receivedChar.add_callback(console.append)
    scf = SyncCrazyflie(uri, cf=cf)
    with Step(tag + "connect"):
        scf.open_link()
    out["connected"] = True
    out["protocol_version"] = cf.platform.get_protocol_version()
    out["log_toc_count"] = sum(len(g) for g in cf.log.toc.toc.values())
    out["param_toc_count"] = sum(len(g) for g in cf.param.toc.toc.values())
    out["log_toc_names"] = sorted("%s.%s" % (g, n) for g, names in cf.log.toc.toc.items() for n in names)

    with Step(tag + "all_param_values"):
        scf.wait_for_params()
    out["params"] = {"%s.%s" % (g, n): v for g, names in cf.param.values.items() for n, v in names.items()}

    # Write a parameter, wait for the firmware's echo, then ask the Crazyflie for its value again.
    name, _, text = param.partition("=")
    updates: list = []
    got = threading.Event()

    def on_update(full_name: str, value: str) -> None:
        updates.append(value)
        got.set()

    group, short = name.split(".")
    cf.param.add_update_callback(group=group, name=short, cb=on_update)
    before = cf.param.get_value(name)
    with Step(tag + "param_write"):
        cf.param.set_value(name, text)
        wait_for(got, 5.0, "echo of the %s write" % name)
    echoed = updates[-1]
    got.clear()
    with Step(tag + "param_read_back"):
        cf.param.request_param_update(name)
        wait_for(got, 5.0, "value of %s" % name)
    out["param_write"] = {"name": name, "before": before, "written": text, "echoed": echoed,
                          "read_back": updates[-1]}

    # One log block at its period.
    samples: list = []
    conf = LogConfig(name="session", period_in_ms=args.period_ms)
    for var in args.log.split(","):
        conf.add_variable(var)
    conf.data_received_cb.add_callback(lambda ts, data, block: samples.append((ts, data)))
    world_times = []
    with Step(tag + "log"):
        cf.log.add_config(conf)
        world_times.append(world_time())
        conf.start()
        sleep_world(args.log_seconds)
        conf.stop()
        world_times.append(world_time())
    out["log"] = {"period_ms": args.period_ms, "seconds": args.log_seconds, "valid": conf.valid,
                  "timestamps": [x[0] for x in samples], "values": [x[1] for x in samples],
                  "world_seconds": world_times[1] - world_times[0]}

    # RPYT setpoints: a thrust-0 unlock, then a distinctive one repeated at 100 Hz.
    roll, pitch, yawrate, thrust = (float(v) for v in args.setpoint.split(","))
    with Step(tag + "setpoints"):
        cf.commander.send_setpoint(0, 0, 0, 0)
        for _ in range(args.setpoints):
            cf.commander.send_setpoint(roll, pitch, yawrate, int(thrust))
            time.sleep(0.01)
    out["setpoints_sent"] = args.setpoints + 1
    if sim_name:
        # What the simulated Crazyflie holds now, through the world server's control API.
        from crazyflie_driver.sim.air.medium import RemoteMedium
        control = RemoteMedium()
        time.sleep(0.05)   # cflib sends asynchronously: let the last setpoint leave its queue
        state = control.crazyflie_state(sim_name)
        control.close()
        out["sim_state"] = {k: state[k] for k in ("last_setpoint", "setpoints", "params", "log_blocks")}
    out["link_needs_resending"] = bool(getattr(cf.link, "needs_resending", False))
    with Step(tag + "disconnect"):
        scf.close_link()
    out["disconnected"] = not scf.is_link_open()
    out["console"] = "".join(console)


def run(args: argparse.Namespace) -> None:
    import cflib.crtp

    backend = None
    if any(u.startswith("radio://") for u in args.uri):
        backend = install_fake_dongle(args.dongles)
    cflib.crtp.init_drivers()

    if args.scan_address:
        with Step("scan"):
            found = cflib.crtp.scan_interfaces(int(args.scan_address, 16))
        RESULT["scan"] = [entry[0] for entry in found]

    params = args.param or ["ring.headlightEnable=1"]
    names = args.sim_name or [""]
    RESULT["sessions"] = {}
    errors: list = []

    def one(i: int, uri: str) -> None:
        out = RESULT["sessions"].setdefault(uri, {})
        try:
            session(uri, params[min(i, len(params) - 1)], names[i] if i < len(names) else "", args, out)
        except Exception as e:
            import traceback
            traceback.print_exc()
            errors.append("%s in session %s: %s" % (type(e).__name__, uri, e))

    # Several URIs: one thread each, all at once (cflib shares the dongle between them).
    threads = [threading.Thread(target=one, args=(i, u), daemon=True) for i, u in enumerate(args.uri)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise RuntimeError("; ".join(errors))
    if backend is not None:
        d = backend.dongles[0]
        RESULT["dongle"] = {"bulk_out": d.bulk_out, "bulk_in": d.bulk_in,
                            "control_transfers": d.control_transfers, "serial": d.serial}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--uri", action="append", required=True, help="repeat to fly several at once")
    p.add_argument("--scan-address", default="", help="hex address to scan for first (radio only)")
    p.add_argument("--dongles", type=int, default=1)
    p.add_argument("--param", action="append", default=[],
                   help="name=value to write and read back (one per --uri, in order)")
    p.add_argument("--log", default="acc.z,pm.vbat", help="comma-separated log variables")
    p.add_argument("--period-ms", type=int, default=50)
    p.add_argument("--log-seconds", type=float, default=1.0, help="seconds of world time to log for")
    p.add_argument("--setpoint", default="1.5,2.5,-3.0,12000", help="roll,pitch,yawrate,thrust")
    p.add_argument("--setpoints", type=int, default=20)
    p.add_argument("--sim-name", action="append", default=[],
                   help="world name of each --uri's simulated Crazyflie, for a control-API check")
    p.add_argument("--timeout", type=float, default=25.0, help="whole-session watchdog (s)")
    args = p.parse_args()
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    start_watchdog(args.timeout)
    try:
        run(args)
    except Exception as e:  # reported in the JSON; the test prints it
        import traceback
        traceback.print_exc()
        RESULT["error"] = "%s (steps running: %s): %s" % (type(e).__name__, sorted(_active_steps), e)
        emit(1)
        os._exit(1)
    emit(0)


if __name__ == "__main__":
    main()
