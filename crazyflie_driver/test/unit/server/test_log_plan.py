"""Log topics packed into firmware log blocks, and custom log blocks checked before any radio traffic."""
from __future__ import annotations

import pytest

from crazyflie_driver.errors import LogConfigError, UnknownName
from crazyflie_driver.server.log_plan import (LogBlockSpec, PlannedBlock, log_packet_rate, plan_log_blocks,
                                       validate_log_block_specs)

from support.worker_doubles import LOG_VARS


def test_log_plan_keeps_topics_whole_and_under_26_bytes():
    types = dict(LOG_VARS)
    topics = [("a", 100, ["acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y"]),   # 20 B
              ("b", 100, ["pm.vbat", "baro.temp"]),                           # 8 B
              ("c", 100, ["radio.rssi"]),                                     # 1 B
              ("d", 10, ["pos.x"])]
    blocks = plan_log_blocks(topics, types)
    for b in blocks:
        assert b.size <= 26
        assert b.size == sum(4 if types[v] == "float" else 1 for v in b.variables)
    placed = {t: (b.period_ms, b.variables[s:e]) for b in blocks for t, s, e in b.topics}
    assert placed["b"] == (100, ["pm.vbat", "baro.temp"])
    assert placed["d"] == (10, ["pos.x"])
    assert len([b for b in blocks if b.period_ms == 100]) == 2   # 29 B do not fit in one block


def test_log_plan_rejects_oversized_and_unknown():
    with pytest.raises(LogConfigError, match="27 bytes"):
        plan_log_blocks([("big", 10, ["acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z",
                                      "motor.m1", "radio.rssi"])], dict(LOG_VARS))
    with pytest.raises(UnknownName, match="nope.x"):
        plan_log_blocks([("t", 10, ["acc.x", "nope.x"])], dict(LOG_VARS))


def test_log_packet_rate_of_a_plan():
    assert log_packet_rate([PlannedBlock(10), PlannedBlock(100), PlannedBlock(100)]) == 120.0
    assert log_packet_rate([]) == 0.0


def test_log_block_spec_validation():
    validate_log_block_specs([LogBlockSpec("log1", 10, ("pm.vbat",))])
    with pytest.raises(ValueError, match="period"):
        validate_log_block_specs([LogBlockSpec("log1", 5, ("pm.vbat",))])
    with pytest.raises(ValueError, match="twice"):
        validate_log_block_specs([LogBlockSpec("a", 10, ("pm.vbat",)), LogBlockSpec("a", 10, ("pm.vbat",))])
    with pytest.raises(ValueError, match="clashes"):
        validate_log_block_specs([LogBlockSpec("imu", 10, ("pm.vbat",))])
    with pytest.raises(ValueError, match="group.name"):
        validate_log_block_specs([LogBlockSpec("a", 10, ("vbat",))])
