"""Console text assembly and the setpoint / stop / emergency packets."""
from __future__ import annotations

import struct

import numpy as np
import pytest

from crazyflie_driver.crtp.firmware_limits import MAX_RATE_DEG_S
from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import LinkTimeout
from crazyflie_driver.protocol.commander import Commander, rpyt_bytes, rpyt_packet
from support.scripted_link import make_crazyflie


def test_console_joins_packets_into_lines():
    cf, link, fw = make_crazyflie(12)
    lines, chunks = [], []
    cf.console.on_line(lines.append)
    cf.console.on_text(chunks.append)
    link.push(CRTPPacket(0, 0, b"SYS: Crazyflie 2.1 is up and"),
              CRTPPacket(0, 0, b" running!\nSYS: Free heap: 1"),
              CRTPPacket(0, 0, b"2 bytes\n<F>\n\x00"))
    link.drain()
    assert lines == ["SYS: Crazyflie 2.1 is up and running!", "SYS: Free heap: 12 bytes", "<F>"]
    assert "".join(chunks) == cf.console.text()
    assert cf.console.text().endswith("12 bytes\n<F>\n")


def test_console_utf8_split_across_packets():
    cf, link, fw = make_crazyflie(12)
    text = "temp 25 \u00b0C\n".encode()
    cut = text.index(b"\xb0")  # between the two bytes of the degree sign
    link.push(CRTPPacket(0, 0, text[:cut]), CRTPPacket(0, 0, text[cut:]))
    link.drain()
    assert cf.console.text() == "temp 25 \u00b0C\n"


def test_rpyt_setpoint_bytes():
    cf, link, fw = make_crazyflie(12)
    assert cf.send_setpoint(1.5, -2.0, 30.0, 40000)
    packet = link.sent[-1]
    assert packet.to_bytes()[0] == 0x3C
    assert packet.data == struct.pack("<fffH", 1.5, -2.0, 30.0, 40000)
    assert len(packet.data) == 14


@pytest.mark.parametrize("values", [(1.5, -2.0, 30.0, 40000), (0.0, -0.0, 0.0, 0), (1e39, -1e30, 1999.5, 70000),
                                    (1, True, np.float64(-3.0), 12345.9), (0.0, 0.0, 0.0, np.int64(1234))])
def test_a_link_that_takes_raw_packets_gets_the_same_bytes(values):
    class RawLink:
        def __init__(self):
            self.sent = []

        def send_bytes(self, raw):
            self.sent.append(raw)
            return True

    link = RawLink()
    assert Commander(link).send_setpoint(*values)
    assert link.sent == [rpyt_packet(*values).to_bytes()] == [rpyt_bytes(*values)]
    cf, scripted, fw = make_crazyflie(12)           # a link with only send(CRTPPacket)
    cf.send_setpoint(*values)
    assert scripted.sent[-1] == rpyt_packet(*values)


@pytest.mark.parametrize("thrust, wire", [(-5, 0), (0, 0), (60000, 60000), (70000, 60000),
                                          (np.int64(1234), 1234), (12345.9, 12345)])
def test_thrust_clamped(thrust, wire):
    cf, link, fw = make_crazyflie(12)
    cf.send_setpoint(0, 0, 0, thrust)
    assert struct.unpack("<H", link.sent[-1].data[12:])[0] == wire


@pytest.mark.parametrize("field", range(4))
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf"), "1", None, 10 ** 400])
def test_non_finite_setpoint_is_refused(field, bad):
    cf, link, fw = make_crazyflie(12)
    before = len(link.sent)
    values = [0.0] * 4
    values[field] = bad
    with pytest.raises(ValueError, match=("roll", "pitch", "yaw rate", "thrust")[field]):
        cf.send_setpoint(*values)
    assert len(link.sent) == before


