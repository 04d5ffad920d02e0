"""What may interrupt a landing, and what a land or a group mask may ask, on a fake clock: the safety
monitor's decisions, the per-Crazyflie commands over a firmware double and the swarm-wide commands
over fake dongles, judged on the packets that go out (none, where a command is refused)."""
from __future__ import annotations

import logging

import pytest

from crazyflie_driver.errors import CommandValueError, CrazyflieError, FlightRefused
from crazyflie_driver.protocol.high_level import CMD_GO_TO_2, CMD_LAND_2, CMD_STOP, HighLevelCommander, TrajectoryInfo
from crazyflie_driver.protocol.memory import MemoryClient
from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server.onboard_commands import GROUP_MASK_PARAM, OnboardCommands, known_group_mask
from crazyflie_driver.server.safety import Action, Reaction, SafetyConfig, SafetyMonitor, checked_landing
from crazyflie_driver.server.safety_actions import ObservedOnboardCommands, worker_onboard_commands
from crazyflie_driver.server.swarm.broadcast import SwarmBroadcaster
from crazyflie_driver.server.swarm.commands import SwarmCommands, SwarmMember
from crazyflie_driver.server.worker import CrazyflieWorker, WorkerConfig
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.radio_doubles import AirReply, FakeClock, ScriptedMedium
from support.swarm_doubles import FirmwareDouble, LinkDouble
from support.worker_doubles import FakeCrazyflie, started, wait_for
from support.worker_doubles import poll_actions as run

CURRENT_FW = 12
HOVER = 36344


class Clock:
    """A fake clock the test moves by hand."""

    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def monitor(protocol=CURRENT_FW):
    return SafetyMonitor(SafetyConfig(), "cf1", lambda: protocol, dict)




def flying_at(m, t, z=0.5):
    """A high-level flight at height ``z`` with fresh poses up to ``t``."""
    m.note_high_level(t - 5.0, "takeoff")
    m.note_pose(t, z)


# ---------------------------------------------------------------- the monitor's decisions

@pytest.mark.parametrize("start", ["shutdown", "battery", "user land"])
def test_a_landing_under_way_refuses_what_flies_and_takes_land_and_stop(start):
    m, t = monitor(), 10.0
    flying_at(m, t)
    if start == "shutdown":
        assert m.begin_shutdown(t, 10.0)
    elif start == "battery":
        for k in range(300):
            m.note_battery(t - 3.0 + k * 0.01, 3.1)
        m.poll(t)
        assert m.reaction == Reaction.LANDING
    else:
        m.note_high_level(t, "land", 2.0)
    for what in ("takeoff", "go_to", "start_trajectory"):
        assert m.refusal(t + 0.1, what), what
    assert m.refusal(t + 0.1, "land") is None and m.refusal(t + 0.1, "stop") is None
    if start == "user land":
        assert m.refusal(t + 2.01, "go_to") is None          # the landing's plan has ended: a new flight may start
        m.note_high_level(t + 3.0, "land", 2.0)
        assert m.note_setpoint(t + 3.5, 0)                   # a low-level setpoint: the planner forgets the landing
        assert m.refusal(t + 3.6, "takeoff") is None and not m.flying


def test_a_go_to_that_got_through_during_the_reactions_landing_makes_it_land_again_not_stop_in_the_air():
    m, t = monitor(), 10.0
    flying_at(m, t, 0.54)
    assert m.begin_shutdown(t, 10.0)
    first = run(m, t, t + 0.05)
    assert first[0][1].kind == "land"
    m.note_pose(t + 0.5, 0.54)
    m.note_high_level(t + 0.5, "go_to")          # e.g. a broadcast: the firmware flies it instead
    acts = run(m, t + 0.5, t + 0.6)
    assert acts and acts[0][1] == Action("land", duration=pytest.approx(0.54 / 0.3), distance=pytest.approx(0.54))
    assert "hl_stop" not in [a.kind for _, a in acts]
    # the motors go off only once it rests on the floor
    m.note_pose(t + 0.7, 0.3)
    assert all(a.kind != "hl_stop" for _, a in run(m, t + 0.6, t + 2.0))
    m.note_pose(t + 2.4, 0.01)
    assert [a.kind for _, a in run(m, t + 2.4, t + 2.45)][:1] == ["hl_stop"]


def test_a_flight_command_is_refused_once_the_server_lets_the_crazyflie_go():
    m = monitor()
    assert not m.begin_shutdown(1.0, 10.0)           # on the ground: nothing to land
    assert "shutting down" in m.refusal(1.1, "takeoff") and m.refusal(1.1, "land") is None


