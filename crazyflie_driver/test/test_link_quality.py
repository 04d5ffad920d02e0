"""Link quality: acked / sent over a sliding window of round trips."""
from __future__ import annotations

import pytest

from crazyflie_driver.radio.quality import LinkQuality


def test_link_quality_window():
    q = LinkQuality(window=10)
    for _ in range(10):
        q.record(True)
    for _ in range(4):
        q.record(False)
    assert q.value == pytest.approx(0.6)
