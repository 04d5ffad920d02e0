"""listMemories, config, comCheck and log against simulated Crazyflies in this process: what they
print, what reaches the simulated firmware, and their one-line errors."""
from __future__ import annotations

import pytest
from test_tools import URI1, URI2, ClockVehicle, sim  # noqa: F401  (sim is a fixture)

from crazyflie_driver.crtp import config_block as cb
from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from crazyflie_tools import com_check, config, list_memories, log


def add_with_decks(sim, uri, decks):  # noqa: F811
    u = parse_uri(uri)
    fw = SimulatedCrazyflie(u.address, ClockVehicle(), decks=decks)
    sim.medium.add_crazyflie(fw, u.channel, u.datarate)
    sim.firmwares.append(fw)
    return fw


def test_list_memories_names_each_memory_and_the_decks(sim, capsys):  # noqa: F811
    add_with_decks(sim, URI1, ("bcZRanger2",))
    assert list_memories.main(["--uri", URI1]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("0: 1-wire, 112 bytes, serial 2d010e") and \
        lines[0].endswith("deck bcZRanger2 rev A (vid 0xBC, pid 0x0E)")
    assert lines[1:] == ["1: EEPROM, 8192 bytes, serial 0000000000000000",
                         "2: trajectory, 4096 bytes, serial 0000000000000000"]


def test_config_reads_writes_and_takes_effect_after_reboot(sim, capsys):  # noqa: F811
    fw = sim.add(URI1)
    assert config.main(["--uri", URI1]) == 0
    assert capsys.readouterr().out == "channel 80, data rate 2M, address E7E7E7E701, pitch trim 0, roll trim 0\n"
    assert config.main(["--uri", URI1, "--channel", "90", "--address", "E7E7E7E7A0", "--roll-trim", "0.5"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "channel 90, data rate 2M, address E7E7E7E7A0, pitch trim 0, roll trim 0.5"
    assert "next boot" in out[1]
    assert fw.config_block() == cb.ConfigBlock(90, 2, 0.0, 0.5, 0xE7E7E7E7A0)
    assert sim.medium.crazyflie(80, 2, b"\xe7\xe7\xe7\xe7\x01") is fw          # not before the reboot
    fw.reboot()
    assert sim.medium.crazyflie(90, 2, b"\xe7\xe7\xe7\xe7\xa0") is fw


@pytest.mark.parametrize("argv,says", [
    (["--channel", "126"], "channel 126 is out of range"),
    (["--datarate", "3M"], "data rate '3M' is unknown"),
    (["--address", "XYZ"], "10 hex digits"),
])
def test_config_refuses_bad_values_in_one_line_and_writes_nothing(sim, capsys, argv, says):  # noqa: F811
    fw = sim.add(URI1)
    before = bytes(fw.eeprom.data[:cb.SIZE])
    assert config.main(["--uri", URI1] + argv) == 1
    err = capsys.readouterr().err
    assert err.startswith("config: error: ") and says in err and "Traceback" not in err
    assert bytes(fw.eeprom.data[:cb.SIZE]) == before


def test_com_check_counts_echoes_and_round_trips(sim, capsys):  # noqa: F811
    fw = sim.add(URI1)
    assert com_check.main(["--uri", URI1, "--count", "20", "--size", "30"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "echo: 20 sent, 20 answered, 0 lost (0.0 %)"
    assert out[1].startswith("round trip: min ") and out[2].startswith("radio: ")
    assert fw.state.packets_by_port[15] >= 20


def test_com_check_on_an_absent_crazyflie_fails_in_one_line(sim, capsys):  # noqa: F811
    sim.add(URI1)
    assert com_check.main(["--uri", URI2, "--timeout", "0.2"]) == 1
    assert capsys.readouterr().err.startswith("comCheck: error: ")


def test_log_streams_samples_of_the_named_variables(sim, capsys):  # noqa: F811
    sim.add(URI1, vbat=3.91)
    assert log.main(["--uri", URI1, "--variables", "pm.vbat", "--period-ms", "20", "--seconds", "0.5"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) >= 5 and all(line.split()[1] == "pm.vbat=3.91" for line in lines)
    stamps = [int(line.split()[0]) for line in lines]
    assert stamps == sorted(stamps)


def test_log_unknown_variable_is_one_line(sim, capsys):  # noqa: F811
    sim.add(URI1)
    assert log.main(["--uri", URI1, "--variables", "pm.nope", "--seconds", "0"]) == 1
    assert capsys.readouterr().err.startswith("log: error: ")