@pytest.mark.parametrize("value, wire", [(1e39, MAX_RATE_DEG_S), (-1e30, -MAX_RATE_DEG_S), (1999.5, 1999.5),
                                         (np.float64(-3.0), -3.0)])
def test_angles_and_rates_never_overflow_the_packing(value, wire):
    cf, link, fw = make_crazyflie(12)
    cf.send_setpoint(value, value, value, 0)
    assert struct.unpack("<fff", link.sent[-1].data[:12]) == (wire, wire, wire)


@pytest.mark.parametrize("version, estop, stop", [
    (12, "9d 03", "7c 00"),          # supervisor port, generic stop
    (11, "6d 03", "7c 00"),          # localization e-stop
    (2, "6d 03", "3c" + " 00" * 14),  # FW16: no port 7, zero RPYT
])
def test_emergency_stop_packets(version, estop, stop):
    cf, link, fw = make_crazyflie(version)
    link.clear()
    cf.emergency_stop()
    assert link.raw_sent() == [estop, stop]


def test_keepalive_is_a_poll_and_delivers_downlink():
    cf, link, fw = make_crazyflie(12)
    link.push(CRTPPacket(0, 0, b"hi\n"))
    n = len(link.sent)
    assert cf.send_keepalive()
    assert len(link.sent) == n  # a poll, not a CRTP packet
    assert cf.console.text() == "hi\n"


@pytest.mark.parametrize("call, step", [
    (lambda cf: cf.params.fetch_toc(), "parameter TOC info"),
    (lambda cf: cf.log.fetch_toc(), "log TOC info"),
])
def test_silent_port_times_out_naming_uri_and_step(call, step):
    cf, link, fw = make_crazyflie(12)
    fw.silent_ports.update({2, 5})
    with pytest.raises(LinkTimeout) as info:
        call(cf)
    assert str(info.value).startswith("radio://0/80/2M/E7E7E7E701: no answer to " + step)


def test_close_and_reconnect():
    cf, link, fw = make_crazyflie(12)
    cf.close()
    cf.close()
    assert link.closed == 2 and not cf.connected
    cf.connect()
    assert cf.connected and link.opened == 2


def test_a_worker_hands_each_console_line_to_its_listener_and_the_server_logs_it_as_the_original():
    from crazyflie_driver.protocol.console import rosout_line
    from crazyflie_driver.server.worker import CrazyflieWorker, WorkerConfig, WorkerListener

    class Lines(WorkerListener):
        def __init__(self) -> None:
            self.lines = []

        def on_console(self, line: str) -> None:
            self.lines.append(line)
    cf, link, fw = make_crazyflie(12)
    listener = Lines()
    CrazyflieWorker(WorkerConfig("radio://0/80/2M/E7E7E7E7E7", "cf1"), cf, listener)
    link.push(CRTPPacket(0, 0, b"SYS: Crazyflie 2.1 is up and"), CRTPPacket(0, 0, b" running!\r\nIMU: ok\n"))
    link.drain()
    assert listener.lines == ["SYS: Crazyflie 2.1 is up and running!\r", "IMU: ok"]
    assert rosout_line("cf1", listener.lines[0]) == "CF Console: [cf1] SYS: Crazyflie 2.1 is up and running!"
    assert rosout_line("cf1", "a\x1b[0mb") == "CF Console: [cf1] a\\x1b[0mb"      # no terminal escapes in the log


def test_console_line_without_newline_is_cut_at_the_bound():
    from crazyflie_driver.protocol.console import MAX_LINE_CHARS

    cf, link, fw = make_crazyflie(12)
    lines = []
    cf.console.on_line(lines.append)
    text = b"x" * (MAX_LINE_CHARS + 40)
    link.push(*(CRTPPacket(0, 0, text[i:i + 30]) for i in range(0, len(text), 30)))
    link.push(CRTPPacket(0, 0, b"y\n"))
    link.drain()
    assert lines == ["x" * MAX_LINE_CHARS, "x" * 40 + "y"]
