"""UDP endpoints as cflib's UDP driver uses them (docs/protocol.md, "The UDP link"): scan probe, connected
socket, pushes."""
from __future__ import annotations

import socket
import struct

import pytest

from crazyflie_driver.sim.air.udp import UdpEndpoint
from crazyflie_driver.sim.world_server import WorldServer
from support.sim_doubles import FakeWorld

URI = "radio://0/80/2M/E7E7E7E701"


@pytest.fixture
def endpoint():
    world = FakeWorld()
    server = WorldServer(world, port=0, udp_base_port=0)   # 0: ephemeral UDP ports for the test
    cf = server.add_crazyflie(URI, "cf1")
    ep = server.entries()[0].udp
    yield world, cf, ep
    server.stop()


def client(ep, timeout=1.0):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(timeout)
    s.connect((ep.host, ep.port))      # like cflib: only datagrams from the endpoint's address arrive
    return s


def receive_until(s, predicate, limit=60):
    for _ in range(limit):
        data = s.recv(1024)
        if predicate(data):
            return data
    raise AssertionError("no matching datagram")


def test_scan_probe_is_answered_within_100ms(endpoint):
    world, cf, ep = endpoint
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(0.1)
    s.sendto(b"\xff", (ep.host, ep.port))
    data, addr = s.recvfrom(1024)
    assert data and addr == (ep.host, ep.port)
    s.close()
    assert ep.uri == "udp://127.0.0.1:%d" % ep.port


def test_connect_sequence_and_param_read_over_udp(endpoint):
    world, cf, ep = endpoint
    s = client(ep)
    s.send(b"\xfd\x00")                                # cflib's first packet: link source
    src = receive_until(s, lambda d: (d[0] & 0xF3) == 0xF1)
    assert src[1:] == b"Bitcraze Crazyflie" + bytes(12)
    s.send(b"\xdd\x00")
    assert receive_until(s, lambda d: (d[0] & 0xF3) == 0xD1) == b"\xdd\x00\x0c\x00\x00\x00"
    ident = cf.params.ident("pid_rate.yaw_kp")
    s.send(b"\x2d" + struct.pack("<H", ident))
    reply = receive_until(s, lambda d: (d[0] & 0xF3) == 0x21)
    assert reply == b"\x2d" + struct.pack("<HBf", ident, 0, 120.0)
    s.send(b"\x2e" + struct.pack("<Hf", ident, 99.5))
    assert receive_until(s, lambda d: (d[0] & 0xF3) == 0x22) == b"\x2e" + struct.pack("<Hf", ident, 99.5)
    assert world.vehicle("cf1").written == [("pid_rate.yaw_kp", 99.5)]
    s.close()


def test_boot_text_waits_for_a_client_and_log_data_is_pushed(endpoint):
    world, cf, ep = endpoint
    world.vehicle("cf1").readings["baro.temp"] = 23.5
    s = client(ep)
    s.send(b"\xfc\x01")                                  # echo; the queued console text comes first
    first = s.recv(1024)
    assert first[0] == 0x00 and first[1:].startswith(b"SYS: ")
    receive_until(s, lambda d: d == b"\xfc\x01")
    temp = [e.full_name for e in cf.logs.entries].index("baro.temp")
    s.send(b"\x5d\x06\x02" + struct.pack("<BH", 7, temp))
    assert receive_until(s, lambda d: d[0] & 0xF3 == 0x51) == b"\x5d\x06\x02\x00"
    s.send(b"\x5d\x03\x02\x0a")                          # 100 ms
    receive_until(s, lambda d: d[:2] == b"\x5d\x03")
    world.advance(0.35)                                  # world ticks push data without any request
    got = [receive_until(s, lambda d: d[0] == 0x52) for _ in range(3)]
    assert [int.from_bytes(d[2:5], "little") for d in got] == [100, 200, 300]
    assert all(d[5:] == struct.pack("<f", 23.5) for d in got)
    s.close()


def test_endpoints_are_loopback_only():
    with pytest.raises(ValueError, match="loopback"):
        UdpEndpoint(object(), 0, host="0.0.0.0")