def test_an_emergency_stop_leaves_nothing_to_bring_down_and_the_shutdown_says_so(caplog):
    m = SafetyMonitor(SafetyConfig(), "cf1", lambda: 2, dict)
    t = 0.0
    while t < 1.0:
        assert m.note_setpoint(t, HOVER)
        t += 0.02
    m.note_motors_off(t, "emergency stop", for_good=True)
    with caplog.at_level(logging.INFO, logger="crazyflie_driver.server.safety"):
        assert not m.begin_shutdown(t + 1.0, 10.0)
    assert not m.flying and m.finished(t + 1.0) and run(m, t + 1.0, t + 3.0) == []
    assert not any("holding level" in e or "descending" in e for e in m.events)
    assert "nothing to bring down, its motors are off (emergency stop)" in m.events[-1]
    m.note_high_level(t + 2.0, "go_to")              # e.g. a swarm command observed afterwards: still stopped
    assert not m.flying


def test_an_emergency_during_a_reaction_ends_it_without_more_packets():
    m = SafetyMonitor(SafetyConfig(), "cf1", lambda: 2, dict)
    t = 0.0
    while t < 1.0:
        m.note_setpoint(t, HOVER)
        t += 0.02
    assert run(m, t + 0.4, t + 0.5)                  # silence: holding level
    m.note_motors_off(t + 0.6, "emergency stop", for_good=True)
    assert m.reaction == Reaction.DOWN and m.finished(t + 0.6)
    assert run(m, t + 0.6, t + 5.0) == []            # no hover thrust, no descent, no extra zero setpoints


def test_checked_landing_refuses_what_would_drop_the_crazyflie():
    assert checked_landing(0.0, 2.5, 0.5) == (0.0, 2.5)
    assert checked_landing(0.54, 1.0, 0.5) == (0.54, 1.0)       # within the pose noise
    assert checked_landing(1.0, 2.0, None) == (1.0, 2.0)        # height unknown: not judged
    with pytest.raises(CommandValueError, match="cf1: land refused: duration must be > 0 s, got 0.0"):
        checked_landing(0.0, 0.0, 0.5, "cf1")
    with pytest.raises(CommandValueError, match=r"target height 1.90 m is above the Crazyflie \(0.50 m\)"):
        checked_landing(1.9, 2.0, 0.5)


# ---------------------------------------------------------------- one Crazyflie's commands

class Crazyflie:
    """The parts of a connected Crazyflie the commands use, over the firmware double."""

    def __init__(self):
        self.firmware = FirmwareDouble()
        self.link = LinkDouble(self.firmware)
        self.protocol_version = CURRENT_FW
        self.high_level = HighLevelCommander(self.link.send, self.link.request, MemoryClient(self.link.request),
                                             protocol_version=CURRENT_FW, label="cf1")
        self.high_level.trajectories[1] = TrajectoryInfo(0, 132, 1, False, 1.0)      # uploaded before


def observed(group_mask=0):
    cf, clock, m = Crazyflie(), Clock(), monitor()
    commands = ObservedOnboardCommands(cf, lambda packet: True, lambda: False, "cf1", m, clock=clock,
                                       group_mask=group_mask)
    return commands, cf, clock, m


def go_to(commands):
    commands.go_to(0, False, (0.0, 0.0, 0.5), 0.0, 1.0)


def test_per_crazyflie_go_to_during_the_servers_landing_is_refused_and_nothing_goes_out():
    commands, cf, clock, m = observed()
    commands.takeoff(0, 0.5, 2.0)
    clock.t += 3.0
    m.note_pose(clock.t, 0.54)
    assert m.begin_shutdown(clock.t, 10.0)
    assert m.poll(clock.t).kind == "land"
    before = len(cf.link.sent)
    for call in (go_to, lambda c: c.takeoff(0, 1.0, 2.0), lambda c: c.start_trajectory(0, 1, 1.0, False, True)):
        with pytest.raises(FlightRefused, match="the server is bringing it down"):
            call(commands)
    assert cf.link.sent[before:] == []
    # what the reaction does next is still a landing, not the high-level stop at 0.54 m
    assert m.poll(clock.t + 0.1) is None and m.reaction == Reaction.LANDING
    commands.stop(0)                                    # motors off is always taken
    assert [p.data[0] for p in cf.link.sent[before:]] == [CMD_STOP]


def test_per_crazyflie_go_to_during_a_land_command_is_refused_until_its_end():
    commands, cf, clock, m = observed()
    commands.takeoff(0, 0.5, 2.0)
    clock.t += 3.0
    commands.land(0, 0.0, 2.0)
    before = len(cf.link.sent)
    clock.t += 1.0
    with pytest.raises(FlightRefused, match="a landing is under way"):
        go_to(commands)
    assert cf.link.sent[before:] == []
    clock.t += 1.1
    go_to(commands)                                     # over: a new flight
    assert cf.link.sent[-1].data[0] == CMD_GO_TO_2


