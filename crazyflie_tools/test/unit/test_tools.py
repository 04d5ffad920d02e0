"""The command-line tools against simulated Crazyflies in this process: output formats,
exit codes and the one-line errors (no traceback)."""
from __future__ import annotations

import errno
import threading
import time

import pytest
import usb.core

from crazyflie_driver import usb_choice as usb_backend
from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from crazyflie_tools import (
    battery,
    console,
    flash,
    get_param,
    list_log_variables,
    list_params,
    reboot,
    scan,
    set_param,
    version,
)

URI1 = "radio://0/80/2M/E7E7E7E701"
URI2 = "radio://0/80/2M/E7E7E7E702"


class ClockVehicle:
    """A vehicle that stands still on a real clock (enough for the protocol side)."""

    name = "cf"

    def __init__(self, vbat: float = 3.87) -> None:
        self.t0 = time.monotonic()
        self.vbat = vbat
        self.written = {}

    def time(self) -> float:
        return time.monotonic() - self.t0

    def read(self, name: str) -> float:
        return self.vbat if name == "pm.vbat" else 0.0

    def param_defaults(self):
        return {}

    def write_param(self, name, value):
        self.written[name] = value

    def set_rpyt(self, *args):
        pass

    def emergency_stop(self):
        pass


class Sim:
    def __init__(self, backend_class=FakeUsbBackend, dongles: int = 1) -> None:
        self.medium = LocalMedium(dongles=max(dongles, 1), seed=2)
        self.backend = backend_class(self.medium, dongles=dongles, timing=DongleTiming.instant())
        self.firmwares = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, daemon=True)
        self._thread.start()

    def add(self, uri: str, firmware: str = "current", vbat: float = 3.87):
        u = parse_uri(uri)
        fw = SimulatedCrazyflie(u.address, ClockVehicle(vbat), firmware=firmware)
        self.medium.add_crazyflie(fw, u.channel, u.datarate)
        self.firmwares.append(fw)
        return fw

    def _tick(self) -> None:
        while not self._stop.wait(0.002):
            for fw in list(self.firmwares):
                fw.tick(fw.now())

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(1.0)


@pytest.fixture
def sim(monkeypatch, tmp_path):
    monkeypatch.setenv("CRAZYFLIE_TOC_CACHE", str(tmp_path / "toc"))
    s = Sim()
    with usb_backend.use_backend(s.backend):
        yield s
    s.stop()


def test_scan_lists_each_answering_uri(sim, capsys):
    sim.add(URI1)
    sim.add(URI2)
    sim.add("radio://0/5/250K/E7E7E7E701")
    assert scan.main(["--address", "E7E7E7E701"]) == 0
    dongle = "Configured Dongle with version 0.53"
    assert capsys.readouterr().out.splitlines() == [dongle, "radio://0/5/250K/E7E7E7E701", URI1]
    assert scan.main(["--address", "0xE7E7E7E702"]) == 0
    assert capsys.readouterr().out.splitlines() == [dongle, URI2]


def test_scan_lists_a_crazyflie_on_the_usb_cable_after_the_radio_ones(monkeypatch, capsys):
    s = Sim()
    try:
        on_radio = s.add(URI1)
        s.medium.plug_usb(on_radio)
        s.medium.plug_usb(s.add(URI2))
        backend = FakeUsbBackend(s.medium, dongles=1, timing=DongleTiming.instant(), usb_crazyflies=2)
        with usb_backend.use_backend(backend):
            assert scan.main(["--address", "E7E7E7E701"]) == 0
    finally:
        s.stop()
    assert capsys.readouterr().out.splitlines() == ["Configured Dongle with version 0.53", URI1, "usb://0", "usb://1"]


def test_scan_default_address_finds_nothing_here(sim, capsys):
    sim.add(URI1)
    assert scan.main([]) == 0
    captured = capsys.readouterr()
    assert captured.out == "Configured Dongle with version 0.53\n"
    assert "no Crazyflie answered at address E7E7E7E7E7" in captured.err


class ClosedPipe:
    """stdout of ``tool | head -1`` once head has exited."""

    def write(self, text):
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self):
        pass


