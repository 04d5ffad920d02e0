#!/usr/bin/env python3
"""Packets per second and round trip for 1, 2, 4 and 8 Crazyflies on one fake Crazyradio: the PA
(firmware 0.53) against the Crazyradio 2.0 without inline mode (5.0: the legacy path) and with it
(firmware 5.4), the Crazyflies on the same
channel (different addresses) or each on its own channel.

Each case runs the driver's real path (``RadioLink`` with safelink -> ``SharedRadio`` -> ``Crazyradio``
-> pyusb -> ``FakeUsbBackend`` -> ``LocalMedium`` -> simulated nRF and firmware of ``SimulatedCrazyflie``)
with one thread per Crazyflie, as the server's per-Crazyflie workers drive a dongle, and the model's
default timing (``DongleTiming``: PA 0.8 ms per bulk round trip, 1.5 ms per control transfer; 2.0
the same bulk round trip and 2.5 ms per control transfer). By default the dongles wait on a virtual
clock (``--clock virtual``: a sleep advances it, nothing waits), so the figures are the timing model's
own, whatever the machine's load, and the bench needs no lock; ``--clock wall`` sleeps for real and
adds the host's own cost (run it under the lock). Two phases per case:

* throughput: every thread sends RPYT setpoints as fast as the dongle takes them (packets/s per
  Crazyflie, the slowest one, control transfers per packet);
* round trip: every thread sends link echoes (port 15) and waits for each answer (the ping time
  Bitcraze quotes: packet up, answer back in a later ack), median and 90th percentile.

Bitcraze's figures beside it (crazyradio2-firmware PR #25 and issue #23, docs/simulation.md).
Usage:
    /usr/bin/python3 bench/bench_dongles.py [--seconds 2] [--counts 1,2,4,8]
    flock /tmp/ros.lock /usr/bin/python3 bench/bench_dongles.py --clock wall
"""
from __future__ import annotations

import statistics
import struct
import sys
import threading
import time
from typing import Dict, List, Tuple

import bench_support as bs
from bench_support import IdleVehicle
from crazyflie_driver.crtp.packet import CRTPPacket  # noqa: E402
from crazyflie_driver.radio.link import RadioLink  # noqa: E402
from crazyflie_driver.radio.shared_radio import RadioManager  # noqa: E402
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend  # noqa: E402
from crazyflie_driver.sim.air.medium import LocalMedium  # noqa: E402
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie  # noqa: E402

SETPOINT = bytes([0x30]) + struct.pack("<fffH", 0.0, 0.0, 0.0, 0)   # port 3 ch 0 RPYT, thrust 0
ECHO_PORT = 15
WARMUP_S = 0.2
SAME_CHANNEL = 80


class VirtualClock:
    """The dongles' clock (``time()``/``sleep(s)``) in virtual seconds: a sleep advances it at once.
    Transfers are serialised by the dongle, so its time is the sum of the transfers' modelled times."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.now = 0.0

    def time(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        with self._lock:
            self.now += seconds


class WallClock:
    def time(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        time.sleep(seconds)


def wait_for(clock, seconds: float) -> None:
    """Until ``seconds`` of ``clock`` have gone by (checked on the wall clock every millisecond)."""
    end = clock.time() + seconds
    while clock.time() < end:
        time.sleep(0.001)


def channel_of(i: int, spread: bool) -> int:
    """Crazyflie i's channel: all on 80, or 10, 20, ... 80 (the 2.0 sends nothing above 100)."""
    return 10 * (i + 1) if spread else SAME_CHANNEL


def run_case(model: str, n: int, spread: bool, seconds: float, clock) -> dict:
    backend, links = open_links(model, n, spread, clock)
    counts: List[int] = [0] * n
    pings: List[List[float]] = [[] for _ in range(n)]
    phase = {"name": "throughput"}
    stop = threading.Event()
    threads = [threading.Thread(target=drive_link, args=(links[i], i, clock, phase, stop, counts, pings), daemon=True)
               for i in range(n)]
    for t in threads:
        t.start()
    wait_for(clock, WARMUP_S)
    dongle = backend.dongles[0]
    c0, ctrl0, t0 = list(counts), dongle.control_transfers, clock.time()
    wait_for(clock, seconds)
    c1, ctrl1, t1 = list(counts), dongle.control_transfers, clock.time()
    phase["name"] = "ping"
    wait_for(clock, WARMUP_S)
    for p in pings:
        p.clear()
    wait_for(clock, seconds / 2)
    measured = [list(p) for p in pings]
    stop.set()
    for t in threads:
        t.join(5.0)
    for link in links:
        link.close()
    return case_figures(c0, c1, t1 - t0, ctrl1 - ctrl0, measured)