def test_per_crazyflie_land_refuses_no_time_and_a_climb_and_sends_nothing():
    commands, cf, clock, m = observed()
    commands.takeoff(0, 0.5, 2.0)
    m.note_pose(clock.t, 0.5)
    before = len(cf.link.sent)
    with pytest.raises(CommandValueError, match="duration must be > 0 s"):
        commands.land(0, 0.0, 0.0)
    with pytest.raises(CommandValueError, match="above the Crazyflie"):
        commands.land(0, 1.9, 2.0)
    assert cf.link.sent[before:] == []
    commands.land(0, 0.0, 2.0)
    assert cf.link.sent[-1].data[0] == CMD_LAND_2
    # without a server's monitor the duration is still checked
    bare = OnboardCommands(Crazyflie(), lambda packet: True, lambda: False, "cf2")
    with pytest.raises(CommandValueError, match="duration must be > 0 s"):
        bare.land(0, 0.0, 0.0)
    assert bare.cf.link.sent == []


def test_per_crazyflie_group_mask_that_does_not_address_it_is_refused_for_every_command():
    commands, cf, clock, m = observed()
    calls = [lambda c: c.takeoff(2, 0.5, 2.0), lambda c: c.land(2, 0.0, 2.0), lambda c: c.stop(2),
             lambda c: c.go_to(2, False, (0.0, 0.0, 0.5), 0.0, 1.0),
             lambda c: c.start_trajectory(2, 1, 1.0, False, True)]
    for call in calls:
        with pytest.raises(CommandValueError, match="no Crazyflie is in group mask 2"):
            call(commands)
    assert cf.link.sent == []
    commands.set_group_mask(6)
    commands.takeoff(2, 0.5, 2.0)
    assert [p for p in cf.link.sent if p.port == 8][-1].data[:2] == bytes([7, 2])     # notify follows it
    # a Crazyflie that kept its groups from an earlier session (read at connect)
    assert known_group_mask({"hlCommander.groupmask": 4}) == 4 and known_group_mask({}) == 0
    commands, cf, _, _ = observed(group_mask=4)
    commands.takeoff(4, 0.5, 2.0)
    assert [p for p in cf.link.sent if p.port == 8][-1].data[:2] == bytes([7, 4])


def served(n: int = 1):
    """A served Crazyflie's worker (not started) and its HEAD API wired as the server wires them."""
    fake = FakeCrazyflie("radio://0/80/2M/E7E7E7E70%d" % n)
    fake.params.values[GROUP_MASK_PARAM] = 0
    wire = Crazyflie()
    fake.link, fake.high_level, fake.protocol_version = wire.link, wire.high_level, wire.protocol_version
    worker = CrazyflieWorker(WorkerConfig(fake.uri, "cf%d" % n, enable_logging=False, enable_parameters=False),
                             fake, safety=SafetyConfig())
    return worker, worker_onboard_commands(worker, fake.uri), wire


def test_a_group_mask_written_by_update_params_is_the_one_the_per_crazyflie_checks_follow():
    worker, commands, wire = served()
    assert worker.update_params({GROUP_MASK_PARAM: 2}) == ([GROUP_MASK_PARAM], [])   # /cf1/update_params
    assert commands.group_mask == 2
    with pytest.raises(CommandValueError, match="no Crazyflie is in group mask 1 .*group mask 2"):
        commands.takeoff(1, 0.5, 2.0)
    assert wire.link.sent == []
    commands.takeoff(2, 0.5, 2.0)
    assert [p for p in wire.link.sent if p.port == 8][-1].data[:2] == bytes([7, 2])   # notify follows it
    # whichever came last counts: set_group_mask, then a write again
    commands.set_group_mask(4)
    assert commands.group_mask == 4 and worker.param_values[GROUP_MASK_PARAM] == 4
    worker.update_params({GROUP_MASK_PARAM: 2})
    assert commands.group_mask == 2


def test_a_group_mask_written_by_update_params_is_the_one_the_swarm_follows():
    served_ = [served(n) for n in (1, 2, 3)]
    members = [SwarmMember("cf%d" % n, w.uri, w, c) for n, (w, c, _) in zip((1, 2, 3), served_)]
    commands = SwarmCommands(lambda: members, broadcaster=None)
    with pytest.raises(CommandValueError, match="no Crazyflie is in group mask 8"):
        commands.targets(8)
    served_[1][0].update_params({GROUP_MASK_PARAM: 8})        # /cf2/update_params after the add
    assert [m.name for m in commands.targets(8)] == ["cf2"]
    assert [m.name for m in commands.targets(0)] == ["cf1", "cf2", "cf3"]


