"""SwarmPolicy without ROS, on a fake server port, a ManualClock and fake dongles: the start sequence,
the first-fix retry, the watch's landings and the land retry, emergency refusals."""
from __future__ import annotations

import contextlib
import os
import threading
from typing import Any, Callable, Dict, List, Optional

import pytest

from crazyflie_driver.clock import ManualClock
from crazyflie_driver.errors import (
    CommandRejected,
    CommandValueError,
    CrazyflieError,
    EmergencyActive,
    FlightRefused,
    LinkLost,
    LogConfigError,
)
from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server.swarm.commands import SwarmMember
from crazyflie_driver.server.swarm.config import load_swarm_file
from crazyflie_driver.server.swarm.options import SwarmOptions
from crazyflie_driver.server.swarm.policy import (
    LAND_RETRY_S,
    REBOOT_ALL_SERVICE,
    REBOOT_BACK_S,
    SwarmPolicy,
    initial_position_params,
    refusal_text,
)
from crazyflie_driver.server.worker import WorkerState
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.radio_doubles import AirReply, ScriptedMedium

EXAMPLE = os.path.join(os.path.dirname(__file__), "..", "..", "..", "..", "config", "swarm_example.yaml")


class Safety:
    def __init__(self) -> None:
        self.poses: List[float] = []
        self.high_level: List[str] = []

    def note_pose(self, now: float, z: float) -> None:
        self.poses.append(z)

    def note_high_level(self, now: float, what: str, duration: float = 0.0) -> None:
        self.high_level.append(what)

    def refusal(self, now: float, what: str) -> Optional[str]:
        return None

    def current_height(self, now: float) -> Optional[float]:
        return None


class Cf:
    protocol_version = 12


class Worker:
    """A served Crazyflie: parameter writes that fail ``fail_writes`` times first."""

    def __init__(self, fail_writes: int = 0) -> None:
        self.cf = Cf()
        self.state = WorkerState.RUNNING
        self.safety = Safety()
        self.written: List[Dict[str, Any]] = []
        self.fail_writes = fail_writes
        self.emergency_active = False
        self.log_packet_rate = 0.0
        self.param_values: Dict[str, Any] = {}
        self.flying: Optional[str] = None       # why a reboot is refused
        self.reboots = 0

    def reboot_refusal(self) -> Optional[str]:
        return self.flying

    def reboot(self) -> None:
        self.reboots += 1
        self.state = WorkerState.LOST           # until it answers again
        self.emergency_active = False

    def update_params(self, values):
        if self.fail_writes:
            self.fail_writes -= 1
            return [], ["%s: not acknowledged" % name for name in values]
        self.written.append(dict(values))
        return list(values), []

    def emergency(self) -> None:
        self.emergency_active = True


class Onboard:
    """Onboard commands whose ``land`` raises each error of ``land_errors`` in turn, then is taken."""

    def __init__(self, land_errors=()) -> None:
        self.group_mask = 0
        self.low_level_active = True
        self.calls: List[Any] = []
        self.land_errors = list(land_errors)

    def set_group_mask(self, mask: int) -> None:
        self.calls.append(("set_group_mask", mask))
        self.group_mask = mask

    def notify_setpoints_stop(self, remain_valid_ms: int = 0) -> None:
        self.calls.append(("notify_setpoints_stop", remain_valid_ms))
        self.low_level_active = False

    def land(self, group_mask: int, height: float, duration_s: float) -> None:
        self.calls.append(("land", group_mask, height, duration_s))
        if self.land_errors:
            raise self.land_errors.pop(0)


class Port:
    """The server as the swarm sees it; ``refuse``: names whose add fails."""

    def __init__(self, refuse=()) -> None:
        self.clock = ManualClock()
        self.refuse = set(refuse)
        self.members: Dict[str, SwarmMember] = {}
        self.medium = ScriptedMedium(lambda tx: AirReply(False, retries=tx.arc), dongles=2)
        self.backend = FakeUsbBackend(self.medium, dongles=2, timing=DongleTiming.instant())
        self.stopping = False
        self.budgeted: List[Any] = []

    def add(self, config) -> SwarmMember:
        if config.tf_prefix in self.refuse:
            raise CrazyflieError("could not add %s: no answer" % config.uri)
        m = SwarmMember(config.tf_prefix, config.uri, Worker(), Onboard())
        self.members[m.name] = m
        return m

    def served_workers(self):
        return [m.worker for m in self.members.values()]

    def radio_manager(self):
        return RadioManager(self.backend)

    def add_broadcasts(self, dongle, stats, burst) -> None:
        self.budgeted.append((dongle, burst))

    def shutting_down(self) -> bool:
        return self.stopping


