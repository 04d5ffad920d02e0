"""crazyflie_ros HEAD's per-Crazyflie API without ROS: what each topic and service puts on the wire."""
from __future__ import annotations

import math
import struct

import pytest

from crazyflie_driver.errors import CommandValueError, CrazyflieError, TrajectoryError
from crazyflie_driver.protocol.high_level import HighLevelCommander
from crazyflie_driver.protocol.memory import MemoryClient
from crazyflie_driver.server.onboard_commands import OnboardCommands
from support.swarm_doubles import FirmwareDouble, LinkDouble
from support.worker_doubles import FakeCrazyflie, started, wait_for


class Crazyflie:
    """The parts of a connected Crazyflie the commands use, over the firmware double."""

    def __init__(self, version=12):
        self.firmware = FirmwareDouble()
        self.link = LinkDouble(self.firmware)
        self.protocol_version = version
        self.high_level = HighLevelCommander(self.link.send, self.link.request, MemoryClient(self.link.request),
                                             protocol_version=version, label="cf1")


def make(version=12):
    cf = Crazyflie(version)
    streamed = []
    emergency = []

    def stream(packet):
        streamed.append(packet)
        return not emergency

    return OnboardCommands(cf, stream, lambda: bool(emergency), "cf1"), cf, streamed, emergency


def wire(cf):
    return [(p.port, p.channel, p.data[0]) for p in cf.link.sent]


def test_high_level_after_low_level_setpoints_goes_out_first_then_hands_control_back():
    """After low-level setpoints the command goes first and notify-setpoints-stop after it: the firmware
    plans the command meanwhile, so when the priority comes back its plan is there and no tick of an
    idle planner (its null setpoint stops the motors) falls between the two packets."""
    commands, cf, streamed, _ = make()
    commands.takeoff(0, 0.5, 2.0)            # after connect: the zero setpoints hold the priority
    commands.go_to(0, False, (1.0, 0.0, 0.5), 0.0, 2.0)
    commands.cmd_position(1.0, 0.0, 0.5, 0.0)
    commands.land(0, 0.0, 2.0)
    assert wire(cf) == [(8, 0, 7), (7, 1, 0), (8, 0, 12), (8, 0, 8), (7, 1, 0)]
    assert streamed[0] is None and streamed[2].port == 7 and streamed[2].data[0] == 7 and streamed[3] is None
    takeoff = cf.link.sent[0].data
    assert struct.unpack("<BBff?f", takeoff) == (7, 0, 0.5, 0.0, True, 2.0)


def test_worker_setpoints_since_the_last_notify_need_another_one():
    """cmd_vel (or a controller's RPYT) streamed by the worker takes the priority back in the firmware: the
    next high-level command hands control back again, and only then."""
    cf = Crazyflie()
    sent = [0]
    commands = OnboardCommands(cf, lambda packet: True, lambda: False, "cf1", low_level_sent=lambda: sent[0])
    commands.takeoff(0, 0.5, 2.0)
    commands.land(0, 0.0, 2.0)               # nothing streamed in between: no notify
    sent[0] += 3                             # the worker sent cmd_vel setpoints
    assert commands.low_level_active
    commands.takeoff(0, 0.5, 2.0)
    assert wire(cf) == [(8, 0, 7), (7, 1, 0), (8, 0, 8), (8, 0, 7), (7, 1, 0)]


def test_a_setpoint_that_goes_out_after_the_command_gets_the_command_again_after_notify():
    """A setpoint already in the worker's hands went out after the command: in the firmware it stopped
    the plan, so notify goes out again (the setpoint took the priority back) and the command once more."""
    cf = Crazyflie()
    counts = iter([0, 1, 1, 1, 1, 1])        # stop_stream: 0; then the setpoint has gone out
    commands = OnboardCommands(cf, lambda packet: True, lambda: False, "cf1", low_level_sent=lambda: next(counts))
    commands.takeoff(0, 0.5, 2.0)
    assert wire(cf) == [(8, 0, 7), (7, 1, 0), (8, 0, 7)]


def test_a_relative_go_to_is_not_sent_twice():
    """A relative go_to taken twice would fly twice the distance: it is not repeated."""
    cf = Crazyflie()
    counts = iter([0, 1, 1, 1, 1, 1])
    commands = OnboardCommands(cf, lambda packet: True, lambda: False, "cf1", low_level_sent=lambda: next(counts))
    commands.go_to(0, True, (0.5, 0.0, 0.0), 0.0, 2.0)
    assert wire(cf) == [(8, 0, 12), (7, 1, 0)]


