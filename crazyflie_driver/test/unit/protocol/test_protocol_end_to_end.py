"""The protocol layer over the real stack in one process: RadioManager -> Crazyradio ->
fake USB dongle -> LocalMedium -> simulated Crazyflie firmware (both generations).

The world is replaced by a stub vehicle with a hand-driven clock, so log timing is exact.
"""
from __future__ import annotations

import pytest

from crazyflie_driver.errors import LinkTimeout, LogConfigError, ReadOnlyParam, UnknownName
from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie

URI1 = "radio://0/80/2M/E7E7E7E701"
URI2 = "radio://0/80/2M/E7E7E7E702"


class StubVehicle:
    """Just enough of the vehicle contract: readings, param writes, setpoints, a clock."""

    def __init__(self, name: str, vbat: float) -> None:
        self.name = name
        self.now = 0.0
        self.readings = {"pm.vbat": vbat, "acc.z": 1.0, "stabilizer.roll": -1.5}
        self.written = {}
        self.setpoints = []
        self.stopped = False

    def time(self) -> float:
        return self.now

    def read(self, name: str) -> float:
        return self.readings.get(name, 0.0)

    def param_defaults(self):
        return {}

    def write_param(self, name, value):
        self.written[name] = value

    def set_rpyt(self, roll, pitch, yaw, thrust):
        self.setpoints.append((roll, pitch, yaw, thrust))

    def emergency_stop(self):
        self.stopped = True


class Air:
    """A medium with simulated Crazyflies on it and a radio manager on a fake dongle."""

    def __init__(self):
        self.medium = LocalMedium(dongles=1, seed=1)
        self.backend = FakeUsbBackend(self.medium, dongles=1, timing=DongleTiming.instant())
        self.manager = RadioManager(backend=self.backend)
        self.firmwares = {}

    def add(self, uri: str, firmware: str = "current", vbat: float = 3.9):
        from crazyflie_driver.crtp.uri import parse_uri
        u = parse_uri(uri)
        vehicle = StubVehicle(uri, vbat)
        fw = SimulatedCrazyflie(u.address, vehicle, firmware=firmware)
        self.medium.add_crazyflie(fw, u.channel, u.datarate)
        self.firmwares[uri] = fw
        return fw, vehicle

    def advance(self, t: float) -> None:
        for fw in self.firmwares.values():
            fw.vehicle.now = t
            fw.tick(t)


@pytest.fixture
def air():
    return Air()


def connect(air, uri, tmp_path, timeout=1.0):
    cf = Crazyflie(uri, radio_manager=air.manager, cache_dir=str(tmp_path / "toc"), timeout=timeout)
    cf.connect()
    return cf


@pytest.mark.parametrize("generation, version", [("current", 12), ("2016.02", 2)])
def test_connect_tocs_params(air, tmp_path, generation, version):
    fw, vehicle = air.add(URI1, generation)
    cf = connect(air, URI1, tmp_path)
    try:
        assert cf.protocol_version == version
        params = cf.params.fetch_toc()
        logs = cf.log.fetch_toc()
        names = {e.full_name: e for e in params}
        assert names["ring.effect"].ctype == "uint8_t" and not names["ring.effect"].readonly
        assert names["cpu.flash"].readonly
        assert "pm.vbat" in {e.full_name for e in logs}
        values = cf.params.read_all()
        assert values["ring.effect"] == 6 and values["cpu.flash"] == 1024
        assert cf.params.set("ring.effect", "3") == 3
        assert cf.params.get("ring.effect") == 3
        assert vehicle.written.get("ring.effect") == 3
        with pytest.raises(ReadOnlyParam):
            cf.params.set("cpu.flash", 1)
        with pytest.raises(UnknownName, match="ring.nope"):
            cf.params.get("ring.nope")
    finally:
        cf.close()


@pytest.mark.parametrize("generation", ["current", "2016.02"])
def test_log_block_arrives_at_its_period(air, tmp_path, generation):
    fw, vehicle = air.add(URI1, generation)
    cf = connect(air, URI1, tmp_path)
    try:
        cf.log.reset()
        got = []
        block = cf.log.create_block(["pm.vbat", "acc.z"], 100, lambda ts, v: got.append((ts, v)))
        for step in range(1, 101):          # one second of firmware time in 10 ms steps
            air.advance(step * 0.01)
            cf.send_keepalive()
        for _ in range(5):
            cf.send_keepalive()
        assert 9 <= len(got) <= 11
        stamps = [ts for ts, _ in got]
        assert all(b - a == 100 for a, b in zip(stamps, stamps[1:]))
        assert got[0][1] == [pytest.approx(3.9), pytest.approx(1.0)]
        block.stop()
        n = len(got)
        for step in range(101, 131):
            air.advance(step * 0.01)
            cf.send_keepalive()
        assert len(got) == n
        too_big = ["pm.vbat"] * 7
        with pytest.raises(LogConfigError, match="28 bytes"):
            cf.log.create_block(too_big, 100, lambda ts, v: None)
    finally:
        cf.close()


