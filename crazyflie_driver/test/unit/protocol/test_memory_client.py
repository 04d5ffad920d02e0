"""MemoryClient's reads and writes over a scripted request: the chunks, the answer each one waits for,
and a refusal named with what was refused."""
from __future__ import annotations

import struct

import pytest

from crazyflie_driver.crtp.packet import PORT_MEM, CRTPPacket
from crazyflie_driver.errors import CommandRejected
from crazyflie_driver.protocol.memory import CH_READ, CH_WRITE, MemoryClient

ADDRESS = struct.Struct("<BI")       # memory id, address: the head of every read and write and their answers


class ScriptedMemory:
    """Answers reads and writes of one memory as the firmware does (the request's head, a status byte,
    the bytes read); from address ``refuse_from`` on the status is 5 (refused)."""

    def __init__(self, size: int = 100, refuse_from: int = 1 << 30) -> None:
        self.data = bytearray(size)
        self.refuse_from = refuse_from
        self.asked = []

    def __call__(self, packet: CRTPPacket, match, timeout: float, what: str) -> CRTPPacket:
        self.asked.append(what)
        mem_id, addr = ADDRESS.unpack_from(packet.data)
        status = 0 if addr < self.refuse_from else 5
        if packet.channel == CH_WRITE:
            body = packet.data[ADDRESS.size:]
            if status == 0:
                self.data[addr:addr + len(body)] = body
            answer = b""
        else:
            answer = bytes(self.data[addr:addr + packet.data[ADDRESS.size]]) if status == 0 else b""
        reply = CRTPPacket(PORT_MEM, packet.channel, packet.data[:ADDRESS.size] + bytes([status]) + answer)
        other_address = CRTPPacket(PORT_MEM, packet.channel, ADDRESS.pack(mem_id, addr + 1) + b"\x00" + answer)
        other_channel = CRTPPacket(PORT_MEM, CH_READ + CH_WRITE - packet.channel, reply.data)
        assert match(reply) and not match(other_address) and not match(other_channel)
        return reply


def test_a_write_goes_in_chunks_each_waiting_for_its_own_answer():
    memory = ScriptedMemory()
    MemoryClient(memory, label="cf1").write(1, 10, bytes(range(1, 61)))
    assert memory.data[10:70] == bytes(range(1, 61))
    assert memory.asked == ["memory 1 write at 10 (4:2)", "memory 1 write at 34 (4:2)", "memory 1 write at 58 (4:2)"]


def test_a_read_goes_in_chunks_and_returns_the_bytes():
    memory = ScriptedMemory()
    memory.data[:] = bytes(range(100))
    assert MemoryClient(memory, label="cf1").read(1, 5, 30) == bytes(range(5, 35))
    assert memory.asked == ["memory 1 read at 5 (4:1)", "memory 1 read at 29 (4:1)"]


@pytest.mark.parametrize("act, says", [
    (lambda client: client.write(1, 10, bytes(60)), "cf1: memory 1 refused 24 bytes at address 34 (status 5)"),
    (lambda client: client.read(1, 5, 30), "cf1: memory 1 refused a read of 6 bytes at address 29 (status 5)"),
])
def test_a_refused_chunk_is_named(act, says):
    with pytest.raises(CommandRejected) as info:
        act(MemoryClient(ScriptedMemory(refuse_from=20), label="cf1"))
    assert str(info.value) == says