def test_output_into_a_closed_pipe_is_quiet(sim, capsys, monkeypatch):
    sim.add(URI1)
    monkeypatch.setattr("sys.stdout", ClosedPipe())
    assert list_params.main(["--uri", URI1]) == 0
    assert capsys.readouterr().err == ""


def test_scan_bad_address(sim, capsys):
    assert scan.main(["--address", "XYZ"]) == 1
    assert "scan: error: address 'XYZ' is not up to 10 hex digits" in capsys.readouterr().err


@pytest.mark.parametrize("firmware", ["current", "2016.02"])
def test_list_params_format(sim, capsys, firmware):
    sim.add(URI1, firmware)
    assert list_params.main(["--uri", URI1]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "ring.effect (uint8_t)" in lines
    assert "cpu.flash (uint16_t, readonly)" in lines
    assert all(line.count(" (") == 1 and line.endswith(")") for line in lines)


def test_list_params_with_values(sim, capsys):
    sim.add(URI1)
    assert list_params.main(["--uri", URI1, "--values"]) == 0
    assert "ring.effect (uint8_t) = 6" in capsys.readouterr().out.splitlines()


@pytest.mark.parametrize("firmware", ["current", "2016.02"])
def test_list_log_variables_format(sim, capsys, firmware):
    sim.add(URI1, firmware)
    assert list_log_variables.main(["--uri", URI1]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "pm.vbat (float)" in lines
    assert len(lines) > 10


def test_get_and_set_param(sim, capsys):
    fw = sim.add(URI1)
    assert get_param.main(["--uri", URI1, "--name", "ring.effect"]) == 0
    assert capsys.readouterr().out == "6\n"
    assert set_param.main(["--uri", URI1, "--name", "ring.effect", "--value", "11"]) == 0
    assert capsys.readouterr().out == "ring.effect = 11\n"
    assert fw.vehicle.written["ring.effect"] == 11
    assert get_param.main(["--uri", URI1, "--name", "ring.effect"]) == 0
    assert capsys.readouterr().out == "11\n"


@pytest.mark.parametrize("argv, message", [
    (["--name", "ring.nope"], "unknown parameter 'ring.nope'"),
    (["--name", "cpu.flash", "--value", "3"], "cpu.flash is read-only"),
    (["--name", "ring.effect", "--value", "300"], "out of range 0..255"),
    (["--name", "ring.effect", "--value", "abc"], "is not an integer"),
])
def test_set_param_errors(sim, capsys, argv, message):
    sim.add(URI1)
    if "--value" not in argv:
        argv = argv + ["--value", "1"]
    assert set_param.main(["--uri", URI1] + argv) == 1
    err = capsys.readouterr().err
    assert err.startswith("setParam: error: ") and message in err
    assert "Traceback" not in err and err.count("\n") == 1


def test_get_param_unknown_name(sim, capsys):
    sim.add(URI1)
    assert get_param.main(["--uri", URI1, "--name", "nope"]) == 1
    assert "unknown parameter 'nope'" in capsys.readouterr().err


@pytest.mark.parametrize("tool", [get_param, set_param])
def test_a_name_no_crazyflie_can_have_is_refused_before_connecting(sim, capsys, tool):
    fw = sim.add(URI1)
    argv = ["--uri", URI1, "--name", "ring.eff\x00ect"] + (["--value", "1"] if tool is set_param else [])
    assert tool.main(argv) == 1
    err = capsys.readouterr().err
    assert "unknown parameter 'ring.eff\\x00ect': it holds a NUL character at position 8" in err
    assert "Traceback" not in err and err.count("\n") == 1
    assert sum(fw.state.packets_by_port.values()) == 0         # not even a connect


def test_console_prints_boot_text(sim, capsys):
    sim.add(URI1)
    assert console.main(["--uri", URI1, "--seconds", "0.2"]) == 0
    assert "is up and running!" in capsys.readouterr().out


@pytest.mark.parametrize("firmware", ["current", "2016.02"])
def test_battery(sim, capsys, firmware):
    sim.add(URI1, firmware, vbat=3.87)
    assert battery.main(["--uri", URI1]) == 0
    assert capsys.readouterr().out == "3.87 V\n"


def test_version(sim, capsys):
    sim.add(URI1)
    assert version.main(["--uri", URI1]) == 0
    lines = capsys.readouterr().out.splitlines()
    serial = sim.backend.dongles[0].serial
    assert lines[0] == "Crazyradio 0: firmware 0.53, serial %s" % serial
    assert lines[1] == "%s: protocol version 12, firmware 2026.08" % URI1


def test_absent_crazyflie(sim, capsys):
    sim.add(URI1)
    assert get_param.main(["--uri", URI2, "--name", "ring.effect", "--timeout", "0.2"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("getParam: error: %s" % URI2) and "switched on" in err
    assert "Traceback" not in err


def test_bad_uri(sim, capsys):
    assert list_params.main(["--uri", "radio://0/200/2M"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("listParams: error: bad URI:") and "channel 200" in err


def test_missing_dongle(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("CRAZYFLIE_TOC_CACHE", str(tmp_path))
    s = Sim(dongles=0)
    try:
        with usb_backend.use_backend(s.backend):
            assert list_params.main(["--uri", URI1]) == 1
            assert "no Crazyradio found" in capsys.readouterr().err
            assert scan.main([]) == 1
            assert "no Crazyradio found" in capsys.readouterr().err
            assert version.main([]) == 1
            assert "no Crazyradio found" in capsys.readouterr().err
    finally:
        s.stop()


class DeniedBackend(FakeUsbBackend):
    """A dongle the user may not open (no udev rules)."""

    def open_device(self, dev):
        raise usb.core.USBError("Access denied (insufficient permissions)", -3, errno.EACCES)


class BusyBackend(FakeUsbBackend):
    """A dongle another program holds (its interface is claimed elsewhere)."""

    def claim_interface(self, dev_handle, intf):
        raise usb.core.USBError("Resource busy", -6, errno.EBUSY)


@pytest.mark.parametrize("backend_class, runs, says, never_says", [
    pytest.param(DeniedBackend, [(list_params.main, []), (scan.main, [])],
                 ["permission denied", "plugdev", "crazyflie_driver/udev"], [], id="permission denied: udev, plugdev"),
    pytest.param(BusyBackend, [(get_param.main, ["--uri", URI1, "--name", "ring.effect"])],
                 ["in use by another program", "crazyflie_server"], ["plugdev", "permission denied", "switched on"],
                 id="in use: no udev or switched-on hints"),
])
def test_a_dongle_that_cannot_be_opened_says_why_in_one_line(backend_class, runs, says, never_says, monkeypatch,
                                                             tmp_path, capsys):
    monkeypatch.setenv("CRAZYFLIE_TOC_CACHE", str(tmp_path))
    s = Sim(backend_class)
    try:
        with usb_backend.use_backend(s.backend):
            for tool, args in runs:
                assert tool(args) == 1
                err = capsys.readouterr().err
                assert all(w in err for w in says) and not any(w in err for w in never_says), err
                assert err.count("\n") == 1, err
    finally:
        s.stop()


class Crowded:
    """The air with another program's Crazyradio on it: after each packet of this process's dongle,
    the other program makes one round trip (as a server polling the same Crazyflie does)."""

    def __init__(self, medium) -> None:
        self.medium = medium
        self.other = None

    def transmit(self, dongle, *args, **kwargs):
        reply = self.medium.transmit(dongle, *args, **kwargs)
        if dongle == 0 and self.other is not None:
            self.other()
        return reply

    def __getattr__(self, name):
        return getattr(self.medium, name)


def test_another_program_on_the_same_crazyflie_is_named_not_switched_on(monkeypatch, tmp_path, capsys):
    """crazyflie_server talks to the Crazyflie through its own dongle: the tool's packets are all
    acked, but the answers to its requests go to the other program."""
    from crazyflie_driver.radio.link import open_link
    from crazyflie_driver.radio.shared_radio import RadioManager

    monkeypatch.setenv("CRAZYFLIE_TOC_CACHE", str(tmp_path))
    s = Sim(dongles=2)
    try:
        s.add(URI1)
        air = Crowded(s.medium)
        tool_backend = FakeUsbBackend(air, dongles=1, timing=DongleTiming.instant())
        server_backend = FakeUsbBackend(s.medium, dongles=1, timing=DongleTiming.instant(), first_id=1)
        other = open_link(URI1, RadioManager(backend=server_backend))
        air.other = other.poll
        with usb_backend.use_backend(tool_backend):
            assert get_param.main(["--uri", URI1, "--name", "ring.effect", "--timeout", "0.3"]) == 1
        err = capsys.readouterr().err
        assert "another program" in err and "crazyflie_server" in err and "acknowledged" in err
        assert "switched on" not in err and "Traceback" not in err
        air.other = None
        other.close()
    finally:
        s.stop()


def test_reboot_and_power_reach_the_radio_chip(sim, capsys):
    fw = sim.add(URI1)
    assert reboot.main(["--uri", URI1]) == 0
    assert capsys.readouterr().out == "%s: rebooted into its firmware\n" % URI1
    assert fw.state.reboots == 1 and fw.powered
    assert reboot.main(["--uri", URI1, "--power", "stm-off"]) == 0
    assert not fw.powered and fw.radio_on
    assert reboot.main(["--uri", URI1, "--power", "stm-on"]) == 0      # reached with the STM32 off
    assert fw.powered
    assert reboot.main(["--uri", URI1, "--bootloader"]) == 0
    assert fw.in_bootloader
    assert reboot.main(["--uri", URI1]) == 0
    assert not fw.in_bootloader and fw.state.reboots == 4
    capsys.readouterr()
    assert reboot.main(["--uri", URI1, "--power", "all-off"]) == 0
    assert not fw.radio_on
    assert reboot.main(["--uri", URI1]) == 1                          # nothing on the air any more
    assert "switched on" in capsys.readouterr().err


def _stm32_image(version: bytes) -> bytes:
    head = (0x20020000).to_bytes(4, "little") + (0x08004201).to_bytes(4, "little")
    return head + bytes((i * 13) & 0xFF for i in range(11 * 1024)) + version + b"\x00"


def test_flash_writes_through_the_radio_and_the_crazyflie_connects_with_the_new_version(sim, capsys, tmp_path):
    fw = sim.add(URI1)
    image = tmp_path / "cf2.bin"
    image.write_bytes(_stm32_image(b"2026.11"))
    assert flash.main(["--uri", URI1, "--target", "stm32", "--filename", str(image)]) == 0
    assert capsys.readouterr().out == ("%s: stm32: wrote %d bytes (12 pages from page 16), verified, rebooted "
                                       "into the firmware\n" % (URI1, image.stat().st_size))
    assert not fw.in_bootloader and fw.powered
    assert version.main(["--uri", URI1]) == 0
    assert capsys.readouterr().out.splitlines()[1] == "%s: protocol version 12, firmware 2026.11" % URI1
    assert flash.main(["--uri", URI1, "--target", "stm32", "--filename", str(image), "--mode", "verifyOnly"]) == 0
    assert "the flash holds the image" in capsys.readouterr().out
    assert get_param.main(["--uri", URI1, "--name", "deck.bcFlow2"]) == 0             # connects and reads again


def test_flash_refuses_a_file_that_is_not_a_firmware_and_writes_nothing(sim, capsys, tmp_path):
    fw = sim.add(URI1)
    text = tmp_path / "notes.txt"
    text.write_bytes(b"hello, this is not firmware\n" * 100)
    assert flash.main(["--uri", URI1, "--target", "stm32", "--filename", str(text)]) == 1
    assert "does not start like a stm32 firmware" in capsys.readouterr().err
    assert not fw.bootloader.written[0xFF] and not fw.in_bootloader        # back in its old firmware
    assert flash.main(["--uri", URI1, "--target", "nrf51", "--filename", str(tmp_path / "missing.bin")]) == 1
    assert "cannot read" in capsys.readouterr().err
