"""The senders of ports 4, 6, 7, 8, 9 against a Crazyflie double that answers as the firmware does:
what reaches the Crazyflie, what it answers, and bad input refused before anything is sent."""
from __future__ import annotations

import errno
import math
import struct

import pytest

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import CommandRejected, CommandValueError, NotSupported, TrajectoryError
from crazyflie_driver.protocol import high_level as hl
from crazyflie_driver.protocol.localization import LocalizationSender
from crazyflie_driver.protocol.memory import MemoryClient
from crazyflie_driver.protocol.setpoints import SetpointSender
from crazyflie_driver.protocol.supervisor import Supervisor
from crazyflie_driver.protocol.trajectory import PIECE_BYTES, make_piece, pack_compressed, pack_poly4d, pieces_from_rows
from support.swarm_doubles import FirmwareDouble, LinkDouble


def commander(version=12, **firmware):
    fw = FirmwareDouble(**firmware)
    link = LinkDouble(fw)
    memory = MemoryClient(link.request, label="cf")
    return hl.HighLevelCommander(link.send, link.request, memory, protocol_version=version, label="cf"), link, fw


def figure(n, duration=1.0):
    """n continuous pieces: x ramps 0.1 m per piece, z constant, yaw 0."""
    return [make_piece(duration, [0.1 * i, 0.1 / duration] + [0] * 6, [0] * 8, [1.0] + [0] * 7, [0] * 8)
            for i in range(n)]


def test_upload_writes_poly4d_into_the_trajectory_memory_then_defines_it():
    hlc, link, fw = commander()
    pieces = figure(3)
    info = hlc.upload_trajectory(2, pieces, piece_offset=4)
    data = pack_poly4d(pieces)
    assert fw.memory[4 * PIECE_BYTES:4 * PIECE_BYTES + len(data)] == data
    define = link.sent[-1]
    assert (define.port, define.data) == (8, struct.pack("<BBBBIB", 6, 2, 1, 0, 4 * PIECE_BYTES, 3))
    assert info.n_pieces == 3 and info.address == 528 and info.duration == 3.0
    hlc.start_trajectory(2, timescale=2.0, relative=True)
    assert link.sent[-1].data[0] == hl.CMD_START_TRAJECTORY_2


def test_compressed_upload_is_defined_as_compressed_and_smaller():
    hlc, link, fw = commander()
    pieces = figure(5)
    hlc.upload_trajectory(1, pieces, compressed=True)
    data = pack_compressed(pieces)
    assert fw.memory[:len(data)] == data and len(data) < len(pack_poly4d(pieces)) / 5
    assert link.sent[-1].data[3] == hl.FORMAT_COMPRESSED
    with pytest.raises(TrajectoryError, match="compressed"):
        hlc.start_trajectory(1, timescale=2.0)


def test_too_large_for_the_memory_is_refused_before_sending_anything():
    hlc, link, fw = commander()
    with pytest.raises(TrajectoryError, match="4096 bytes"):
        hlc.upload_trajectory(1, figure(32))
    with pytest.raises(TrajectoryError, match="holds 4096"):
        hlc.upload_trajectory(1, figure(2), piece_offset=30)
    assert not [p for p in link.sent if p.port != 4 or p.channel != 0]   # only the memory enumeration
    hlc.upload_trajectory(1, figure(31))   # 31 pieces fill it exactly


def test_pieces_that_are_not_eight_coefficients_each():
    with pytest.raises(TrajectoryError, match="piece 2: y has 7 coefficients"):
        make_piece(1.0, [0] * 8, [0] * 7, [0] * 8, [0] * 8, index=2)
    with pytest.raises(TrajectoryError, match="row 0 has 32 values"):
        pieces_from_rows([[1.0] + [0.0] * 31])
    with pytest.raises(TrajectoryError, match="duration"):
        make_piece(float("nan"), [0] * 8, [0] * 8, [0] * 8, [0] * 8)
    with pytest.raises(TrajectoryError, match="not a finite number"):
        make_piece(1.0, [0] * 7 + [math.inf], [0] * 8, [0] * 8, [0] * 8)


