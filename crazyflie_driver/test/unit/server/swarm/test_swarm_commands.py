"""Swarm-wide commands through SwarmBroadcaster and two fake dongles: group masks, hand-over from the
low-level stream, bad input refused with nothing on the air, emergency by broadcast and unicast."""
from __future__ import annotations

import math
import struct

import pytest

from crazyflie_driver.errors import CommandValueError, CrazyflieError, TrajectoryError
from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.server.swarm.broadcast import SwarmBroadcaster
from crazyflie_driver.server.swarm.commands import SwarmCommands, SwarmMember, in_groups, update_param_values
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.radio_doubles import AirReply, FakeClock, ScriptedMedium

URIS = ["radio://0/80/2M/E7E7E7E701", "radio://0/80/2M/E7E7E7E702", "radio://1/90/2M/E7E7E7E703"]


class Onboard:
    """``on_air()`` counts the broadcasts on the air, to tell whether notify went out after them."""

    def __init__(self, mask=0, on_air=lambda: 0):
        self.group_mask = mask
        self.low_level_active = True
        self.notified = 0
        self.stopped = 0
        self.notified_after = []        # broadcasts on the air at each notify
        self.on_air = on_air

    def stop_stream(self):
        self.stopped += 1
        return 0

    def hand_over(self, since):
        self.notify_setpoints_stop(0)
        return False

    def notify_setpoints_stop(self, remain_valid_ms=0):
        self.notified += 1
        self.notified_after.append(self.on_air())
        self.low_level_active = False


class HighLevel:
    def __init__(self):
        self.trajectories = {}


class Cf:
    def __init__(self):
        self.high_level = HighLevel()


class Worker:
    def __init__(self, fail=False):
        self.cf = Cf()
        self.emergency_active = False
        self.fail = fail

    def emergency(self):
        self.emergency_active = True
        if self.fail:
            raise CrazyflieError("dongle gone")


def swarm(masks=(0, 1, 2)):
    medium = ScriptedMedium(lambda tx: AirReply(False, retries=tx.arc), dongles=2)
    backend = FakeUsbBackend(medium, dongles=2, timing=DongleTiming.instant())
    bc = SwarmBroadcaster(URIS, 12, RadioManager(backend), repeats=2, sleep=FakeClock().sleep)
    bc.open()
    members = [SwarmMember("cf%d" % (i + 1), uri, Worker(), Onboard(mask, lambda: len(broadcasts(medium))))
               for i, (uri, mask) in enumerate(zip(URIS, masks))]
    return SwarmCommands(lambda: members, bc), members, medium


def broadcasts(medium):
    return [t for t in medium.transmits if t.address == BROADCAST_ADDRESS]


def test_group_rule_is_the_firmware_one():
    assert in_groups(0, 0) and in_groups(3, 0) and in_groups(3, 2) and not in_groups(0, 1) and not in_groups(4, 3)


def test_takeoff_with_a_group_mask_broadcasts_on_every_radio_then_hands_over_only_the_addressed():
    """Notify-setpoints-stop goes out after the broadcast: the plan is there when the priority comes
    back, so no tick of an idle planner (motors off) falls in between."""
    commands, members, medium = swarm()
    assert [m.name for m in commands.targets(1)] == ["cf2"]
    assert commands.takeoff(1, 0.5, 2.0) == 4
    sent = broadcasts(medium)
    assert sorted((t.dongle, t.channel) for t in sent) == [(0, 80), (0, 80), (1, 90), (1, 90)]
    assert {t.data for t in sent} == {bytes([0x8C]) + struct.pack("<BBff?f", 7, 1, 0.5, 0.0, True, 2.0)}
    assert [m.onboard.notified for m in members] == [0, 1, 0]
    assert members[1].onboard.stopped == 1 and members[1].onboard.notified_after == [4]
    commands.land(0, 0.0, 2.0)
    assert [m.onboard.notified for m in members] == [1, 1, 1]
    assert members[0].onboard.notified_after == [8]


