"""Log topics packed into firmware log blocks, and custom log blocks checked before any radio traffic."""
from __future__ import annotations

import pytest

from crazyflie_driver.errors import LogConfigError, UnknownName
from crazyflie_driver.server.log_plan import (
    FIXED_LOG_TOPICS,
    LogBlockSpec,
    PlannedBlock,
    check_custom_log_limits,
    check_log_limits,
    log_packet_rate,
    plan_log_blocks,
    validate_log_block_specs,
)
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


def _plan_with_custom(n_custom, variables=("pm.vbat",)):
    types = dict(LOG_VARS)
    own = plan_log_blocks([(t, p, vs) for t, p, vs in FIXED_LOG_TOPICS], types)
    custom = plan_log_blocks([("c%d" % i, 100, variables) for i in range(n_custom)], types, share=False)
    return own + custom, {"c%d" % i for i in range(n_custom)}


def test_block_limit_counts_the_driver_topics_and_the_custom_ones_together():
    plan, custom = _plan_with_custom(14)
    assert len(plan) == 16
    check_log_limits(plan, custom, 16, 128)         # exactly full: accepted
    plan, custom = _plan_with_custom(20)
    with pytest.raises(LogConfigError) as e:
        check_log_limits(plan, custom, 16, 128)
    text = str(e.value)
    assert "22 log blocks needed" in text and "at most 16" in text
    assert "the driver's own topics use 2 (imu; " in text and "the 20 custom topics one each" in text
    assert "remove at least 6 custom topics" in text and "enable_logging false" in text
    # the older firmware reports 8 blocks in its TOC info: the same plan is counted against that
    plan, custom = _plan_with_custom(7)
    with pytest.raises(LogConfigError, match="9 log blocks needed, .* at most 8"):
        check_log_limits(plan, custom, 8, 64)


def test_variable_limit_counts_every_block():
    four = ("motor.m1", "motor.m2", "motor.m3", "motor.m4")
    plan, custom = _plan_with_custom(12, four * 2)       # 12 x 8 + 12 of the driver's own = 108
    check_log_limits(plan, custom, 16, 128)
    plan, custom = _plan_with_custom(14, four * 2)       # 14 x 8 + 12 = 124, then 9 each: 126 + 12
    check_log_limits(plan, custom, 16, 128)
    plan, custom = _plan_with_custom(14, four * 2 + ("radio.rssi",))
    with pytest.raises(LogConfigError) as e:
        check_log_limits(plan, custom, 16, 128)
    assert "138 log variables needed" in str(e.value) and "at most 128" in str(e.value)
    assert "own topics use 12, the custom topics 126: remove at least 10 custom variables" in str(e.value)


def test_custom_blocks_that_can_never_fit_are_refused_without_a_crazyflie():
    twenty = [LogBlockSpec("t%d" % i, 100, ("pm.vbat",)) for i in range(20)]
    with pytest.raises(LogConfigError, match="20 custom log topics need 20 log blocks .* at most 16: "
                                             "remove at least 4 custom topics"):
        check_custom_log_limits(twenty, enable_logging=False)
    check_custom_log_limits(twenty[:16], enable_logging=False)
    many = [LogBlockSpec("t%d" % i, 100, ("pm.vbat",) * 10) for i in range(13)]
    with pytest.raises(LogConfigError, match="130 log variables, .* at most 128 .* own topics need at least 2 "
                                             "blocks and 12 variables more"):
        check_custom_log_limits(many, enable_logging=True)


def test_a_custom_topic_may_not_take_a_name_the_node_uses_per_crazyflie():
    """Its own status and packets, and every topic the onboard commands subscribe to: read from the node's
    source, so a topic added there and not here fails this test."""
    import ast
    import pathlib

    from crazyflie_driver.server.log_plan import NODE_TOPICS
    node = pathlib.Path(__file__).resolve().parents[3] / "src" / "crazyflie_driver" / "nodes" / "onboard_ros.py"
    subscribed = {n.elts[0].value for n in ast.walk(ast.parse(node.read_text()))
                  if isinstance(n, ast.Tuple) and len(n.elts) == 3 and isinstance(n.elts[0], ast.Constant)
                  and isinstance(n.elts[0].value, str) and isinstance(n.elts[2], ast.Lambda)}
    assert {"cmd_position", "external_pose"} <= subscribed            # the scan found the subscriptions
    assert subscribed <= NODE_TOPICS
    for name in sorted(NODE_TOPICS):
        with pytest.raises(ValueError, match="clashes"):
            validate_log_block_specs([LogBlockSpec(name, 10, ("pm.vbat",))])