def test_unknown_trajectory_ids():
    hlc, link, fw = commander()
    with pytest.raises(TrajectoryError, match="trajectory 4 was not uploaded"):
        hlc.start_trajectory(4)
    with pytest.raises(TrajectoryError, match="0..30"):
        hlc.upload_trajectory(31, figure(1))
    with pytest.raises(TrajectoryError, match="0..30"):
        hl.start_trajectory_packet(-1, 12)
    assert link.sent == []


def test_an_overwritten_trajectory_is_forgotten():
    hlc, link, fw = commander()
    hlc.upload_trajectory(1, figure(2), piece_offset=0)
    hlc.upload_trajectory(2, figure(2), piece_offset=1)
    assert sorted(hlc.trajectories) == [2]
    with pytest.raises(TrajectoryError, match="not uploaded"):
        hlc.start_trajectory(1)


def test_set_group_mask_takes_the_firmwares_reply_whatever_its_third_byte_holds():
    # The firmware answers in the request's own buffer: [0, mask, <undefined>, result] for a 2-byte request.
    hlc, link, fw = commander()
    for third in (0x00, 0xA5):
        fw.handle = lambda p, third=third: [CRTPPacket(8, 0, bytes([0, p.data[1], third, 0]))]
        hlc.set_group_mask(0b101)
    assert [p.data for p in link.sent] == [bytes([0, 0b101])] * 2


@pytest.mark.parametrize("mask", [256, -1, 1.0, True, None])
def test_group_mask_out_of_range(mask):
    with pytest.raises(CommandValueError, match="group mask"):
        hl.takeoff_packet(0.5, 2.0, 12, group_mask=mask)
    with pytest.raises(CommandValueError, match="group mask"):
        hl.set_group_mask_packet(mask)


@pytest.mark.parametrize("bad", [dict(x=math.nan), dict(z=math.inf), dict(yaw=math.nan), dict(duration=-1.0),
                                 dict(duration=math.nan)])
def test_go_to_with_bad_numbers_sends_nothing(bad):
    hlc, link, fw = commander()
    args = dict(x=1.0, y=2.0, z=0.5, yaw=0.0, duration=2.0)
    args.update(bad)
    with pytest.raises(CommandValueError):
        hlc.go_to(**args)
    assert link.sent == []


def test_refusals_carry_the_reason():
    hlc, link, fw = commander(hl_result=errno.EBUSY)
    with pytest.raises(CommandRejected, match="supervisor blocks"):
        hlc.takeoff(0.5, 2.0)
    hlc, link, fw = commander(hl_result=1)
    with pytest.raises(CommandRejected, match="only while the planner is idle"):
        hlc.takeoff(0.5, 2.0)
    hlc, link, fw = commander(write_status=1)
    with pytest.raises(CommandRejected, match="refused 24 bytes at address 0"):
        hlc.upload_trajectory(1, figure(1))
    assert not [p for p in link.sent if p.port == 8]   # not defined after a failed write


def test_old_and_new_commands_by_protocol_version():
    for version, takeoff, go_to, start in ((4, 1, 4, 5), (5, 7, 4, 5), (8, 7, 12, 5), (12, 7, 12, 13)):
        assert hl.takeoff_packet(0.5, 2, version).data[0] == takeoff
        assert hl.land_packet(0.0, 2, version).data[0] == takeoff + 1
        assert hl.go_to_packet(0, 0, 1, 0, 2, version).data[0] == go_to
        assert hl.start_trajectory_packet(1, version).data[0] == start
    assert hl.takeoff_packet(0.5, 2.0, 4).data == struct.pack("<BBff", 1, 0, 0.5, 2.0)
    with pytest.raises(NotSupported, match="protocol version 4"):
        hl.takeoff_packet(0.5, 2.0, 2)
    with pytest.raises(NotSupported, match="linear"):
        hl.go_to_packet(0, 0, 1, 0, 2, 7, linear=True)
    with pytest.raises(NotSupported, match="relative_yaw"):
        hl.start_trajectory_packet(1, 9, relative=True, relative_yaw=True)
    with pytest.raises(TrajectoryError, match="together with relative"):
        hl.start_trajectory_packet(1, 12, relative_yaw=True)