def test_streaming_topics_become_port_7_packets_for_the_worker():
    commands, cf, streamed, _ = make(version=8)
    commands.cmd_hover(0.1, 0.2, 30.0, 0.4)
    commands.cmd_velocity_world(0.1, 0.2, 0.3, -20.0)
    commands.cmd_full_state((1, 2, 0.5), (0, 0, 0, 1), (0.1, 0, 0), (0, 0, 0.2), (0, 0, 0))
    commands.cmd_stop()
    assert [(p.port, p.data[0]) for p in streamed] == [(7, 5), (7, 1), (7, 6), (7, 0)]
    assert struct.unpack_from("<4f", streamed[0].data, 1)[2] == -30.0   # legacy type: negated for the firmware
    with pytest.raises(CommandValueError):
        commands.cmd_position(math.nan, 0, 0, 0)
    assert len(streamed) == 4


def test_a_pose_counts_for_diagnostics_only_once_the_crazyflie_took_it():
    """A NaN pose (refused by the builder) and a pose the radio lost must not make the pose look fresh."""
    cf = Crazyflie()
    counted = []
    commands = OnboardCommands(cf, lambda packet: True, lambda: False, "cf1", on_pose=lambda: counted.append(1))
    assert commands.external_position(1.0, 2.0, 0.5)
    with pytest.raises(CommandValueError):
        commands.external_pose(math.nan, 2.0, 0.5, (0, 0, 0, 1))
    cf.link.send = lambda packet: False          # not acknowledged: lost on the radio
    assert commands.external_position(1.0, 2.0, 0.5) is False
    assert len(counted) == 1


def test_external_pose_goes_out_at_once_and_not_after_emergency():
    commands, cf, _, emergency = make()
    assert commands.external_pose(1.0, 2.0, 0.5, (0, 0, 0, 1))
    assert wire(cf) == [(6, 1, 8)]
    emergency.append(True)
    assert commands.external_position(1.0, 2.0, 0.5) is False
    with pytest.raises(CrazyflieError, match="emergency is active"):
        commands.takeoff(0, 0.5, 2.0)
    assert wire(cf) == [(6, 1, 8)]


def test_upload_and_start_trajectory_and_bad_requests():
    commands, cf, _, _ = make()
    piece = (1.5, [0.0] * 8, [0.0] * 8, [0.5] + [0.0] * 7, [0.0] * 8)
    commands.upload_trajectory(1, 0, [piece, piece])
    commands.start_trajectory(0, 1, 1.0, False, True)
    assert cf.firmware.memory[:264] == b"".join(struct.pack("<33f", *([0.0] * 16 + [0.5] + [0.0] * 15 + [1.5]))
                                                for _ in range(2))
    assert wire(cf)[-3:] == [(8, 0, 6), (8, 0, 13), (7, 1, 0)]
    before = len(cf.link.sent)
    commands.cmd_position(0.0, 0.0, 0.5, 0.0)   # flying on low-level setpoints: a bad request must not
    #                                             hand control to the idle planner (motors off)
    with pytest.raises(TrajectoryError, match="piece 1: y has 7"):
        commands.upload_trajectory(2, 0, [piece, (1.0, [0.0] * 8, [0.0] * 7, [0.0] * 8, [0.0] * 8)])
    with pytest.raises(TrajectoryError, match="trajectory 9 was not uploaded"):
        commands.start_trajectory(0, 9, 1.0, False, True)
    with pytest.raises(CommandValueError, match="goal x"):
        commands.go_to(0, False, (math.nan, 0.0, 1.0), 0.0, 2.0)
    assert len(cf.link.sent) == before


class PacketCrazyflie(FakeCrazyflie):
    """The worker double with a link that can send prepared packets."""

    def __init__(self):
        super().__init__()
        self.link.send = lambda packet: self._packet("packet", packet)


def test_the_worker_streams_prepared_packets_like_setpoints():
    w, cf, _ = started(cf=PacketCrazyflie(), keepalive_period=0.5)
    try:
        commands = OnboardCommands(cf, w.set_packet_setpoint, lambda: w.emergency_active, "cf1")
        commands.cmd_position(0.5, 0.0, 1.0, 90.0)
        assert wait_for(lambda: cf.of_kind("packet"))
        packet = cf.of_kind("packet")[0][2][0]
        assert (packet.port, packet.data) == (7, struct.pack("<B4f", 7, 0.5, 0.0, 1.0, 90.0))
        w.emergency()
        assert commands.cmd_position(0.5, 0.0, 1.0, 90.0) is False
    finally:
        w.stop()