def policy(port: Optional[Port] = None, spawn: Optional[Callable] = None, **options) -> SwarmPolicy:
    options.setdefault("emergency_watchdog", False)
    port = port or Port()
    config = load_swarm_file(EXAMPLE, dongles=2)
    spawned: List[Any] = []
    p = SwarmPolicy(port, SwarmOptions(swarm_file=EXAMPLE, **options), config,
                    spawn=spawn or (lambda target, name: spawned.append((name, target))))
    p.spawned = spawned         # type: ignore[attr-defined]
    return p


def broadcasts(port: Port):
    return [t for t in port.medium.transmits if t.address == BROADCAST_ADDRESS]


def test_start_adds_every_crazyflie_writes_its_file_params_and_names_the_one_that_failed():
    port = Port(refuse={"cf3"})
    p = policy(port)
    assert p.start() is True
    assert [m.name for m in p.members] == ["cf1", "cf2"]
    assert p.failed == {"cf3": "could not add radio://1/90/2M/E7E7E7E703: no answer"}
    cf1, cf2 = (port.members[n] for n in ("cf1", "cf2"))
    # without motion capture the file's initial position is the estimator's start, after the file's params
    written = cf2.worker.written[0]
    assert written["commander.enHighLevel"] == 1 and written["stabilizer.estimator"] == 2
    assert list(written)[-4:] == list(initial_position_params((0.5, 0.0, 0.0)))
    assert written["kalman.initialX"] == 0.5
    # groups from the file, then the high-level commander gets the priority, on the ground
    assert cf2.onboard.calls == [("set_group_mask", 1), ("notify_setpoints_stop", 0)]
    assert cf1.onboard.calls == [("notify_setpoints_stop", 0)]
    assert p.broadcaster is not None and p.commands is not None
    assert p.takeoff(0, 0.5, 2.0) > 0
    assert {t.dongle for t in broadcasts(port)} == {0}      # cf3's radio (dongle 1) is not in the swarm


def test_start_with_no_crazyflie_added_opens_nothing():
    p = policy(Port(refuse={"cf1", "cf2", "cf3"}))
    assert p.start() is False
    assert p.broadcaster is None and sorted(p.failed) == ["cf1", "cf2", "cf3"]
    with pytest.raises(CommandRejected, match="has not started"):
        p.takeoff(0, 0.5, 2.0)


def test_a_member_the_server_stopped_serving_is_left_out():
    port = Port()
    p = policy(port)
    p.start()
    del port.members["cf2"]
    assert [m.name for m in p.live_members()] == ["cf1", "cf3"]


@contextlib.contextmanager
def running_clock(clock: ManualClock, step_s: float = 0.5):
    """The clock runs on in another thread (a wait on it then ends)."""
    done = threading.Event()

    def run() -> None:
        while not done.wait(0.002):
            clock.advance(step_s)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


class Stream:
    def __init__(self) -> None:
        self.refixed: List[str] = []
        self.last_refusal: Dict[str, str] = {}

    def refix(self, name: str) -> None:
        self.refixed.append(name)

    def pause(self, paused: bool = True) -> None:
        self.paused = paused


def test_a_first_fix_lost_on_the_radio_asks_for_the_next_pose_and_the_takeoff_waits_for_it():
    port = Port()
    p = policy(port, mocap="vrpn")
    p.start()
    p.stream = Stream()         # type: ignore[assignment]
    cf1 = next(m for m in p.members if m.name == "cf1")
    cf1.worker.fail_writes = 1
    assert p.write_initial_position(cf1, (1.0, 2.0, 0.0)) is False
    assert p.stream.refixed == ["cf1"] and p.placement.missing(["cf1"], wait_s=0.0) == ["cf1"]
    with running_clock(port.clock), pytest.raises(CommandValueError, match="cf1"):
        p.takeoff(0, 0.5, 2.0)          # waits the placement's time on the server's clock, then refuses
    assert broadcasts(port) == []
    assert p.write_initial_position(cf1, (1.0, 2.0, 0.0)) is True
    assert cf1.worker.written[-1] == initial_position_params((1.0, 2.0, 0.0))
    assert p.placement.missing(["cf1"], wait_s=0.0) == []