def test_two_crazyflies_share_one_dongle(air, tmp_path):
    fw1, v1 = air.add(URI1, "current", vbat=3.7)
    fw2, v2 = air.add(URI2, "2016.02", vbat=4.1)
    cf1 = connect(air, URI1, tmp_path)
    cf2 = connect(air, URI2, tmp_path)
    try:
        assert air.manager.users(0) == 2
        assert (cf1.protocol_version, cf2.protocol_version) == (12, 2)
        got1, got2 = [], []
        cf1.log.create_block(["pm.vbat"], 50, lambda ts, v: got1.append(v[0]))
        cf2.log.create_block(["pm.vbat"], 50, lambda ts, v: got2.append(v[0]))
        cf1.params.set("ring.effect", 1)
        cf2.params.set("ring.effect", 2)
        for step in range(1, 31):
            air.advance(step * 0.01)
            cf1.send_keepalive()
            cf2.send_keepalive()
        assert got1 and got2
        assert got1 == [pytest.approx(3.7)] * len(got1)
        assert got2 == [pytest.approx(4.1)] * len(got2)
        assert v1.written["ring.effect"] == 1 and v2.written["ring.effect"] == 2
        cf1.send_setpoint(1.0, 2.0, 3.0, 0)
        cf2.send_setpoint(-1.0, 0.0, 0.0, 0)
        assert v1.setpoints[-1][0] == 1.0 and v2.setpoints[-1][0] == -1.0
    finally:
        cf1.close()
        cf2.close()
    assert air.manager.users(0) == 0


def test_second_connect_uses_the_toc_cache(air, tmp_path):
    fw, vehicle = air.add(URI1)
    cf = connect(air, URI1, tmp_path)
    first = cf.params.fetch_toc()
    cf.log.fetch_toc()
    cf.close()
    before = fw.state.packets_by_port.get(2, 0)
    cf2 = connect(air, URI1, tmp_path)
    try:
        assert cf2.params.fetch_toc() == first
        assert fw.state.packets_by_port.get(2, 0) - before == 1   # the info request only
    finally:
        cf2.close()


def test_absent_crazyflie_times_out_naming_the_uri(air, tmp_path):
    air.add(URI1)
    cf = Crazyflie("radio://0/80/2M/E7E7E7E7AA", radio_manager=air.manager,
                   cache_dir=str(tmp_path), timeout=0.3)
    with pytest.raises(LinkTimeout, match="radio://0/80/2M/E7E7E7E7AA"):
        cf.connect()
    assert air.manager.users(0) == 0


def test_emergency_stop_reaches_the_vehicle(air, tmp_path):
    fw, vehicle = air.add(URI1)
    cf = connect(air, URI1, tmp_path)
    try:
        cf.emergency_stop()
        assert vehicle.stopped and fw.state.emergency
    finally:
        cf.close()


def test_console_boot_text(air, tmp_path):
    """The boot text waits in the firmware's queue and arrives right after connect."""
    fw, vehicle = air.add(URI1)
    cf = connect(air, URI1, tmp_path)
    try:
        lines = []
        cf.console.on_line(lines.append)
        for _ in range(40):
            cf.send_keepalive()
        assert "is up and running!\n" in cf.console.text()
        fw.console.write("TEST: a line\n")
        for _ in range(3):
            cf.send_keepalive()
        assert lines[-1] == "TEST: a line"
    finally:
        cf.close()


def test_ids_past_255_read_write_and_log_on_the_wire(air, tmp_path):
    """The real-size tables through the host library: 16-bit ids for a parameter and a log variable past 255."""
    fw, vehicle = air.add(URI1, "current")
    vehicle.readings["stateEstimate.qw"] = 0.875
    cf = connect(air, URI1, tmp_path)
    try:
        params = {e.full_name: e for e in cf.params.fetch_toc()}
        assert len(params) == len(fw.params.entries) > 380
        far = params["posCtlPid.zKp"]
        assert far.ident == fw.params.ident("posCtlPid.zKp") > 255
        values = cf.params.read_all()
        assert len(values) == len(params)
        for n in ("posCtlPid.zKp", "cpu.id0", "pm.lowVoltage"):
            assert values[n] == pytest.approx(fw.params.value(n)), n
        assert cf.params.set("posCtlPid.zKp", 3.25) == 3.25
        assert vehicle.written["posCtlPid.zKp"] == 3.25 and fw.params.value("posCtlPid.zKp") == 3.25
        assert cf.params.get("posCtlPid.zKp") == 3.25
        logs = {e.full_name: e for e in cf.log.fetch_toc()}
        assert len(logs) == len(fw.logs.entries) > 580 and logs["stateEstimate.qw"].ident > 255
        cf.log.reset()
        got = []
        cf.log.create_block(["stateEstimate.qw", "pm.vbat"], 100, lambda ts, v: got.append(v))
        (block,) = fw.logs.blocks.values()     # the firmware resolved the 16-bit ids the host sent
        assert [fw.logs.entries[i].full_name for i, _ in block.ops] == ["stateEstimate.qw", "pm.vbat"]
        for step in range(1, 31):
            air.advance(step * 0.01)
            cf.send_keepalive()
        assert got and got[0] == [pytest.approx(0.875), pytest.approx(3.9)]
    finally:
        cf.close()


def test_crazyflies_connecting_together_download_a_shared_table_once(air, tmp_path):
    """Same build, same CRC: while one Crazyflie downloads a table the other waits and reads the cache."""
    import threading
    fws = [air.add(URI1, "current")[0], air.add(URI2, "current")[0]]
    cfs = [Crazyflie(u, radio_manager=air.manager, cache_dir=str(tmp_path / "toc")) for u in (URI1, URI2)]
    errors = []

    def connect_and_fetch(cf):
        try:
            cf.connect()
            cf.params.fetch_toc()
        except Exception as e:      # reported below
            errors.append(e)
    threads = [threading.Thread(target=connect_and_fetch, args=(cf,)) for cf in cfs]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(30.0)
        assert errors == [] and all(len(cf.params.toc) == len(fws[0].params.entries) for cf in cfs)
        asked = sorted(fw.state.packets_by_port.get(2, 0) for fw in fws)
        assert asked[1] > len(fws[0].params.entries) and asked[0] < 5, asked
    finally:
        for cf in cfs:
            cf.close()
