#!/usr/bin/env python3
"""Packets that Bitcraze's cflib builds for given calls, as hex, for byte-for-byte comparison.

Run with cflib's interpreter. Reads a JSON list of calls on stdin; each call is
{"api": ..., "method": ..., "args": [...], "kwargs": {...}, "version": protocol version}.
APIs: "commander", "high_level", "localization", "supervisor" (cflib's classes, on a stand-in
Crazyflie that records packets), "poly4d" (Poly4D.pack), "compressed_start",
"compressed_segment" (the compressed trajectory elements), "mem_write" (cflib's memory write
request, chunked), "quaternion" (compress_quaternion). Prints one JSON list: per call the hex
strings of the packets (header byte first) or of the packed bytes.
"""
from __future__ import annotations

import json
import sys
import warnings

from cflib.crazyflie.commander import Commander
from cflib.crazyflie.high_level_commander import HighLevelCommander
from cflib.crazyflie.localization import Localization
from cflib.crazyflie.mem import _WriteRequest
from cflib.crazyflie.mem.trajectory_memory import CompressedSegment, CompressedStart, Poly4D
from cflib.crazyflie.supervisor import Supervisor
from cflib.utils.encoding import compress_quaternion


class _Platform:
    def __init__(self, version):
        self.version = version

    def get_protocol_version(self):
        return self.version


class _RecordingCrazyflie:
    """What cflib's port classes need from a Crazyflie: send_packet and a protocol version."""

    def __init__(self, version):
        self.platform = _Platform(version)
        self.sent = []

    def send_packet(self, pk, expected_reply=(), resend=False, timeout=0.2):
        self.sent.append((bytes([pk.header]) + bytes(pk.data)).hex())

    def add_port_callback(self, port, cb):
        pass


class _Mem:
    def __init__(self, mem_id):
        self.id = mem_id


def run(call):
    api, args, kwargs = call["api"], call.get("args", []), call.get("kwargs", {})
    cf = _RecordingCrazyflie(call.get("version", 12))
    if api in ("commander", "high_level", "localization", "supervisor"):
        cls = {"commander": Commander, "high_level": HighLevelCommander, "localization": Localization,
               "supervisor": Supervisor}[api]
        getattr(cls(cf), call["method"])(*args, **kwargs)
        return cf.sent
    if api == "poly4d":
        duration, x, y, z, yaw = args
        return [bytes(Poly4D(duration, Poly4D.Poly(x), Poly4D.Poly(y), Poly4D.Poly(z), Poly4D.Poly(yaw)).pack()).hex()]
    if api == "compressed_start":
        return [bytes(CompressedStart(*args).pack()).hex()]
    if api == "compressed_segment":
        return [bytes(CompressedSegment(*args).pack()).hex()]
    if api == "mem_write":
        mem_id, addr, data_hex = args
        request = _WriteRequest(_Mem(mem_id), addr, bytearray.fromhex(data_hex), cf)
        request.start()
        while request._data:
            request.write_done(request._current_addr)
        return cf.sent
    if api == "quaternion":
        return ["%08x" % int(compress_quaternion(args))]
    raise ValueError("unknown api %r" % api)


def main():
    warnings.simplefilter("ignore")
    calls = json.load(sys.stdin)
    print(json.dumps([run(c) for c in calls]))


if __name__ == "__main__":
    main()
