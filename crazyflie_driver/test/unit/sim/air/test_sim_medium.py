"""The simulated air: registry, fault injection statistics, RSSI and power (LocalMedium)."""
from __future__ import annotations

import pytest

from crazyflie_driver.sim.air.medium import LocalMedium, RemoteMedium, WorldNotRunning, parse_address
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.sim_doubles import FakeVehicle

ADDR = b"\xe7\xe7\xe7\xe7\x01"


def world(seed=1, dongles=2, firmware="current"):
    m = LocalMedium(dongles=dongles, seed=seed)
    cf = SimulatedCrazyflie(ADDR, FakeVehicle(), firmware=firmware)
    while cf.pop_outgoing() is not None:   # boot text
        pass
    m.add_crazyflie(cf, 80, 2)
    return m, cf


def test_only_the_addressed_crazyflie_acks():
    m, cf = world()
    assert m.transmit(0, 80, 2, ADDR, b"\xff").acked
    for ch, rate, addr in ((81, 2, ADDR), (80, 1, ADDR), (80, 2, b"\xe7" * 5)):
        r = m.transmit(0, ch, rate, addr, b"\xff", arc=3)
        assert not r.acked and r.retries == 3 and r.payload == b""
    with pytest.raises(ValueError):
        m.add_crazyflie(SimulatedCrazyflie(ADDR, FakeVehicle()), 80, 2)


def test_packet_loss_statistics_are_seeded_and_near_the_setting():
    def run(seed):
        m, cf = world(seed)
        m.set_dongle_faults(0, packet_loss=30)
        acks = [m.transmit(0, 80, 2, ADDR, b"\xff").acked for _ in range(4000)]
        return acks, cf
    a, cf = run(5)
    b, _ = run(5)
    assert a == b
    ratio = sum(a) / len(a)
    assert 0.67 < ratio < 0.73
    # the other dongle is unaffected
    m, _ = world()
    m.set_dongle_faults(0, packet_loss=100)
    assert not m.transmit(0, 80, 2, ADDR, b"\xff").acked
    assert m.transmit(1, 80, 2, ADDR, b"\xff").acked


def test_ack_loss_still_delivers_the_packet():
    m, cf = world(seed=3)
    m.set_dongle_faults(0, ack_loss=100)
    r = m.transmit(0, 80, 2, ADDR, b"\x3c" + bytes(14))
    assert not r.acked and cf.vehicle.setpoints == [(0.0, 0.0, 0.0, 0)]
    m.set_dongle_faults(0, ack_loss=0, packet_loss=100)
    m.transmit(0, 80, 2, ADDR, b"\x3c" + bytes(14))
    assert len(cf.vehicle.setpoints) == 1


def test_ack_loss_with_safelink_is_invisible_to_the_protocol():
    m, cf = world(seed=11)
    assert m.transmit(0, 80, 2, ADDR, b"\xff\x05\x01").payload == b"\xff\x05\x01"
    m.set_dongle_faults(0, ack_loss=40)
    up = down = 0
    got = []
    sent = seq = 0
    while len(got) < 50 and sent < 2000:
        data = bytes([0xF0 | (up << 3) | (down << 2), seq & 0xFF])   # echo request carrying a counter
        r = m.transmit(0, 80, 2, ADDR, data)
        sent += 1
        if r.acked:
            if r.payload and (r.payload[0] & 0x04) == (down << 2):
                down ^= 1
                if (r.payload[0] & 0xF3) != 0xF3:
                    got.append(r.payload[1])
            up ^= 1
            seq += 1   # the next request; a lost ack means resending the same bytes
    # every echo arrived exactly once and in order despite 40 % lost acks
    assert got == list(range(50))
    assert cf.link.duplicates > 0


def test_unplugged_dongle_and_power_off():
    m, cf = world()
    m.set_dongle_faults(1, unplugged=True, latency_s=0.002)
    r = m.transmit(1, 80, 2, ADDR, b"\xff")
    assert r.unplugged and not r.acked and r.latency_s == 0.002
    assert m.transmit(5, 80, 2, ADDR, b"\xff").unplugged
    cf.power_off()
    assert not m.transmit(0, 80, 2, ADDR, b"\xff").acked
    cf.power_on()
    assert m.transmit(0, 80, 2, ADDR, b"\xff").acked
    with pytest.raises(ValueError):
        m.set_dongle_faults(0, packet_loss=120)
    with pytest.raises(ValueError):
        m.set_dongle_faults(7, packet_loss=1)


def test_rssi_model_reaches_acks_and_power_detector():
    m, cf = world(firmware="2016.02")
    m.set_rssi(80, 2, ADDR, -55.0, noise_db=0.0)
    r = m.transmit(0, 80, 2, ADDR, b"\xff")
    assert r.payload[1:] == b"\x01\x37" and r.power_detector
    m.set_rssi(80, 2, ADDR, -70.0, noise_db=3.0)
    values = []
    for _ in range(300):
        r = m.transmit(0, 80, 2, ADDR, b"\xff")
        values.append(-r.payload[2])
        assert r.power_detector == (-r.payload[2] > -64)
    mean = sum(values) / len(values)
    assert -71 < mean < -69 and len(set(values)) > 5
    assert cf.read_value("radio.rssi") == -values[-1]


def test_no_ack_packets_are_delivered_without_a_reply():
    m, cf = world()
    r = m.transmit(0, 80, 2, ADDR, b"\x3c" + bytes(14), ack_enabled=False)
    assert not r.acked and cf.vehicle.setpoints == [(0.0, 0.0, 0.0, 0)]


def test_remote_medium_without_a_world_names_the_fix():
    with pytest.raises(WorldNotRunning) as e:
        RemoteMedium("127.0.0.1", 1).dongle_count()
    assert "no simulated world at 127.0.0.1:1" in str(e.value)
    assert "rosrun crazyflie_driver crazyflie_world_server" in str(e.value)


def test_parse_address():
    assert parse_address("127.0.0.1:1234") == ("127.0.0.1", 1234)
    assert parse_address("localhost:5") == ("127.0.0.1", 5)
    with pytest.raises(ValueError):
        parse_address("10.0.0.1:19840")
    with pytest.raises(ValueError):
        parse_address("127.0.0.1:port")