def test_go_to_is_relative_and_start_trajectory_needs_the_trajectory_on_every_addressed_crazyflie():
    commands, members, medium = swarm()
    commands.go_to(2, (0.5, -0.25, 0.0), 0.0, 1.5)
    go_to = broadcasts(medium)[-1].data
    assert go_to[1:5] == bytes([12, 2, 1, 0]) and struct.unpack_from("<3f", go_to, 5) == (0.5, -0.25, 0.0)
    members[2].worker.cf.high_level.trajectories[4] = object()
    before = len(broadcasts(medium))
    with pytest.raises(TrajectoryError, match="trajectory 4 was not uploaded to cf1, cf2"):
        commands.start_trajectory(0, 4, 1.0, False)
    assert len(broadcasts(medium)) == before
    commands.start_trajectory(2, 4, 1.0, False)          # only cf3 is in group 2: it has it
    assert broadcasts(medium)[-1].data[1:7] == bytes([13, 2, 1, 0, 0, 4])


@pytest.mark.parametrize("call, words", [
    (lambda c: c.takeoff(256, 0.5, 2.0), "group mask"),
    (lambda c: c.takeoff(-1, 0.5, 2.0), "group mask"),
    (lambda c: c.takeoff(0, 0.5, 0.0), "duration must be > 0"),
    (lambda c: c.land(0, 0.0, -1.0), "duration must be > 0"),
    (lambda c: c.takeoff(0, math.nan, 2.0), "height"),
    (lambda c: c.go_to(0, (math.nan, 0.0, 0.0), 0.0, 2.0), "goal x"),
    (lambda c: c.go_to(0, (0.0, 0.0, math.inf), 0.0, 2.0), "goal z"),
    (lambda c: c.go_to(0, (0.0, 0.0, 0.0), math.nan, 2.0), "yaw"),
    (lambda c: c.start_trajectory(0, 7, 1.0, False), "trajectory 7 was not uploaded"),
    (lambda c: c.start_trajectory(0, 7, 0.0, False), "timescale"),
    (lambda c: c.start_trajectory(128, 7, 1.0, False), "no Crazyflie is in group mask 128"),
    (lambda c: c.stop(300), "group mask"),
])
def test_bad_input_is_refused_by_name_and_nothing_is_sent(call, words):
    commands, members, medium = swarm()
    with pytest.raises(CommandValueError, match=words):
        call(commands)
    assert medium.transmits == []
    assert [m.onboard.notified for m in members] == [0, 0, 0]


def test_emergency_broadcasts_and_stops_every_worker_even_when_one_fails():
    commands, members, medium = swarm()
    members[1].worker.fail = True
    failures = commands.emergency()
    assert failures == ["cf2: dongle gone"]
    assert all(m.worker.emergency_active for m in members)
    sent = broadcasts(medium)
    assert sorted((t.dongle, t.data) for t in sent) == [(0, bytes([0x9D, 3]))] * 2 + [(1, bytes([0x9D, 3]))] * 2


def test_update_params_reads_allcfs_first_then_the_crazyflies_own_and_names_what_is_missing():
    ros = {"/allcfs/stabilizer/controller": 2, "/cf1/stabilizer/controller": 1, "/cf1/locSrv/extPosStdDev": 0.001}
    values, errors = update_param_values(["stabilizer/controller", "/locSrv/extPosStdDev/", "ring/effect", "bad"],
                                         "cf1", ros.get)
    assert values == {"stabilizer.controller": 2, "locSrv.extPosStdDev": 0.001}
    assert errors == ["'ring/effect': neither /allcfs/ring/effect nor /cf1/ring/effect is set",
                      "'bad': not of the form group/name"]


def test_commands_that_went_out_are_observed_for_the_safety_reactions_refused_ones_are_not():
    seen = []
    commands, members, medium = swarm()
    commands = SwarmCommands(lambda: members, commands.broadcaster,
                             observe=lambda targets, what, d: seen.append(([m.name for m in targets], what, d)))
    commands.takeoff(1, 0.5, 2.0)
    commands.land(0, 0.0, 3.0)
    commands.stop(2)
    with pytest.raises(CommandValueError):
        commands.go_to(0, (math.nan, 0.0, 0.0), 0.0, 1.0)
    assert seen == [(["cf2"], "takeoff", 2.0), (["cf1", "cf2", "cf3"], "land", 3.0), (["cf3"], "stop", 0.0)]
