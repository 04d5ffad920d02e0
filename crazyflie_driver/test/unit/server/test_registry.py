"""CrazyflieRegistry: duplicates refused, a failing or slow add keeps nothing and blocks no one else."""
from __future__ import annotations

import time
from typing import Dict

import pytest

from crazyflie_driver.errors import LinkTimeout
from crazyflie_driver.server.registry import CrazyflieRegistry, DuplicateCrazyflie
from crazyflie_driver.server.worker import WorkerConfig, WorkerState

from support.worker_doubles import FakeCrazyflie


def test_registry_refuses_duplicates_and_serves_others_while_one_times_out():
    made: Dict[str, FakeCrazyflie] = {}

    def factory(uri):
        cf = FakeCrazyflie(uri, connect_error=LinkTimeout("%s: no answer" % uri) if uri.endswith("09") else None)
        made[uri] = cf
        return cf

    reg = CrazyflieRegistry(factory)
    try:
        reg.add(WorkerConfig(uri="radio://0/80/2M/E7E7E7E701", tf_prefix="cf1"))
        with pytest.raises(DuplicateCrazyflie, match="already added"):
            reg.add(WorkerConfig(uri="radio://0/80/2m/e7e7e7e701", tf_prefix="other"))
        with pytest.raises(DuplicateCrazyflie, match="tf_prefix"):
            reg.add(WorkerConfig(uri="radio://0/80/2M/E7E7E7E702", tf_prefix="cf1"))
        n = len(made["radio://0/80/2M/E7E7E7E701"].of_kind("null"))
        with pytest.raises(LinkTimeout, match="no answer"):
            reg.add(WorkerConfig(uri="radio://0/80/2M/E7E7E7E709", tf_prefix="cf9"))
        assert [w.uri for w in reg.workers()] == ["radio://0/80/2M/E7E7E7E701"]
        assert made["radio://0/80/2M/E7E7E7E709"].closed
        time.sleep(0.05)
        assert len(made["radio://0/80/2M/E7E7E7E701"].of_kind("null")) > n
    finally:
        reg.shutdown()


def test_registry_add_timeout_and_remove():
    reg = CrazyflieRegistry(lambda uri: FakeCrazyflie(uri, connect_delay=0.5 if uri.endswith("03") else 0))
    try:
        t0 = time.monotonic()
        with pytest.raises(TimeoutError, match="E7E7E7E703"):
            reg.add(WorkerConfig(uri="radio://0/80/2M/E7E7E7E703", tf_prefix="c"), timeout=0.1)
        assert time.monotonic() - t0 < 0.4
        assert reg.workers() == []
        w = reg.add(WorkerConfig(uri="radio://0/80/2M/E7E7E7E701", tf_prefix="a"))
        reg.remove("radio://0/80/2M/E7E7E7E701")
        assert w.cf.closed and w.state == WorkerState.STOPPED
        with pytest.raises(KeyError):
            reg.remove("radio://0/80/2M/E7E7E7E701")
    finally:
        reg.shutdown()