def test_a_takeoff_before_the_stream_started_waits_for_the_placements_too():
    """The node advertises /takeoff once ``start`` returns; the stream starts after it. A takeoff in
    between once went out unchecked, to estimators still at the origin."""
    port = Port()
    p = policy(port, mocap="vrpn")
    p.start()
    assert p.stream is None
    with running_clock(port.clock), pytest.raises(CommandValueError, match="no first motion-capture pose"):
        p.takeoff(0, 0.5, 2.0)
    assert broadcasts(port) == []
    for m in p.members:
        p.placement.placed(m.name)
    assert p.takeoff(0, 0.5, 2.0) > 0 and len(broadcasts(port)) > 0


def test_the_watch_lands_a_crazyflie_whose_pose_went_stale_or_whose_link_was_lost_once_each():
    port = Port()
    p = policy(port, mocap="vrpn", stale_after=0.2, stale_hold=0.5)
    p.start()
    port.members["cf3"].worker.state = WorkerState.LOST
    landed = {}
    for tick in range(1, 21):               # cf1 and cf3 keep their poses, cf2's stop after t = 0
        t = 0.05 * tick
        for name in ("cf1", "cf3") if tick > 1 else ("cf1", "cf2", "cf3"):
            p.pose_seen(name, t)
        for name in p.check(t):
            landed[name] = t
    # cf2: stale once its pose is 0.2 s old, landed 0.5 s later; cf3: 0.5 s after its link was seen lost
    assert landed == {"cf2": pytest.approx(0.05 + 0.2 + 0.5, abs=0.06), "cf3": pytest.approx(0.05 + 0.5, abs=0.01)}
    assert p.link_ok == {"cf3": False}
    assert [name for name, _ in p.spawned] == ["land cf3", "land cf2"]
    p.pose_seen("cf1", 1.5)
    assert p.check(1.5) == []           # cf2 and cf3 were told once
    assert port.members["cf2"].onboard.calls[-1] == ("notify_setpoints_stop", 0)
    p.spawned[1][1]()                   # the land runs in its own thread in the server
    assert port.members["cf2"].onboard.calls[-1] == ("land", 0, 0.0, p.options.stale_land_duration)


def test_no_watch_landing_after_the_emergency():
    port = Port()
    p = policy(port, mocap="vrpn")
    p.start()
    p.pose_seen("cf1", 0.0)
    p.emergency()
    assert p.check(5.0) == [] and p.spawned == []


@pytest.mark.parametrize("error", [LinkLost("link lost"), CrazyflieError("not acknowledged")])
def test_the_land_is_retried_while_it_does_not_reach_the_crazyflie(error):
    port = Port()
    p = policy(port)
    member = SwarmMember("cf1", "radio://0/80/2M/E7E7E7E701", Worker(), Onboard([error, error]))
    assert p.land_one(member, "no pose") is True
    assert [c[0] for c in member.onboard.calls] == ["land"] * 3
    assert port.clock.sleeps == [LAND_RETRY_S, LAND_RETRY_S]


@pytest.mark.parametrize("error", [CommandRejected("high-level command 5 refused: 1"),
                                   FlightRefused("landing under way"), EmergencyActive("emergency is active")])
def test_a_refused_land_means_nothing_to_land_and_is_not_retried(error):
    port = Port()
    p = policy(port)
    member = SwarmMember("cf1", "radio://0/80/2M/E7E7E7E701", Worker(), Onboard([error]))
    assert p.land_one(member, "no pose") is False
    assert len(member.onboard.calls) == 1 and port.clock.sleeps == []


def test_a_land_its_checks_refuse_is_not_retried():
    port = Port()
    p = policy(port)
    member = SwarmMember("cf1", "radio://0/80/2M/E7E7E7E701", Worker(), Onboard([CommandValueError("bad")]))
    assert p.land_one(member, "no pose") is False and len(member.onboard.calls) == 1