def test_worker_emergency_clears_what_the_shutdown_reaction_trusts():
    w, cf, _ = started(cf=FakeCrazyflie(), safety=SafetyConfig())
    try:
        def hovering():           # a setpoint at hover thrust until the worker has sent one
            w.cmd_vel(0.0, 0.0, float(HOVER), 0.0)
            return w.safety.flying
        assert wait_for(hovering, 5.0)
        w.emergency()
        assert not w.begin_safe_shutdown(5.0)           # the server says nothing about bringing it down
        assert w.safe_to_close() and not w.safety.flying
        assert not any("holding level" in e for e in w.safety.events)
    finally:
        w.stop()


# ---------------------------------------------------------------- swarm-wide commands

URIS = ["radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702", "radio://1/90/2M/E7E7E7E703"]


class Onboard:
    def __init__(self, mask=0):
        self.group_mask = mask
        self.low_level_active = False


class Worker:
    def __init__(self):
        self.cf = type("Cf", (), {})()
        self.cf.high_level = type("Hl", (), {"trajectories": {1: object()}})()
        self.emergency_active = False
        self.safety = monitor()


def swarm(masks=(0, 1, 2)):
    medium = ScriptedMedium(lambda tx: AirReply(False, retries=tx.arc), dongles=2)
    backend = FakeUsbBackend(medium, dongles=2, timing=DongleTiming.instant())
    bc = SwarmBroadcaster(URIS, CURRENT_FW, RadioManager(backend), repeats=2, sleep=FakeClock().sleep)
    bc.open()
    members = [SwarmMember("cf%d" % (i + 1), uri, Worker(), Onboard(mask)) for i, (uri, mask) in
               enumerate(zip(URIS, masks))]
    clock = Clock()
    commands = SwarmCommands(lambda: members, bc,
                             observe=lambda targets, what, d: [m.worker.safety.note_high_level(clock(), what, d)
                                                               for m in targets],
                             refusal=lambda m, what: m.worker.safety.refusal(clock(), what),
                             height=lambda m: m.worker.safety.current_height(clock()))
    return commands, members, medium, clock


def broadcasts(medium):
    return [t for t in medium.transmits if t.address == BROADCAST_ADDRESS]


def test_swarm_commands_that_would_cancel_a_members_landing_are_refused_and_nothing_is_broadcast():
    commands, members, medium, clock = swarm()
    commands.takeoff(0, 0.5, 2.0)
    clock.t += 3.0
    members[2].worker.safety.note_pose(clock.t, 0.5)
    assert members[2].worker.safety.begin_shutdown(clock.t, 10.0)     # cf3 removed: landing
    before = len(medium.transmits)
    for call in (lambda c: c.go_to(0, (0.1, 0.0, 0.0), 0.0, 1.0), lambda c: c.takeoff(0, 1.0, 2.0),
                 lambda c: c.start_trajectory(0, 1, 1.0, False)):
        with pytest.raises(FlightRefused, match="leave cf3 out with a group mask"):
            call(commands)
    assert medium.transmits[before:] == []
    commands.go_to(1, (0.1, 0.0, 0.0), 0.0, 1.0)       # cf2 alone (group 1) may move
    assert broadcasts(medium)[-1].data[1:3] == bytes([CMD_GO_TO_2, 1])
    commands.land(0, 0.0, 2.0)                          # a land is taken
    assert broadcasts(medium)[-1].data[1] == CMD_LAND_2


def test_swarm_land_refuses_no_time_and_a_climb_and_nothing_is_broadcast():
    commands, members, medium, clock = swarm()
    members[1].worker.safety.note_pose(clock.t, 0.4)
    for call, words in ((lambda c: c.land(0, 0.0, 0.0), "duration must be > 0 s"),
                        (lambda c: c.land(0, 1.0, 2.0), r"cf2: land refused: target height 1.00 m is above")):
        with pytest.raises(CommandValueError, match=words):
            call(commands)
    assert medium.transmits == []


@pytest.mark.parametrize("call", [lambda c: c.takeoff(128, 0.5, 2.0), lambda c: c.land(128, 0.0, 2.0),
                                  lambda c: c.go_to(128, (0.1, 0.0, 0.0), 0.0, 1.0), lambda c: c.stop(128),
                                  lambda c: c.start_trajectory(128, 1, 1.0, False)])
def test_swarm_command_whose_group_mask_addresses_nobody_is_refused_and_nothing_is_broadcast(call):
    commands, members, medium, _ = swarm()
    with pytest.raises(CommandValueError, match="no Crazyflie is in group mask 128 .*group masks 0, 1, 2"):
        call(commands)
    assert medium.transmits == []


def test_errors_are_in_the_one_hierarchy():
    assert issubclass(FlightRefused, CrazyflieError)
