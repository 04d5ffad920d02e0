"""World server <-> RemoteMedium round trips in process, control calls, and the CLI's lifecycle."""
from __future__ import annotations

import pathlib
import signal
import struct
import subprocess
import sys
import threading
import time

import pytest

from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.sim.air.medium import RemoteMedium, WorldNotRunning
from crazyflie_driver.sim.world_server import WorldServer, load_vehicle_config, main
from support.sim_doubles import FakeWorld

URI1 = "radio://0/80/2M/E7E7E7E701"
URI2 = "radio://0/80/2M/E7E7E7E702"
A1 = bytes.fromhex("E7E7E7E701")
A2 = bytes.fromhex("E7E7E7E702")
TEST = pathlib.Path(__file__).resolve().parents[2]        # crazyflie_driver/test


@pytest.fixture
def served():
    world = FakeWorld()
    server = WorldServer(world, dongles=2, port=0, seed=1)
    server.add_crazyflie(URI1, "cf1")
    server.add_crazyflie(URI2, "cf2", firmware="2016.02")
    for e in server.entries():
        while e.crazyflie.pop_outgoing() is not None:
            pass
    host, port = server.start()
    medium = RemoteMedium(host, port)
    yield world, server, medium
    medium.close()
    server.stop()


def request(medium, address, raw, polls=5):
    """Send one packet and poll until a non-empty downlink arrives (no safelink)."""
    r = medium.transmit(0, 80, 2, address, raw)
    assert r.acked
    for _ in range(polls):
        r = medium.transmit(0, 80, 2, address, b"\xff")
        if r.payload and (r.payload[0] & 0xF3) != 0xF3:
            return r.payload
    raise AssertionError("no reply to %s" % raw.hex())


def test_transmit_round_trip_both_generations(served):
    world, server, medium = served
    assert medium.dongle_count() == 2
    assert medium.transmit(0, 80, 2, A1, b"\xff").payload in (b"\xf3", b"\xf7")
    r = medium.transmit(1, 80, 2, A2, b"\xff")
    assert r.acked and r.payload[1] == 0x01 and len(r.payload) == 3
    assert medium.transmit(0, 80, 2, A1, b"\xff\x05\x01").payload == b"\xff\x05\x01"
    assert request(medium, A2, b"\xdd\x00")[1:] == b"\x00\x02\x00\x00\x00"
    assert not medium.transmit(0, 81, 2, A1, b"\xff").acked


def test_control_calls(served):
    world, server, medium = served
    assert [d["uri"] for d in medium.list_crazyflies()] == [URI1, URI2]
    medium.transmit(0, 80, 2, A1, b"\x3c" + struct.pack("<fffH", 1.0, 2.0, 3.0, 1000))
    state = medium.crazyflie_state(URI1)
    assert state["last_setpoint"] == [1.0, 2.0, 3.0, 1000] and not state["emergency"]
    medium.transmit(0, 80, 2, A1, b"\x9d\x03")
    assert medium.crazyflie_state("cf1")["emergency"] is True
    assert world.vehicle("cf1").estops == 1
    medium.power(URI2, False)
    assert not medium.transmit(0, 80, 2, A2, b"\xff").acked
    medium.power(URI2, True)
    assert medium.transmit(0, 80, 2, A2, b"\xff").acked
    medium.set_dongle_faults(1, unplugged=True)
    assert medium.transmit(1, 80, 2, A1, b"\xff").unplugged
    assert medium.dongle_faults(1).unplugged and not medium.dongle_faults(0).unplugged
    medium.set_dongle_faults(1, unplugged=False)
    assert not medium.dongle_faults(1).unplugged
    medium.set_dongle_faults(0, packet_loss=100)
    assert not medium.transmit(0, 80, 2, A1, b"\xff").acked
    medium.set_dongle_faults(0, packet_loss=0)
    uri3 = "radio://0/90/1M/E7E7E7E703"
    assert medium.add_crazyflie(uri3, name="cf3", position=(1, 2, 0))["name"] == "cf3"
    assert world.vehicle("cf3").position == (1.0, 2.0, 0.0)
    assert medium.transmit(0, 90, 1, bytes.fromhex("E7E7E7E703"), b"\xff").acked
    medium.remove_crazyflie(uri3)
    assert not medium.transmit(0, 90, 1, bytes.fromhex("E7E7E7E703"), b"\xff").acked
    with pytest.raises(CrazyflieError, match="no simulated Crazyflie on radio://0/10/2M"):
        medium.crazyflie_state("radio://0/10/2M")
    with pytest.raises(CrazyflieError, match="unknown control operation"):
        medium.control("fly_to_the_moon")
    with pytest.raises(CrazyflieError, match="already answers"):
        medium.add_crazyflie(URI1)
    medium.set_rssi(URI2, -80.0, 0.0)
    for _ in range(40):   # past the boot text of the power cycle above, to an empty ack
        r = medium.transmit(0, 80, 2, A2, b"\xff")
        if (r.payload[0] & 0xF3) == 0xF3:
            break
    assert r.payload[2] == 80 and not r.power_detector


