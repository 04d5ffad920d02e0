"""The real firmware's variable tables: loader, Crazyflie 2.1 build selection, the tables built from it."""
from __future__ import annotations

import pytest

from crazyflie_driver.errors import FirmwareTableError
from crazyflie_driver.sim.crtp import firmware_toc as F
from crazyflie_driver.sim.crtp import tables as T

HEADER = "kind\tgroup\tname\ttype_and_flags\tmacro\tsource"


def rows(*lines):
    return F.parse_rows(["# comment", HEADER] + list(lines))


def test_parse_types_flags_and_macros():
    got = rows("param\tpm\tlowVoltage\tPARAM_FLOAT|PARAM_PERSISTENT\tplain\tsrc/hal/src/pm_stm32f4.c",
               "param\tcpu\tid0\tPARAM_UINT32|PARAM_RONLY\tcore\tsrc/modules/src/system.c",
               "log\tpm\tstate\tLOG_INT8\tcore\tsrc/hal/src/pm_stm32f4.c")
    assert [(r.kind, r.group, r.name, r.ctype, r.flags, r.macro) for r in got] == [
        ("param", "pm", "lowVoltage", "float", ("PARAM_PERSISTENT",), "plain"),
        ("param", "cpu", "id0", "uint32_t", ("PARAM_RONLY",), "core"),
        ("log", "pm", "state", "int8_t", (), "core")]
    p = T.real_params(got, {"pm.lowVoltage": 3.2})
    assert [(e.full_name, e.default, e.readonly, e.persistent, e.core) for e in p] == [
        ("pm.lowVoltage", 3.2, False, True, False), ("cpu.id0", 0, True, False, True)]
    assert p[0].type_byte(T.GEN_CURRENT) == 0x16 and p[1].type_byte(T.GEN_CURRENT) == 0x6A


@pytest.mark.parametrize("lines,fix", [
    ([HEADER, "param\tpm\tx\tPARAM_DOUBLE\tplain\ts.c"], "unknown kind/type"),
    ([HEADER, "log\tpm\tx\tLOG_FLOAT\tplain"], "columns"),
    (["kind\tgroup"], "header"),
    (["# only a comment"], "no header"),
])
def test_bad_table_names_the_line_and_the_fix(lines, fix):
    with pytest.raises(FirmwareTableError, match=fix):
        F.parse_rows(lines, "t.tsv")


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(FirmwareTableError, match="reinstall"):
        F.load(str(tmp_path / "none.tsv"))


def test_cf21_build_leaves_out_debug_and_other_platforms_and_keeps_the_first_of_a_name():
    got = rows("log\tlighthouse\twidth0\tLOG_UINT16\tdebug\tsrc/modules/src/lighthouse/lighthouse_core.c",
               "param\tflapper\tmotBiasRoll\tPARAM_INT8\tplain\tsrc/modules/src/power_distribution_flapper.c",
               "log\tloadcell\trawWeight\tLOG_INT32\tplain\tsrc/deck/drivers/src/loadcell.c",
               "log\tloadcell\trawWeight\tLOG_INT32\tplain\tsrc/deck/drivers/src/loadcell_nau7802.c")
    kept = [r for r in got if F.in_cf21_build(r)]
    assert [r.name for r in kept] == ["rawWeight", "rawWeight"]
    assert [e.full_name for e in T.real_logs(kept)] == ["loadcell.rawWeight"]


def test_shipped_table_is_real_size_with_ids_past_255():
    all_rows = F.load()
    assert sum(r.kind == "param" for r in all_rows) > 380 and sum(r.kind == "log" for r in all_rows) > 580
    params, logs = T.select(T.PARAM_TABLE, T.GEN_CURRENT), T.select(T.LOG_TABLE, T.GEN_CURRENT)
    assert len(params) > 255 and len(logs) > 255
    T.check_names(params)
    T.check_names(logs)
    names = {e.full_name for e in params}
    assert len(names) == len(params)
    # flags as the source declares them, the generated version parameters, known defaults
    by = {e.full_name: e for e in params}
    assert by["pid_rate.roll_kp"].persistent and not by["pid_rate.roll_kp"].core
    assert by["cpu.id0"].readonly and by["cpu.id0"].core
    assert by["firmware.revision0"].readonly and by["firmware.revision0"].default == 0x2A18FC29
    assert by["pid_rate.roll_kp"].default == 250.0 and by["pm.lowVoltage"].default == 3.2
    assert by["colAv.vorIters"].default == 0


def test_2016_keeps_its_small_v1_table():
    params, logs = T.select(T.PARAM_TABLE, T.GEN_2016), T.select(T.LOG_TABLE, T.GEN_2016)
    assert len(params) < 256 and len(logs) < 256
    assert "flightmode.althold" in {e.full_name for e in params}
    assert "mag_raw.x" in {e.full_name for e in logs}


def test_the_variables_the_world_drives_are_in_the_current_table():
    """The names the simulated Crazyflie answers from its vehicle (docs/simulation.md) all exist in the real table."""
    logs = {e.full_name for e in T.select(T.LOG_TABLE, T.GEN_CURRENT)}
    driven = ["acc.z", "gyro.x", "mag.x", "baro.asl", "pm.vbat", "pm.state", "pm.batteryLevel", "stabilizer.roll",
              "stabilizer.thrust", "stateEstimate.x", "stateEstimate.qw", "stateEstimateZ.quat", "locSrv.x",
              "locSrvZ.tick", "ctrltarget.az", "posCtl.targetVZ", "motor.m4", "radio.rssi", "radio.isConnected",
              "radio.numRxUc", "sys.canfly", "sys.isFlying", "sys.isTumbled", "supervisor.info", "controller.roll"]
    assert [n for n in driven if n not in logs] == []


def test_crc_changes_with_the_table():
    params = T.select(T.PARAM_TABLE, T.GEN_CURRENT)
    crc = T.toc_crc(params, lambda e: e.type_byte(T.GEN_CURRENT))
    assert T.toc_crc(params[:-1], lambda e: e.type_byte(T.GEN_CURRENT)) != crc
    small = T.select(T._SMALL_PARAM_TABLE, T.GEN_CURRENT)
    assert T.toc_crc(small, lambda e: e.type_byte(T.GEN_CURRENT)) != crc