def test_the_land_retry_ends_with_the_worker_or_the_process():
    port = Port()
    p = policy(port)
    member = SwarmMember("cf1", "radio://0/80/2M/E7E7E7E701", Worker(), Onboard([LinkLost("x")] * 100))
    port.clock.sleep = lambda s: setattr(member.worker, "state", WorkerState.STOPPED)     # type: ignore
    assert p.land_one(member, "link lost") is False and len(member.onboard.calls) == 1
    port.stopping = True
    member.worker.state = WorkerState.RUNNING
    assert p.land_one(member, "link lost") is False and len(member.onboard.calls) == 1


def test_after_the_emergency_every_flight_command_is_refused_with_nothing_on_the_air():
    port = Port()
    p = policy(port)
    p.start()
    assert p.emergency() == []
    assert all(m.worker.emergency_active for m in p.members)
    sent = len(broadcasts(port))
    for call in (lambda: p.takeoff(0, 0.5, 2.0), lambda: p.land(0, 0.0, 2.0), lambda: p.go_to(0, (0, 0, 0), 0, 1),
                 lambda: p.start_trajectory(0, 1, 1.0, False), lambda: p.stop(0)):
        with pytest.raises(CommandRejected, match="emergency"):
            call()
    assert len(broadcasts(port)) == sent


def test_after_the_emergency_a_reboot_of_all_brings_the_swarm_back_once_every_crazyflie_is_back():
    port = Port()
    p = policy(port, mocap="vrpn")
    p.start()
    p.stream = Stream()         # type: ignore[assignment]
    p.emergency()
    with pytest.raises(CommandRejected, match=REBOOT_ALL_SERVICE):     # the refusal names the way back
        p.takeoff(0, 0.5, 2.0)
    assert p.reboot_all() == ["cf1", "cf2", "cf3"]
    assert all(m.worker.reboots == 1 for m in p.members)
    with pytest.raises(CommandRejected, match="rebooting"):
        p.takeoff(0, 0.5, 2.0)
    with pytest.raises(CommandRejected, match="under way"):
        p.reboot_all()
    (name, come_back), = p.spawned
    for m in p.members:
        m.worker.state = WorkerState.RUNNING        # each answered and was set up again by its worker
    assert come_back() is True
    cf2 = port.members["cf2"]
    assert cf2.onboard.calls[-2:] == [("set_group_mask", 1), ("notify_setpoints_stop", 0)]
    assert sorted(p.stream.refixed) == ["cf1", "cf2", "cf3"] and p.stream.paused is False
    assert not p.emergency_active
    for m in p.members:                              # new first fixes place the estimators again
        assert p.write_initial_position(m, (0.0, 0.0, 0.0)) is True
    assert p.takeoff(0, 0.5, 2.0) > 0


def test_a_reboot_of_all_is_refused_whole_while_one_flies_and_one_that_never_comes_back_keeps_the_emergency():
    port = Port()
    p = policy(port)
    p.start()
    p.emergency()
    port.members["cf3"].worker.flying = "not done: a reboot would drop it out of the air"
    with pytest.raises(CommandRejected, match="cf3: not done"):
        p.reboot_all()
    assert all(m.worker.reboots == 0 for m in p.members)
    port.members["cf3"].worker.flying = None
    p.reboot_all()
    (_, come_back), = p.spawned
    port.members["cf1"].worker.state = WorkerState.RUNNING
    port.members["cf2"].worker.state = WorkerState.RUNNING          # cf3 stays silent
    with running_clock(port.clock):
        assert come_back() is False
    assert port.clock.now() >= REBOOT_BACK_S and p.emergency_active
    with pytest.raises(CommandRejected, match=REBOOT_ALL_SERVICE):
        p.land(0, 0.0, 2.0)


def test_a_refusal_names_its_service_once():
    p = policy()
    with pytest.raises(CommandRejected) as e:
        p.takeoff(0, 0.5, 2.0)
    assert refusal_text("/takeoff", e.value) == str(e.value) == (
        "/takeoff refused: the swarm has not started (no Crazyflie added yet)")
    assert refusal_text("/update_params", ValueError("1 not applied: x")) == "/update_params refused: 1 not applied: x"


def test_swarm_workers_log_their_battery_for_the_safety_monitor_with_the_sensor_topics_off():
    config = load_swarm_file(EXAMPLE, dongles=2)
    from crazyflie_driver.server.swarm.policy import BATTERY_WATCH_MS, worker_config
    wc = worker_config(config.crazyflies[0], SwarmOptions(swarm_file=EXAMPLE))
    assert wc.enable_logging is False and wc.battery_watch_ms == BATTERY_WATCH_MS > 0


