"""The swarm's /update_params: an /allcfs value by one broadcast per radio, a Crazyflie's own by unicast with the
radios in parallel (radio lanes); a busy radio holds up no other, nor a placement."""
from __future__ import annotations

import threading
import time
from typing import Dict, List

import pytest

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server.radio_lanes import RadioLanes
from crazyflie_driver.server.swarm.broadcast import SwarmBroadcaster
from crazyflie_driver.server.swarm.commands import SwarmMember, update_params
from crazyflie_driver.server.worker import CrazyflieWorker, WorkerConfig
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.sim_doubles import FakeVehicle
from support.worker_doubles import wait_for

#: Crazyflies per radio: the first radio has more than a shared pool of 16 writers would take at once in
#: file order, as the demo's 49 (17 on the first channel).
PER_RADIO = {0: 17, 1: 4, 2: 4}
CHANNELS = {0: 80, 1: 90, 2: 100}


class Swarm:
    """Simulated Crazyflies on three fake Crazyradios, each with a connected Crazyflie and an (unstarted)
    worker whose ``update_params`` is what the swarm's ``/update_params`` calls; radio 0 can be held."""

    def __init__(self, cache_dir: str) -> None:
        self.medium = LocalMedium(dongles=3, seed=5)
        self.manager = RadioManager(FakeUsbBackend(self.medium, dongles=3, timing=DongleTiming.instant()))
        self.hold = threading.Event()
        self.hold.set()
        self.firmware: Dict[str, SimulatedCrazyflie] = {}
        self.workers: List[CrazyflieWorker] = []
        n = 0
        for radio, count in PER_RADIO.items():
            for _ in range(count):
                n += 1
                uri = "radio://%d/%d/2M/E7E7E7E7%02X" % (radio, CHANNELS[radio], n)
                p = parse_uri(uri)
                fw = SimulatedCrazyflie(p.address, FakeVehicle("cf%d" % n))
                if radio == 0:
                    fw.handle_radio_packet = self._held(fw.handle_radio_packet)
                self.medium.add_crazyflie(fw, p.channel, p.datarate)
                self.firmware[uri] = fw
                cf = Crazyflie(uri, radio_manager=self.manager, cache_dir=cache_dir, timeout=5.0)
                cf.connect()
                cf.params.fetch_toc()       # as the swarm's connect does (its firmwareParams)
                self.workers.append(CrazyflieWorker(WorkerConfig(uri, "cf%d" % n, enable_logging=False,
                                                                 enable_parameters=False), cf))
        self.members = [SwarmMember(w.config.tf_prefix, w.uri, w, None) for w in self.workers]
        self.broadcaster = SwarmBroadcaster([w.uri for w in self.workers], self.workers[0].cf.protocol_version,
                                            self.manager)
        self.broadcaster.open()

    def _held(self, handle):
        def held(data, ack_requested=True):
            self.hold.wait(30.0)
            return handle(data, ack_requested)
        return held

    def written(self, radio: int, name: str, value: float) -> int:
        return sum(fw.params.value(name) == value for uri, fw in self.firmware.items()
                   if parse_uri(uri).index == radio)

    def close(self) -> None:
        self.hold.set()
        self.broadcaster.close()
        for w in self.workers:
            w.cf.close()


@pytest.fixture
def swarm(tmp_path):
    s = Swarm(str(tmp_path))
    yield s
    s.close()


def test_an_allcfs_value_goes_by_one_broadcast_per_radio_even_with_every_transmit_queue_full(swarm):
    """Broadcast go_tos (each answered by every Crazyflie, 15 repeats) have filled every transmit queue, and
    radio 0 answers no unicast: an /allcfs value still reaches all 25 at once, by name on every radio, and
    the call returns without waiting for one answer."""
    for _ in range(14):
        swarm.broadcaster.go_to((0.0, 0.0, 0.0), 0.0, 1.0)
    assert all(fw.pending_outgoing() >= 200 for fw in swarm.firmware.values())
    swarm.hold.clear()
    ros = {"/allcfs/ring/effect": 5, "/allcfs/ring/solidRed": "0x20"}
    out: List = []
    call = threading.Thread(target=lambda: out.append(update_params(swarm.members, ["ring/effect", "ring/solidRed"],
                                                                    ros.get, swarm.broadcaster)))
    call.start()
    call.join(10.0)
    swarm.hold.set()
    assert not call.is_alive() and out
    written, errors = out[0]
    names = [m.name for m in swarm.members]
    assert (written, errors) == ({"ring.effect": names, "ring.solidRed": names}, [])
    assert all(swarm.written(r, "ring.effect", 5) == n and swarm.written(r, "ring.solidRed", 0x20) == n
               for r, n in PER_RADIO.items())
    assert all(w.param_values["ring.solidRed"] == 0x20 for w in swarm.workers)
    assert all(w.user_params["ring.solidRed"] == 0x20 for w in swarm.workers)     # set again after a reboot


def test_own_values_go_by_unicast_to_every_radio_at_once_and_a_held_radio_holds_up_no_other_nor_a_placement(swarm):
    """Each Crazyflie's own value (no /allcfs one) by acknowledged unicast. Radio 0 answers nothing while held:
    the other radios' Crazyflies are all written meanwhile (a pool taken in file order would have them wait
    behind the first radio's 17), a placement write on another radio goes through while the update is still
    under way, and once radio 0 answers again every write lands. A bad name is named once, not per Crazyflie."""
    ros = {"/%s/ring/effect" % m.name: 5 for m in swarm.members}
    swarm.hold.clear()
    out: List = []
    updating = threading.Thread(target=lambda: out.append(update_params(
        swarm.members, ["ring/effect", "ring/eff\x01ect"], ros.get, swarm.broadcaster)))
    updating.start()
    try:
        assert wait_for(lambda: swarm.written(1, "ring.effect", 5) == PER_RADIO[1]
                        and swarm.written(2, "ring.effect", 5) == PER_RADIO[2], timeout=10.0)
        assert swarm.written(0, "ring.effect", 5) == 0 and updating.is_alive()
        placed = next(w for w in swarm.workers if parse_uri(w.uri).index == 2)
        written, errors = placed.update_params({"kalman.initialX": 1.5, "kalman.resetEstimation": 1})
        assert (written, errors) == (["kalman.initialX", "kalman.resetEstimation"], [])
        assert updating.is_alive()          # the placement did not wait for the update
    finally:
        swarm.hold.set()
        updating.join(30.0)
    assert not updating.is_alive() and out
    written, errors = out[0]
    assert written == {"ring.effect": [m.name for m in swarm.members]}
    assert len(errors) == 1 and errors[0].startswith("'ring/eff\\x01ect'"), errors
    assert all(swarm.written(r, "ring.effect", 5) == n for r, n in PER_RADIO.items())


def test_lanes_keep_the_order_of_the_items_and_raise_a_tasks_error_after_all_ended():
    ran: List[int] = []
    with RadioLanes(2) as lanes:
        assert lanes.map(lambda i: i % 3, lambda i: ran.append(i) or i * i, list(range(10))) == \
            [i * i for i in range(10)]

        def fail(i: int) -> int:
            if i == 4:
                raise ValueError("four")
            time.sleep(0.01)
            ran.append(100 + i)
            return i
        with pytest.raises(ValueError, match="four"):
            lanes.map(lambda i: i % 3, fail, list(range(8)))
    assert sorted(ran[10:]) == [100 + i for i in range(8) if i != 4]
    with pytest.raises(ValueError):
        RadioLanes(0)
