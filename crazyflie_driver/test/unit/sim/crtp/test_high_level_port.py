"""Port 8 as the firmware decodes it: each command's bytes become one call of the world with the
fields in their places, and every packet is answered on its own header with its result."""
from __future__ import annotations

import pytest

from crazyflie_driver.sim.crtp import high_level_port as hl
from crazyflie_driver.sim.crtp.trajectory_memory import (
    COMPRESSED_HEADER,
    COMPRESSED_START,
    LOCATION_MEMORY,
    MAX_TRAJECTORIES,
    POLY4D_PIECE,
    TYPE_COMPRESSED,
    TYPE_POLY4D,
    Descriptor,
    TrajectoryMemory,
)

HEADER = 0x80


def packet(cmd: int, *fields) -> bytes:
    """The command byte, then its fields packed by the firmware's layout."""
    return bytes([cmd]) + hl.LAYOUTS[cmd].pack(*fields)


class Port:
    """The port with a world that records its calls and answers ``result``."""

    def __init__(self, result: int = 0) -> None:
        self.calls: list = []
        self.replies: list = []
        self.memory = TrajectoryMemory()
        self.result = result
        self.handle = hl.high_level_port(self._send, self._call, self.memory)

    def _send(self, header: int, data: bytes) -> bool:
        self.replies.append((header, data))
        return True

    def _call(self, op: str, **args) -> int:
        self.calls.append((op, args))
        return self.result

    def command(self, cmd: int, *fields) -> bytes:
        """Send command ``cmd`` with its fields packed by the firmware's layout; the reply's data."""
        self.handle(HEADER, 0, packet(cmd, *fields))
        header, data = self.replies[-1]
        assert header == HEADER
        return data


@pytest.mark.parametrize("cmd, fields, op, args", [
    (hl.SET_GROUP_MASK, (6,), "set_group_mask", {"mask": 6}),
    (hl.TAKEOFF, (2, 0.5, 2.0), "takeoff", {"mask": 2, "height": 0.5, "yaw": 0.0, "duration": 2.0}),
    (hl.LAND, (0, 0.25, 3.0), "land", {"mask": 0, "height": 0.25, "yaw": 0.0, "duration": 3.0}),
    (hl.TAKEOFF_2, (1, 0.5, 1.5, True, 2.0), "takeoff",
     {"mask": 1, "height": 0.5, "yaw": 1.5, "use_current_yaw": True, "duration": 2.0}),
    (hl.LAND_2, (0, 0.0, -1.5, False, 4.0), "land",
     {"mask": 0, "height": 0.0, "yaw": -1.5, "use_current_yaw": False, "duration": 4.0}),
    (hl.TAKEOFF_WITH_VELOCITY, (3, 0.5, True, 0.25, False, 0.75), "takeoff",
     {"mask": 3, "height": 0.5, "relative": True, "yaw": 0.25, "use_current_yaw": False, "velocity": 0.75}),
    (hl.LAND_WITH_VELOCITY, (0, 0.0, False, 0.0, True, 0.5), "land",
     {"mask": 0, "height": 0.0, "relative": False, "yaw": 0.0, "use_current_yaw": True, "velocity": 0.5}),
    (hl.STOP, (4,), "stop", {"mask": 4}),
    (hl.GO_TO, (0, 1, 1.0, 2.0, 0.5, 0.25, 3.0), "go_to",
     {"mask": 0, "relative": 1, "linear": False, "goal": (1.0, 2.0, 0.5), "yaw": 0.25, "duration": 3.0}),
    (hl.GO_TO_2, (5, 0, 1, -1.0, 0.5, 1.5, -0.25, 2.5), "go_to",
     {"mask": 5, "relative": 0, "linear": 1, "goal": (-1.0, 0.5, 1.5), "yaw": -0.25, "duration": 2.5}),
    (hl.SPIRAL, (0, 1, 0, 3.0, 0.5, 0.25, 1.0, 6.0), "spiral",
     {"mask": 0, "sideways": True, "clockwise": False, "angle": 3.0, "r0": 0.5, "rf": 0.25, "ascent": 1.0,
      "duration": 6.0}),
])
def test_each_command_is_one_call_with_its_fields(cmd, fields, op, args):
    port = Port(result=0x1234)
    reply = port.command(cmd, *fields)
    assert port.calls == [(op, args)]
    assert reply == packet(cmd, *fields)[:3].ljust(3, b"\x00") + b"\x34"


