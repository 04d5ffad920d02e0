"""Regression tests for protocol bugs that running Bitcraze's cflib against the simulation found.

They need no cflib: each replays the packets of the failing cflib session directly.
"""
from __future__ import annotations

import struct

from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.sim_doubles import FakeVehicle, drain

ADDRESS = bytes.fromhex("E7E7E7E701")
LOG_CONTROL = 0x51   # port 5, channel 1
LOG_DATA = 0x52      # port 5, channel 2


def test_log_block_over_packet_link_survives_an_earlier_radio_users_silence():
    """cflib over UDP after a radio session: the radio link-loss cleanup (current firmware deletes
    log blocks after 1 s without radio packets) deleted the UDP host's new log block, so cflib never
    got a sample. A packet link is the active link, as USB is on the real firmware."""
    v = FakeVehicle(readings={"acc.z": 1.0})
    cf = SimulatedCrazyflie(ADDRESS, v, firmware="current")
    drain(cf)
    cf.handle_radio_packet(b"\xff")                 # a radio host was here at t = 0 ...
    v.t = 5.0                                       # ... and left; a UDP host connects later
    acc_z = [e.full_name for e in cf.logs.entries].index("acc.z")
    cf.handle_crtp(bytes([LOG_CONTROL, 6, 1, 7]) + struct.pack("<H", acc_z))   # CREATE_V2 block 1
    cf.handle_crtp(bytes([LOG_CONTROL, 3, 1, 1]))                              # START, 10 ms
    assert drain(cf) == [bytes([LOG_CONTROL, 6, 1, 0]), bytes([LOG_CONTROL, 3, 1, 0])]
    for t in (5.01, 5.02, 5.03):
        v.t = t
        cf.tick(t)
    data = drain(cf)
    assert len(data) == 3 and all(p[0] == LOG_DATA and p[1] == 1 for p in data)
    assert struct.unpack("<f", data[0][5:9])[0] == 1.0


def test_radio_link_loss_still_deletes_log_blocks():
    """The fix keeps the firmware's radio behaviour: radio silence > 1 s deletes the blocks."""
    v = FakeVehicle(readings={"acc.z": 1.0})
    cf = SimulatedCrazyflie(ADDRESS, v, firmware="current")
    drain(cf)
    acc_z = [e.full_name for e in cf.logs.entries].index("acc.z")
    # Over the radio without safelink: every packet is delivered.
    cf.handle_radio_packet(bytes([LOG_CONTROL, 6, 1, 7]) + struct.pack("<H", acc_z))
    cf.handle_radio_packet(bytes([LOG_CONTROL, 3, 1, 1]))
    v.t = 0.5
    cf.tick(0.5)
    assert cf.logs.blocks
    v.t = 1.6
    cf.tick(1.6)
    assert not cf.logs.blocks


def test_radio_host_gets_its_replies_after_a_udp_host_left():
    """cflib over the radio after a cflib session over UDP: the UDP endpoint kept sending every
    queued packet to the departed UDP client, stealing the radio host's replies (cflib, which never
    re-sends on a safelink link, stalled in connect). Only the active link drains the TX queue:
    the last link a packet came in on, as the firmware sends on the link it switched to."""
    import socket
    import time as _time

    from crazyflie_driver.sim.air.udp import UdpEndpoint

    v = FakeVehicle()
    cf = SimulatedCrazyflie(ADDRESS, v, firmware="current")
    drain(cf)
    endpoint = UdpEndpoint(cf, port=0)
    endpoint.start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(1.0)
    try:
        client.connect((endpoint.host, endpoint.port))
        client.send(b"\xdd\x00")                                   # UDP host: protocol version
        assert client.recv(64)[:2] == b"\xdd\x00"
        # The UDP host goes away without a word (cflib sends nothing on close); a radio host comes.
        cf.handle_radio_packet(b"\xdd\x00")                         # no safelink: delivered
        _time.sleep(0.1)                                            # time for a UDP flush to run
        ack = cf.handle_radio_packet(b"\xff")                       # poll: the reply rides this ack
        assert ack[0] & 0xF3 == 0xD1 and ack[1:3] == b"\x00\x0c", ack.hex()
        client.settimeout(0.1)
        try:
            stolen = client.recv(64)
        except socket.timeout:
            stolen = None
        assert stolen is None
        # And the UDP host is served again as soon as it speaks.
        client.settimeout(1.0)
        client.send(b"\xdd\x00")
        assert client.recv(64)[:2] == b"\xdd\x00"
    finally:
        client.close()
        endpoint.stop()
