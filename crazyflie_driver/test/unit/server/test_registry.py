"""CrazyflieRegistry: duplicates refused, a failing or slow add keeps nothing and blocks no one else."""
from __future__ import annotations

import threading
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
        with pytest.raises(DuplicateCrazyflie, match="already served"):
            reg.add(WorkerConfig(uri="radio://0/80/2m/e7e7e7e701", tf_prefix="other"))
        with pytest.raises(DuplicateCrazyflie, match="tf_prefix"):
            reg.add(WorkerConfig(uri="radio://0/80/2M/E7E7E7E702", tf_prefix="cf1"))
        with pytest.raises(DuplicateCrazyflie, match="already served as 'cf1'"):   # asked before building
            reg.check_free(WorkerConfig(uri="radio://0/80/2m/e7e7e7e701", tf_prefix="other"))
        with pytest.raises(DuplicateCrazyflie, match="tf_prefix 'cf1' is already served by"):
            reg.check_free(WorkerConfig(uri="radio://0/80/2M/E7E7E7E702", tf_prefix="cf1"))
        reg.check_free(WorkerConfig(uri="radio://0/80/2M/E7E7E7E702", tf_prefix="cf2"))     # free: no error
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


def test_an_add_that_times_out_stops_talking_to_the_crazyflie_before_it_answers_and_a_retry_works(tmp_path):
    """The real radio stack to a simulated Crazyflie made slow (2 ms per packet): its parameter TOC alone takes
    longer than the add's timeout. When the add answers, its worker's thread has ended and its link is closed:
    no packet of that link reaches the Crazyflie afterwards (counted while a retry connects), and the retry,
    with the Crazyflie fast again, connects and reads its parameters."""
    from crazyflie_driver.protocol.crazyflie import Crazyflie
    from support.radio_rig import RadioRig

    rig = RadioRig()
    firmware = rig.firmware
    handle = firmware.handle_radio_packet
    slow = [True]
    heard = [0]

    def slow_handle(data, ack_requested=True):
        heard[0] += 1
        if slow[0]:
            time.sleep(0.002)
        return handle(data, ack_requested)
    firmware.handle_radio_packet = slow_handle
    made = []

    def factory(uri):
        made.append(Crazyflie(uri, radio_manager=rig.manager, cache_dir=str(tmp_path), timeout=1.0))
        return made[-1]
    reg = CrazyflieRegistry(factory)
    config = WorkerConfig(uri=str(rig.uri), tf_prefix="cf1", enable_logging=False)
    try:
        with pytest.raises(TimeoutError, match="did not finish connecting"):
            reg.add(config, timeout=0.3)
        first = made[0]
        sent_at_answer, heard_at_answer = first.link.stats.sent, heard[0]
        assert heard_at_answer > 20         # it was under way: the TOC download had begun
        assert not first.link.is_open
        assert not [t for t in threading.enumerate() if t.name == "crazyflie %s" % config.uri and t.is_alive()]
        assert reg.workers() == []
        slow[0] = False
        worker = reg.add(config, timeout=10.0)
        assert worker.state == WorkerState.RUNNING
        assert worker.param_values["ring.effect"] == firmware.params.value("ring.effect")
        assert first.link.stats.sent == sent_at_answer      # not one packet of the failed add since its answer
    finally:
        reg.shutdown()