CS2_LOGS = """\
robots:
  cf1: {uri: "radio://0/80/2M/E7E7E7E701"}
  cf2:
    uri: radio://0/80/2M/E7E7E7E702
    firmware_logging: {custom_topics: {zlog: {frequency: 500}}}
  cf3:
    uri: radio://0/80/2M/E7E7E7E703
    firmware_logging: {custom_topics: {log1: {frequency: 20, vars: [stateEstimate.z]}}}
  cf4:
    uri: radio://0/80/2M/E7E7E7E704
    firmware_logging: {custom_topics: {bad: {frequency: 20, vars: [nosuch.x]}}}
all:
  firmware_logging:
    enabled: true
    custom_topics: {zlog: {frequency: 10, vars: [stateEstimate.z]}}
"""


class LogTocPort(Port):
    """A server whose Crazyflies lack every log variable of group ``nosuch``; ``seen``: each add's config."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: List[Any] = []

    def add(self, config) -> SwarmMember:
        self.seen.append(config)
        if any(v.startswith("nosuch.") for b in config.log_blocks for v in b.variables):
            raise LogConfigError("could not add %s: log topic 'bad': unknown log variable(s) nosuch.x" % config.uri)
        return super().add(config)


def started(port: Port, **options) -> SwarmPolicy:
    from crazyflie_driver.server.swarm.config import parse_swarm
    options = dict(dict(swarm_file="crazyflies.yaml", emergency_watchdog=False, pose_period_ms=0), **options)
    p = SwarmPolicy(port, SwarmOptions(**options), parse_swarm(CS2_LOGS, "crazyflies.yaml"),
                    spawn=lambda target, name: None)
    assert p.start() is True
    return p


def test_custom_log_topics_reach_each_worker_the_files_over_the_parameters_of_the_same_name():
    from crazyflie_driver.server.log_plan import LogBlockSpec
    generic = (LogBlockSpec("log1", 100, ("pm.vbat",)), LogBlockSpec("acc", 10, ("acc.z",)))
    port = LogTocPort()
    p = started(port, enable_logging=True, log_blocks=generic)
    seen = {c.tf_prefix: c.log_blocks for c in port.seen}
    z = LogBlockSpec("zlog", 100, ("stateEstimate.z",))
    assert seen["cf1"] == generic + (z,)
    assert seen["cf3"] == (generic[1], z, LogBlockSpec("log1", 50, ("stateEstimate.z",)))
    assert sorted(p.log_topic_faults) == ["cf2", "cf4"]
    assert p.log_topic_faults["cf2"] == p.config.crazyflies[1].log_error


def test_a_crazyflie_whose_custom_topics_cannot_be_served_is_connected_without_them_never_left_unsupervised():
    port = LogTocPort()
    p = started(port)
    # cf2: a fault in the file; cf4: a variable its firmware lacks. Both fly with the swarm, without custom topics.
    assert [m.name for m in p.members] == ["cf1", "cf2", "cf3", "cf4"] and p.failed == {}
    # the adds run in parallel: in name order, cf4's two tries in theirs
    assert sorted(((c.tf_prefix, [b.topic_name for b in c.log_blocks]) for c in port.seen),
                  key=lambda row: (row[0], -len(row[1]))) == [
        ("cf1", ["zlog"]), ("cf2", []), ("cf3", ["zlog", "log1"]), ("cf4", ["zlog", "bad"]), ("cf4", [])]
    assert p.log_topic_faults["cf2"].startswith("crazyflies.yaml:5: robots.cf2.firmware_logging.custom_topics"
                                                ".zlog.frequency: the Crazyflie's log timer cannot do 500 Hz")
    assert p.log_topic_faults["cf4"] == ("could not add radio://0/80/2M/E7E7E7E704: log topic 'bad': unknown log "
                                         "variable(s) nosuch.x")


def test_a_crazyflie_refused_for_its_link_is_not_tried_again():
    port = LogTocPort()
    port.refuse = {"cf1"}
    p = started(port)
    assert p.failed == {"cf1": "could not add radio://0/80/2M/E7E7E7E701: no answer"}
    assert [c.tf_prefix for c in port.seen].count("cf1") == 1
