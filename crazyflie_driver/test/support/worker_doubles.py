"""A fake Crazyflie and a recording listener, for tests of the server's worker and registry.

The fake records every packet with the time it was sent, answers from fixed log and parameter
tables, and injects faults on request (no acks, an unplugged dongle, a missing radio, a slow or
failing connect).
"""
from __future__ import annotations

import threading
import time
from typing import Any, Dict, List, Optional, Tuple

from crazyflie_driver.crtp.firmware_limits import LOG_MAX_BLOCKS, LOG_MAX_OPS
from crazyflie_driver.errors import CrazyflieError, RadioNotFound, RadioUnplugged, UnknownName
from crazyflie_driver.protocol.toc import Toc, TocEntry
from crazyflie_driver.radio.statistics import LinkStatistics
from crazyflie_driver.server.worker import CrazyflieWorker, WorkerConfig, WorkerListener

LOG_VARS = {"acc.x": "float", "acc.y": "float", "acc.z": "float", "gyro.x": "float",
            "gyro.y": "float", "gyro.z": "float", "baro.temp": "float", "baro.pressure": "float",
            "mag.x": "float", "mag.y": "float", "mag.z": "float", "pm.vbat": "float",
            "radio.rssi": "uint8_t", "stabilizer.roll": "float", "stabilizer.pitch": "float",
            "stabilizer.yaw": "float", "stabilizer.thrust": "float", "motor.m1": "uint16_t",
            "motor.m2": "uint16_t", "motor.m3": "uint16_t", "motor.m4": "uint16_t",
            "pos.x": "float", "pos.y": "float", "pos.z": "float"}
PARAMS = {"ring.headlightEnable": ("uint8_t", 0), "pid_rate.roll_kp": ("float", 250.0),
          "flightmode.althold": ("uint8_t", 0)}


class FakeBlock:
    def __init__(self, variables, period_ms, callback):
        self.variables, self.period_ms, self.callback = list(variables), period_ms, callback

    def deliver(self, ts: int, values: List[float]) -> None:
        self.callback(ts, values)


class FakeLog:
    def __init__(self, cf: FakeCrazyflie):
        self.cf = cf
        self.toc: Optional[Toc] = None
        self.blocks: List[FakeBlock] = []
        self.resets = 0
        self.max_blocks, self.max_ops = LOG_MAX_BLOCKS, LOG_MAX_OPS     # as the TOC info reports them

    def reset(self):
        self.cf.calls.append("log.reset")
        self.resets += 1
        self.blocks = []

    def fetch_toc(self):
        self.cf.calls.append("log.fetch_toc")
        self.toc = Toc([TocEntry(i, *n.split("."), t) for i, (n, t) in enumerate(self.cf.log_vars.items())])
        return self.toc

    def create_block(self, variables, period_ms, callback):
        self.cf.calls.append("log.create_block")
        b = FakeBlock(variables, period_ms, callback)
        self.blocks.append(b)
        return b


class FakeParams:
    def __init__(self, cf: FakeCrazyflie):
        self.cf = cf
        self.toc: Optional[Toc] = None
        self.values = {k: v for k, (_, v) in PARAMS.items()}

    def fetch_toc(self):
        self.cf.calls.append("params.fetch_toc")
        self.toc = Toc([TocEntry(i, *n.split("."), t) for i, (n, (t, _)) in enumerate(PARAMS.items())])
        return self.toc

    def read_all(self):
        self.cf.calls.append("params.read_all")
        return dict(self.values)

    def set(self, name, value):
        if name not in self.values:
            raise UnknownName("no parameter %s" % name)
        self.values[name] = value


class Link:
    """The part of the link contract the worker reads: its statistics."""

    def __init__(self):
        self.stats = LinkStatistics()


class FakeCrazyflie:
    """Records every packet with a timestamp; ``acking`` and ``unplugged`` inject faults."""

    def __init__(self, uri: str = "radio://0/80/2M/E7E7E7E701", connect_delay: float = 0.0,
                 connect_error: Exception = None):
        self.uri = uri
        self.calls: List[str] = []
        self.packets: List[tuple] = []      # (time, kind, args)
        self.acking = True
        self.unplugged = False
        self.connect_delay = connect_delay
        self.connect_error = connect_error
        self.log_vars = dict(LOG_VARS)
        self.log = FakeLog(self)
        self.params = FakeParams(self)
        self.link = Link()
        self.closed = False
        self._closing = threading.Event()
        self.lock = threading.Lock()
        self.radio_missing_for = 0           # connect attempts that find no dongle
        self.downlink: List[tuple] = []     # queued log packets, one fetched per null packet
        self.inject: List[BaseException] = []   # raised by the next packets, one each (a bug's stand-in)

    def connect(self):
        self.calls.append("connect")
        if self.radio_missing_for > 0:
            self.radio_missing_for -= 1
            raise RadioNotFound("no Crazyradio at index 0")
        if self.connect_delay and self._closing.wait(self.connect_delay):
            raise CrazyflieError("%s: link is not open" % self.uri)     # closed under it, as a real link ends
        if self.connect_error:
            raise self.connect_error

    def close(self):
        self.closed = True
        self._closing.set()

    def _packet(self, kind, *args):
        if self.unplugged:
            raise RadioUnplugged("dongle 0 unplugged")
        with self.lock:
            if self.inject:
                raise self.inject.pop(0)
            self.packets.append((time.monotonic(), kind, args))
            self.link.stats.record(self.acking)
        return self.acking

    def send_setpoint(self, roll, pitch, yawrate, thrust):
        return self._packet("setpoint", roll, pitch, yawrate, thrust)

    def send_keepalive(self):
        acked = self._packet("null")
        if acked and self.downlink:
            block, ts, values = self.downlink.pop(0)
            block.deliver(ts, values)
        return acked

    def emergency_stop(self):
        self._packet("estop")

    def of_kind(self, kind):
        with self.lock:
            return [p for p in self.packets if p[1] == kind]


class Recorder(WorkerListener):
    def __init__(self):
        self.params: Dict[str, Any] = {}
        self.logs: List[tuple] = []
        self.rssi: List[float] = []
        self.quality: List[tuple] = []
        self.lost: List[str] = []
        self.restored = 0
        self.worker_errors: List[tuple] = []    # (message, gave_up)

    def on_params(self, values):
        self.params = values

    def on_log(self, topic, ts, values):
        self.logs.append((topic, ts, values))

    def on_rssi(self, rssi):
        self.rssi.append(rssi)

    def on_link_quality(self, q, low):
        self.quality.append((q, low))

    def on_link_lost(self, reason):
        self.lost.append(reason)

    def on_link_restored(self):
        self.restored += 1

    def on_worker_error(self, message, gave_up):
        self.worker_errors.append((message, gave_up))


def wait_for(cond, timeout=2.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.002)
    return cond()


def started(cf=None, config=None, listener=None, ready_timeout=2.0, **kw):
    cf = cf or FakeCrazyflie()
    listener = listener or Recorder()
    w = CrazyflieWorker(config or WorkerConfig(uri=cf.uri, tf_prefix="cf1"), cf, listener, **kw)
    w.start()
    w.wait_ready(ready_timeout)
    return w, cf, listener


def poll_actions(monitor: Any, t0: float, t1: float, step: float = 0.01) -> List[Tuple[float, Any]]:
    """Poll a SafetyMonitor from t0 to t1 [s] every ``step`` s; the actions it took, with their times."""
    out, t = [], t0
    while t <= t1:
        a = monitor.poll(t)
        if a is not None:
            out.append((round(t, 3), a))
        t += step
    return out
