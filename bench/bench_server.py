#!/usr/bin/env python3
"""crazyflie_server throughput and latency on one (simulated) Crazyradio.

For 1, 2, 4 and 8 Crazyflies sharing one fake dongle (PA timing model: 0.8 ms per bulk round
trip), with the fixed log blocks on or off: how many setpoints per second each Crazyflie actually
receives when cmd_vel arrives at 100 Hz per Crazyflie, and the cmd_vel-to-radio latency (from the
moment cmd_vel is handed to the worker until the setpoint's radio round trip is acked; median and
p99). Also the IMU messages per second each Crazyflie delivers with logging on.

Runs the server's workers (registry, worker) in process against the real simulated world (sim.room.world.World stepping
in real time, sim.world_server.WorldServer's medium without TCP), so it measures the driver, not ROS transport. Usage:
    /usr/bin/python3 bench/bench_server.py [--seconds 3] [--out FILE]
"""
from __future__ import annotations

import statistics
import sys
import threading
import time

import bench_support as bs
from bench_support import percentile
from crazyflie_driver.protocol.crazyflie import Crazyflie  # noqa: E402
from crazyflie_driver.radio.shared_radio import RadioManager  # noqa: E402
from crazyflie_driver.server.registry import CrazyflieRegistry  # noqa: E402
from crazyflie_driver.server.worker import WorkerConfig, WorkerListener  # noqa: E402
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend  # noqa: E402
from crazyflie_driver.sim.room.world import World  # noqa: E402
from crazyflie_driver.sim.world_server import WorldServer  # noqa: E402

CMD_RATE_HZ = 100.0


class Counter(WorkerListener):
    def __init__(self) -> None:
        self.imu = 0

    def on_log(self, topic, ts, values) -> None:
        if topic == "imu":
            self.imu += 1


class TimedCrazyflie(Crazyflie):
    """Records, for each setpoint sent, the time from the latest cmd_vel handed to its worker
    (``handed_at``, set by the commander) until the setpoint's round trip returned."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.handed_at = None
        self.latencies: list = []

    def send_setpoint(self, roll, pitch, yawrate, thrust):
        handed = self.handed_at
        acked = super().send_setpoint(roll, pitch, yawrate, thrust)
        if handed is not None:
            self.latencies.append(time.monotonic() - handed)
        return acked


def run_case(n: int, logging_on: bool, seconds: float, cache_dir: str) -> dict:
    world = World(speed=1.0, seed=1)
    server = WorldServer(world, dongles=1)
    uris = ["radio://0/80/2M/E7E7E7E7%02X" % (i + 1) for i in range(n)]
    for i, uri in enumerate(uris):
        server.add_crazyflie(uri, "cf%d" % (i + 1), (0.5 * i, 0.0, 0.0))
    world.start()
    manager = RadioManager(backend=FakeUsbBackend(server.medium, dongles=1))
    crazyflies = {}

    def factory(uri):
        crazyflies[uri] = TimedCrazyflie(uri, radio_manager=manager, cache_dir=cache_dir)
        return crazyflies[uri]
    registry = CrazyflieRegistry(factory)
    workers, counters, latencies, timed = [], [], [], []
    try:
        for i, uri in enumerate(uris):
            c = Counter()
            w = registry.add(WorkerConfig(uri=uri, tf_prefix="cf%d" % (i + 1), enable_logging=logging_on,
                                          enable_parameters=False), c, timeout=60.0)
            workers.append(w)
            counters.append(c)
            timed.append(crazyflies[uri])
            latencies.append(crazyflies[uri].latencies)
        stop = threading.Event()

        def commander(w, cf):
            period = 1.0 / CMD_RATE_HZ
            next_t = time.monotonic()
            while not stop.is_set():
                cf.handed_at = time.monotonic()
                w.cmd_vel(0.0, 0.0, 0.0, 0.0)
                next_t += period
                time.sleep(max(0.0, next_t - time.monotonic()))

        time.sleep(0.5)                                   # let log blocks settle
        for own in latencies:
            own.clear()
        sent0 = [w.setpoints_sent for w in workers]
        imu0 = [c.imu for c in counters]
        snap0 = [server.crazyflie(u).snapshot()["setpoints"] for u in uris]
        trips0 = server.medium.round_trips
        threads = [threading.Thread(target=commander, args=(w, cf), daemon=True) for w, cf in zip(workers, timed)]
        t0 = time.monotonic()
        for t in threads:
            t.start()
        time.sleep(seconds)
        stop.set()
        for t in threads:
            t.join()
        elapsed = time.monotonic() - t0
        received = [(server.crazyflie(u).snapshot()["setpoints"] - s0) / elapsed for u, s0 in zip(uris, snap0)]
        sent = [(w.setpoints_sent - s0) / elapsed for w, s0 in zip(workers, sent0)]
        imu = [(c.imu - i0) / elapsed for c, i0 in zip(counters, imu0)]
        all_lat = [x for own in latencies for x in own]
        return {"n": n, "logging": logging_on, "received_min": min(received),
                "received_mean": statistics.mean(received), "sent_mean": statistics.mean(sent),
                "imu_min": min(imu) if logging_on else 0.0,
                "lat_median_ms": 1000 * statistics.median(all_lat) if all_lat else float("nan"),
                "lat_p99_ms": 1000 * percentile(all_lat, 99) if all_lat else float("nan"),
                "world_rtf": world.realtime_factor,
                "round_trips_per_s": (server.medium.round_trips - trips0) / elapsed}
    finally:
        registry.shutdown()
        world.stop()


def main() -> int:
    ap = bs.parser(__doc__, "server.txt", 3.0, counts="1,2,4,8")
    args = ap.parse_args()
    import tempfile
    cache_dir = tempfile.mkdtemp(prefix="cf_bench_toc_")
    lines = ["crazyflie_server core on one fake Crazyradio PA (0.8 ms per round trip), cmd_vel offered at "
             "%.0f Hz per Crazyflie, %.1f s per case" % (CMD_RATE_HZ, args.seconds),
             bs.machine_line(),
             "",
             "%4s %8s %18s %16s %12s %14s %12s %12s %6s" % ("CFs", "logging", "setpoints/s/CF min", "mean",
                                                       "IMU/s/CF min", "latency med ms", "p99 ms", "radio RT/s",
                                                       "world RTF")]
    print("\n".join(lines), flush=True)
    for n in bs.counts_of(args.counts):
        for logging_on in (False, True):
            r = run_case(n, logging_on, args.seconds, cache_dir)
            line = "%4d %8s %18.1f %16.1f %12s %14.2f %12.2f %12.0f %6.2f" % (
                r["n"], "on" if logging_on else "off", r["received_min"], r["received_mean"],
                "%.1f" % r["imu_min"] if logging_on else "-", r["lat_median_ms"], r["lat_p99_ms"],
                r["round_trips_per_s"], r["world_rtf"])
            print(line, flush=True)
            lines.append(line)
    bs.write_lines(args.out, lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