def test_a_relative_go_to_is_never_sent_twice_by_the_resend_timer():
    hlc, link, fw = commander()
    hlc.go_to(0.5, 0, 0, 0, 1.0, relative=True)
    hlc.go_to(0.5, 0, 0, 0, 1.0, relative=False)
    assert link.resend_intervals[0] > hlc.timeout and link.resend_intervals[1] < hlc.timeout


def test_setpoint_sender_checks_values_and_picks_types():
    link = LinkDouble(FirmwareDouble())
    setpoints = SetpointSender(link.send, protocol_version=12)
    setpoints.hover(0.1, 0.0, 10.0, 0.5)
    setpoints.velocity_world(0.0, 0.0, 0.1, 0.0)
    setpoints.position(1.0, 1.0, 1.0, 0.0)
    setpoints.full_state((0, 0, 1), (0, 0, 0), (0, 0, 0), (0, 0, 0, 1), (0, 0, 0))
    setpoints.notify_setpoints_stop()
    setpoints.stop()
    assert [(p.port, p.channel, p.data[0]) for p in link.sent] == [(7, 0, 10), (7, 0, 8), (7, 0, 7), (7, 0, 6),
                                                                   (7, 1, 0), (7, 0, 0)]
    with pytest.raises(CommandValueError, match="position x"):
        setpoints.full_state((40.0, 0, 1), (0, 0, 0), (0, 0, 0), (0, 0, 0, 1), (0, 0, 0))
    with pytest.raises(CommandValueError, match="quaternion"):
        setpoints.full_state((0, 0, 1), (0, 0, 0), (0, 0, 0), (0, 0, 0, 0), (0, 0, 0))
    with pytest.raises(CommandValueError, match="z"):
        setpoints.position(0, 0, math.nan, 0)
    with pytest.raises(CommandValueError, match="remain_valid_ms"):
        setpoints.notify_setpoints_stop(-1)
    assert len(link.sent) == 6
    old = SetpointSender(link.send, protocol_version=2)
    with pytest.raises(NotSupported, match="port 7"):
        old.hover(0, 0, 0, 0.5)
    old.stop()
    assert link.sent[-1].port == 3   # zero RPYT where port 7 does not exist


def test_localization_sender_and_bad_poses():
    link = LinkDouble(FirmwareDouble())
    sender = LocalizationSender(link.send)
    sender.external_position(1.0, 2.0, 3.0)
    sender.external_pose(1.0, 2.0, 3.0, (0, 0, 0, 1))
    assert [(p.port, p.channel, len(p.data)) for p in link.sent] == [(6, 0, 12), (6, 1, 29)]
    with pytest.raises(CommandValueError, match="qw"):
        sender.external_pose(1.0, 2.0, 3.0, (0, 0, 0, math.nan))
    with pytest.raises(CommandValueError, match="normalised"):
        sender.external_pose(1.0, 2.0, 3.0, (0, 0, 0, 0))


def test_supervisor_arms_reads_state_and_keeps_the_watchdog_alive():
    fw = FirmwareDouble()
    link = LinkDouble(fw)
    supervisor = Supervisor(link.send, link.request, protocol_version=12)
    assert supervisor.arm(True) is True and fw.armed
    state = supervisor.state()
    assert state.bits == 0b1_0000_1001
    assert state.flags["can_arm"] and state.flags["can_fly"] and state.flags["hl_active"]
    assert not state.flags["locked"]
    supervisor.keep_alive()
    supervisor.emergency_stop()
    assert [(p.port, p.channel, p.data) for p in link.sent[-2:]] == [(9, 1, b"\x04"), (9, 1, b"\x03")]
    legacy = Supervisor(link.send, link.request, protocol_version=4)
    legacy.keep_alive()
    assert (link.sent[-1].port, link.sent[-1].data) == (6, b"\x04")
    with pytest.raises(NotSupported, match="protocol version 12"):
        legacy.state()
    with pytest.raises(NotSupported, match="arming"):
        legacy.arm()