def test_a_short_packet_reads_as_zero_padded_and_the_echo_too():
    port = Port()
    port.handle(HEADER, 0, bytes([hl.TAKEOFF, 7]))
    assert port.calls == [("takeoff", {"mask": 7, "height": 0.0, "yaw": 0.0, "duration": 0.0})]
    assert port.replies == [(HEADER, bytes([hl.TAKEOFF, 7, 0, 0]))]


def test_unknown_command_is_enoexec_without_a_call_and_an_empty_packet_gets_no_reply():
    port = Port()
    port.handle(HEADER, 0, bytes([99, 1, 2, 3]))
    port.handle(HEADER, 0, b"")
    assert port.calls == []
    assert port.replies == [(HEADER, bytes([99, 1, 2, hl.ENOEXEC]))]


def test_define_trajectory_fills_a_descriptor_within_the_table_only():
    port = Port()
    assert port.command(hl.DEFINE_TRAJECTORY, 3, LOCATION_MEMORY, TYPE_POLY4D, 66, 2)[3] == 0
    assert port.memory.descriptors == {3: Descriptor(LOCATION_MEMORY, TYPE_POLY4D, 66, 2)}
    assert port.command(hl.DEFINE_TRAJECTORY, MAX_TRAJECTORIES, LOCATION_MEMORY, TYPE_POLY4D, 0, 1)[3] == hl.ENOEXEC
    assert set(port.memory.descriptors) == {3}
    assert port.calls == []


def _poly4d(port: Port, traj_id: int, duration: float) -> None:
    port.memory.write(0, POLY4D_PIECE.pack(*([0.5] * 32 + [duration])))
    port.memory.descriptors[traj_id] = Descriptor(LOCATION_MEMORY, TYPE_POLY4D, 0, 1)


def test_start_trajectory_plays_poly4d_pieces_with_either_layout():
    port = Port()
    _poly4d(port, 2, 1.5)
    # START_TRAJECTORY: mask, relative, reversed, id, time scale
    port.command(hl.START_TRAJECTORY, 1, 1, 1, 2, 2.0)
    # START_TRAJECTORY_2: mask, relative, relative yaw, reversed, id, time scale
    port.command(hl.START_TRAJECTORY_2, 0, 1, 1, 0, 2, 0.5)
    port.command(hl.START_TRAJECTORY_2, 0, 0, 1, 0, 2, 1.0)     # relative yaw only with relative
    expected = [(1, 2.0, True, True, False), (0, 0.5, False, True, True), (0, 1.0, False, False, False)]
    assert [(a["mask"], a["timescale"], a["reversed"], a["relative"], a["relative_yaw"])
            for _, a in port.calls] == expected
    for op, args in port.calls:
        assert op == "start_trajectory"
        assert [d for d, _ in args["pieces"]] == [1.5]


def test_start_of_an_undefined_trajectory_is_enoexec():
    port = Port()
    assert port.command(hl.START_TRAJECTORY, 0, 0, 0, 5, 1.0)[3] == hl.ENOEXEC
    assert port.calls == []


def _compressed(port: Port, traj_id: int) -> None:
    """A start point and one constant segment of 1 s, then the end (duration 0)."""
    data = COMPRESSED_START.pack(1000, 0, 500, 0) + COMPRESSED_HEADER.pack(0, 1000) + COMPRESSED_HEADER.pack(0, 0)
    port.memory.write(100, data)
    port.memory.descriptors[traj_id] = Descriptor(LOCATION_MEMORY, TYPE_COMPRESSED, 100, 1)


def test_compressed_trajectory_plays_forwards_at_its_own_speed_without_relative_yaw():
    port = Port()
    _compressed(port, 4)
    port.command(hl.START_TRAJECTORY_2, 1, 1, 1, 0, 4, 1.0)
    ((op, args),) = port.calls
    assert op == "start_trajectory"
    assert (args["timescale"], args["reversed"], args["relative"], args["relative_yaw"]) == (1.0, False, True, False)
    assert args["pieces"] and args["pieces"][0][0] == pytest.approx(1.0)
    assert args["pieces"][0][1][0][0] == pytest.approx(1.0)      # x of the start point, m


@pytest.mark.parametrize("timescale, reversed_", [(2.0, 0), (1.0, 1)])
def test_compressed_trajectory_scaled_or_reversed_starts_nothing(timescale, reversed_):
    port = Port()
    _compressed(port, 4)
    port.command(hl.START_TRAJECTORY, 0, 0, reversed_, 4, timescale)
    assert port.calls == [("start_trajectory", {"mask": 0, "pieces": []})]