def test_log_data_flows_from_world_ticks(served):
    world, server, medium = served
    cf = server.crazyflie("cf1")
    world.vehicle("cf1").readings["pm.vbat"] = 4.0
    vbat = [e.full_name for e in cf.logs.entries].index("pm.vbat")
    request(medium, A1, b"\x5d\x06\x01" + struct.pack("<BH", 7, vbat))
    request(medium, A1, b"\x5d\x03\x01\x02")     # 20 ms
    world.advance(0.1)
    data = []
    for _ in range(12):
        r = medium.transmit(0, 80, 2, A1, b"\xff")
        if r.payload and (r.payload[0] & 0xF3) == 0x52:
            data.append(r.payload)
    assert len(data) == 5
    assert [int.from_bytes(p[2:5], "little") for p in data] == [20, 40, 60, 80, 100]
    assert all(p[5:] == struct.pack("<f", 4.0) for p in data)


def test_concurrent_clients_and_reconnect(served):
    world, server, medium = served
    errors = []

    def client():
        m = RemoteMedium(server.host, server.port)
        try:
            for _ in range(300):
                if not m.transmit(0, 80, 2, A1, b"\xff").acked:
                    errors.append("unacked")
        except Exception as e:  # collected for the assertion below
            errors.append(repr(e))
        finally:
            m.close()
    threads = [threading.Thread(target=client) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert errors == []
    # the server restarts on the same port: the client reconnects on its own
    port = server.port
    server.stop()
    with pytest.raises(WorldNotRunning):
        medium.dongle_count()
    server2 = WorldServer(world, port=port)
    server2.start()
    try:
        assert medium.dongle_count() == 1
    finally:
        server2.stop()


def test_vehicle_config(tmp_path):
    good = tmp_path / "v.yaml"
    good.write_text("vehicles:\n  - uri: radio://0/80/2M/E7E7E7E701\n    name: a\n    position: [0, 1, 0]\n"
                    "    firmware: '2016.02'\n")
    assert load_vehicle_config(str(good)) == [{"uri": URI1, "name": "a", "position": [0, 1, 0],
                                               "firmware": "2016.02"}]
    bad = tmp_path / "b.yaml"
    bad.write_text("- name: x\n")
    with pytest.raises(ValueError, match="needs at least a 'uri'"):
        load_vehicle_config(str(bad))
    bad.write_text("- uri: radio://0/80/2M\n  colour: red\n")
    with pytest.raises(ValueError, match="unknown keys"):
        load_vehicle_config(str(bad))
    bad.write_text("- uri: radio://0/80/2M\n  platform: quad\n")
    with pytest.raises(ValueError, match="platform must be one of cf2, brushless"):
        load_vehicle_config(str(bad))
    good.write_text("- uri: radio://0/80/2M/E7E7E7E701\n  platform: brushless\n")
    assert load_vehicle_config(str(good))[0]["platform"] == "brushless"


def test_cli_refuses_bad_arguments(capsys):
    assert main([]) == 2
    assert "no Crazyflies to simulate" in capsys.readouterr().err
    assert main(["--uri", "radio://0/300/2M"]) == 2
    assert "300" in capsys.readouterr().err
    assert main(["--uri", URI1, "--address", "10.1.1.1:5"]) == 2
    assert "loopback" in capsys.readouterr().err


_LAUNCHER = """
import sys, types
from support import sim_doubles
mod = types.ModuleType("crazyflie_driver.sim.room.world")
class World(sim_doubles.FakeWorld):
    def __init__(self, speed=1.0, seed=None):
        super().__init__()
mod.World = World
sys.modules["crazyflie_driver.sim.room.world"] = mod
from crazyflie_driver.sim.world_server import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_cli_serves_and_stops_cleanly_on_signals(sig):
    proc = subprocess.Popen([sys.executable, "-c", _LAUNCHER, "--uri", URI1, "--uri", URI2, "--address", "127.0.0.1:0",
                             "--udp", "--dongles", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        deadline = time.time() + 10
        while time.time() < deadline:
            line = proc.stderr.readline()
            lines.append(line)
            if "world served on" in line:
                break
        assert any("world served on 127.0.0.1:" in ln for ln in lines), lines
        assert any("udp://127.0.0.1:" in ln for ln in lines)
        port = int(lines[-1].split("127.0.0.1:")[1].split()[0])
        m = RemoteMedium("127.0.0.1", port)
        assert m.dongle_count() == 2 and m.transmit(0, 80, 2, A2, b"\xff").acked
        m.close()
        proc.send_signal(sig)
        assert proc.wait(timeout=10) == 0
        assert "stopped" in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_shipped_example_vehicle_config_loads():
    """The example file in crazyflie_driver/config is valid: URIs parse, positions are 3-vectors."""
    from crazyflie_driver.crtp.uri import parse_uri
    from crazyflie_driver.sim.world_server import load_vehicle_config
    path = str(TEST.parent / "config" / "sim_vehicles.yaml")
    vehicles = load_vehicle_config(path)
    assert [v["name"] for v in vehicles] == ["crazyflie1", "crazyflie2", "crazyflie3"]
    assert [parse_uri(v["uri"]).index for v in vehicles] == [0, 0, 1]
    assert all(len(v["position"]) == 3 for v in vehicles)
    assert vehicles[2]["firmware"] == "2016.02"


def test_plug_change_is_stamped_with_world_time(served):
    """A tool that takes a while to start still lets a test time the reaction from the plug itself."""
    world, server, medium = served
    assert medium.control("dongle_faults", dongle=1)[0]["plug_changed_at"] is None
    world.time = 3.25
    assert medium.control("set_dongle_faults", dongle=1, unplugged=True)["plug_changed_at"] == 3.25
    world.time = 4.5
    medium.set_dongle_faults(1, packet_loss=10.0)            # not a change of plug: the stamp stays
    medium.set_dongle_faults(1, unplugged=True)
    assert medium.control("dongle_faults", dongle=1)[0]["plug_changed_at"] == 3.25
    world.time = 5.0
    medium.control("clear_faults", dongle=1)                  # plugs it back in
    row = medium.control("dongle_faults", dongle=1)[0]
    assert row["plug_changed_at"] == 5.0 and not row["unplugged"]
    assert medium.control("dongle_faults", dongle=0)[0]["plug_changed_at"] is None


def test_the_world_says_which_crazyradio_model_is_plugged_in():
    server = WorldServer(FakeWorld(), dongles=1, port=0, dongle_model="2.0")
    host, port = server.start()
    medium = RemoteMedium(host, port)
    try:
        assert medium.dongle_model() == "2.0"
    finally:
        medium.close()
        server.stop()
    with pytest.raises(ValueError, match="unknown Crazyradio model 'PA2'"):
        WorldServer(FakeWorld(), dongles=1, port=0, dongle_model="PA2")


def test_a_crazyflie_on_a_usb_cable_through_the_world_server(served):
    world, server, medium = served
    assert medium.usb_count() == 0
    assert server.plug_usb("cf1") == 0
    assert medium.usb_count() == 1
    assert medium.usb_send(0, b"\xfc\x2a")                       # port 15 ch 0: an echo, straight to the STM
    assert medium.usb_receive(0) == b"\xfc\x2a"
    assert medium.usb_receive(0) is None
    with pytest.raises(CrazyflieError, match="no simulated Crazyflie usb://1"):
        medium.usb_receive(1)
    with pytest.raises(ValueError, match="no simulated Crazyflie of that name.*cf1, cf2"):
        server.plug_usb("cf9")


def test_the_stack_connects_to_usb_0_of_a_world_in_another_process(served):
    from crazyflie_driver.protocol.crazyflie import Crazyflie
    from crazyflie_driver.radio.shared_radio import RadioManager
    from crazyflie_driver.sim.air.dongle_timing import DongleTiming
    from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend

    world, server, medium = served
    server.plug_usb(URI2)                                        # the 2016 firmware, by its URI
    backend = FakeUsbBackend(medium, dongles=1, timing=DongleTiming.instant(), usb_crazyflies=medium.usb_count())
    cf = Crazyflie("usb://0", radio_manager=RadioManager(backend), timeout=2.0)
    cf.connect()
    try:
        assert cf.protocol_version == server.crazyflie(URI2).profile.protocol_version
        assert backend.cables[0].bulk_in > 0 and backend.dongles[0].bulk_out == 0
    finally:
        cf.close()
    assert not backend.cables[0].crtp_to_usb


def test_each_dongle_has_its_own_connection_so_radios_transmit_at_once(served):
    """Real Crazyradios transmit at the same time, each on its own USB device. The fake dongles of one
    process each have their own connection to the world, so a packet of one never waits for another
    dongle's round trip: counted, a packet of dongle 0 and one of dongle 1 are in the world's medium
    at once (the world lets neither go before both are in). On one shared connection the second waited
    for the first, which waited for the second: a burst on each of three radios cost the sum of all
    their round trips."""
    world, server, medium = served
    inner = server.medium.transmit
    both_in = threading.Barrier(2, timeout=5.0)
    count = threading.Lock()
    inside, most = [0], [0]

    def gated(*args, **kwargs):
        with count:
            inside[0] += 1
            most[0] = max(most[0], inside[0])
        try:
            both_in.wait()
            return inner(*args, **kwargs)
        finally:
            with count:
                inside[0] -= 1

    server.medium.transmit = gated
    replies = {}

    def send(dongle, address):
        try:
            replies[dongle] = medium.transmit(dongle, 80, 2, address, b"\xff").acked
        except CrazyflieError as e:
            replies[dongle] = repr(e)

    threads = [threading.Thread(target=send, args=(0, A1)), threading.Thread(target=send, args=(1, A2))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10.0)
    assert most[0] == 2
    assert replies == {0: True, 1: True}