def open_links(model: str, n: int, spread: bool, clock) -> Tuple[FakeUsbBackend, List[RadioLink]]:
    """``n`` simulated Crazyflies behind one fake dongle of ``model``, a safelink ``RadioLink`` open to each."""
    medium = LocalMedium(dongles=1, seed=1)
    for i in range(n):
        cf = SimulatedCrazyflie(bytes([0xE7, 0xE7, 0xE7, 0xE7, i + 1]), IdleVehicle())
        medium.add_crazyflie(cf, channel_of(i, spread), 2)
    backend = FakeUsbBackend(medium, dongles=1, model=model, clock=clock)
    manager = RadioManager(backend=backend)
    links = [RadioLink("radio://0/%d/2M/E7E7E7E7%02X" % (channel_of(i, spread), i + 1), manager) for i in range(n)]
    for link in links:
        link.open()
    assert all(link.safelink for link in links), "safelink was not negotiated"
    return backend, links


def drive_link(link: RadioLink, i: int, clock, phase: Dict[str, str], stop: threading.Event, counts: List[int],
               pings: List[List[float]]) -> None:
    """One Crazyflie's thread: setpoints as fast as the dongle takes them (counted in ``counts[i]``) while
    ``phase`` is "throughput", then echo round trips (their times in ``pings[i]``), until ``stop``."""
    seq = 0
    while not stop.is_set():
        if phase["name"] == "throughput":
            if link.send_bytes(SETPOINT):
                counts[i] += 1
            continue
        seq = (seq + 1) & 0xFFFF
        tag = struct.pack("<HB", seq, i)
        t0 = clock.time()
        link.request(CRTPPacket(ECHO_PORT, 0, tag),
                     lambda p, tag=tag: p.port == ECHO_PORT and p.channel == 0 and p.data == tag,
                     timeout=1.0, what="echo")
        pings[i].append(clock.time() - t0)


def case_figures(before: List[int], after: List[int], elapsed: float, control_transfers: int,
                 pings: List[List[float]]) -> dict:
    """A case's row from the setpoint counts per Crazyflie at the start and the end of ``elapsed`` s, the
    dongle's control transfers meanwhile, and the echo round trips (s) of each Crazyflie."""
    per_cf = [(b - a) / elapsed for a, b in zip(before, after)]
    packets = sum(after) - sum(before)
    all_pings = sorted(x for p in pings for x in p)
    return {"rate_cf": sum(per_cf) / len(per_cf), "rate_min": min(per_cf), "rate": packets / elapsed,
            "ctrl_per_packet": control_transfers / packets if packets else float("nan"),
            "ping_ms": 1000.0 * statistics.median(all_pings) if all_pings else float("nan"),
            "ping_p90_ms": 1000.0 * all_pings[int(0.9 * (len(all_pings) - 1))] if all_pings else float("nan")}


def main() -> int:
    ap = bs.parser(__doc__, "dongles.txt", 2.0, counts="1,2,4,8")
    ap.add_argument("--models", default="PA,2.0-5.0,2.0")
    ap.add_argument("--clock", choices=("virtual", "wall"), default="virtual")
    args = ap.parse_args()
    table = bs.Table(
        ["Packets/s and round trip per Crazyflie through one fake Crazyradio: PA (0.53) and 2.0-5.0 (a control",
         "transfer per change of channel or address) vs 2.0 (5.4, inline mode); %.1f s of setpoints then %.1f s of"
         % (args.seconds, args.seconds / 2),
         "echo round trips per case, one thread per Crazyflie, the model's default timing, %s"
         % ("on a virtual clock (the model's own figures)" if args.clock == "virtual" else "real sleeps"),
         bs.machine_line(),
         ""],
        [("dongle", "<6"), ("channels", "<9"), ("CFs", "3d"), ("packets/s per CF", "16.0f"), ("slowest CF", "10.0f"),
         ("total/s", "8.0f"), ("ctrl/packet", "11.2f"), ("RTT median ms", "13.1f"), ("RTT p90 ms", "10.1f")])
    for model in args.models.split(","):
        for spread in (False, True):
            for n in bs.counts_of(args.counts):
                if n == 1 and spread:
                    continue            # one Crazyflie has one channel
                r = run_case(model, n, spread, args.seconds, VirtualClock() if args.clock == "virtual" else WallClock())
                table.row(model, "different" if spread else "same", n, r["rate_cf"], r["rate_min"], r["rate"],
                          r["ctrl_per_packet"], r["ping_ms"], r["ping_p90_ms"])
    table.write(args.out, [
        "Bitcraze (crazyradio2-firmware PR #25, a Crazyradio 2.0 on hardware, 2 Crazyflies on different channels",
        "and addresses): round trip 30 ms -> 6 ms, ~100 -> ~500 packets/s per Crazyflie with inline mode.",
        "Its prototype bench (issue #23): 1 / 2 / 3 Crazyflies 3 / 5.7 / 8 ms ping, 1274 / 685 / 456 packets/s each.",
        "ctrl/packet: vendor requests per acked packet (0 with inline mode, after the first SET_INLINE_MODE).",
        "RTT: echo sent until its answer is dispatched, all Crazyflies pinging at once."])
    return 0


if __name__ == "__main__":
    sys.exit(main())
