"""Refused input is said once per kind and second, per Crazyflie, topic and field, with the count of the unsaid."""
from __future__ import annotations

from crazyflie_driver.server.refusals import RefusalThrottle, refusal_kind


def test_numbers_are_not_part_of_the_kind():
    assert refusal_kind("x must be finite, got nan") == refusal_kind("x must be finite, got -1e+39")
    assert refusal_kind("x must be finite, got inf") != refusal_kind("y must be finite, got inf")
    assert refusal_kind("quaternion component 2 is 1.5e-310") == "quaternion component # is #"


def test_each_kind_is_said_at_once_then_throttled_with_a_count():
    now = [0.0]
    t = RefusalThrottle(1.0, clock=lambda: now[0])
    assert t.say("cf1", "cmd_position", "x must be finite, got nan") == "x must be finite, got nan"
    assert t.say("cf1", "cmd_position", "x must be finite, got inf") is None
    assert t.say("cf1", "cmd_position", "y must be finite, got inf") is not None        # another field
    assert t.say("cf2", "cmd_position", "x must be finite, got inf") is not None        # another Crazyflie
    assert t.say("cf1", "cmd_hover", "x must be finite, got inf") is not None           # another topic
    now[0] = 0.5
    assert t.say("cf1", "cmd_position", "x must be finite, got 1e+39") is None
    now[0] = 1.0
    line = t.say("cf1", "cmd_position", "x must be finite, got -inf")
    assert line.endswith("got -inf (and 2 more like it since the last message)")
