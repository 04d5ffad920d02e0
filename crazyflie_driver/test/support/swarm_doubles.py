"""Doubles for ports 4, 8 and 9: a Crazyflie answering with the firmware's reply layouts, and a
link offering ``send``/``request`` without a radio."""
from __future__ import annotations

import errno
import struct

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import LinkTimeout
from crazyflie_driver.protocol.memory import TYPE_TRAJECTORY

TRAJ_MEM_SIZE = 4096


class FirmwareDouble:
    """Answers ports 4, 8 and 9 with the firmware's reply layouts; keeps the trajectory memory."""

    def __init__(self, hl_result=0, write_status=0):
        self.memory = bytearray(TRAJ_MEM_SIZE)
        self.hl_result = hl_result
        self.write_status = write_status
        self.received = []
        self.armed = False

    def handle(self, p: CRTPPacket):
        self.received.append(p)
        d = p.data
        if p.port == 4 and p.channel == 0:
            if d[:1] == b"\x01":
                return [CRTPPacket(4, 0, bytes([1, 2]))]
            if d[:1] == b"\x02":
                kind, size = (0x01, 112) if d[1] == 0 else (TYPE_TRAJECTORY, TRAJ_MEM_SIZE)
                return [CRTPPacket(4, 0, struct.pack("<BBBI8s", 2, d[1], kind, size, b"\x00" * 8))]
        if p.port == 4 and p.channel == 2:
            mem_id, addr = struct.unpack_from("<BI", d)
            ok = mem_id == 1 and addr + len(d) - 5 <= TRAJ_MEM_SIZE and self.write_status == 0
            if ok:
                self.memory[addr:addr + len(d) - 5] = d[5:]
            return [CRTPPacket(4, 2, d[:5] + bytes([0 if ok else errno.EIO]))]
        if p.port == 8:
            return [CRTPPacket(8, p.channel, bytes([d[0], d[1] if len(d) > 1 else 0, d[2] if len(d) > 2 else 0,
                                                   self.hl_result]))]
        if p.port == 9 and p.channel == 1 and d[0] == 1:
            self.armed = bool(d[1])
            return [CRTPPacket(9, 1, bytes([0x81, 1, self.armed]))]
        if p.port == 9 and p.channel == 0 and d[0] == 0x0C:
            return [CRTPPacket(9, 0, struct.pack("<BH", 0x8C, 0b1_0000_1001))]
        return []


class LinkDouble:
    """send/request as the radio link offers them, without a radio; records every packet."""

    def __init__(self, firmware):
        self.firmware = firmware
        self.sent = []
        self.resend_intervals = []

    def send(self, packet):
        self.sent.append(packet)
        self.firmware.handle(packet)
        return True

    def request(self, packet, match, timeout=1.0, resend_interval=0.2, what=""):
        self.sent.append(packet)
        self.resend_intervals.append(resend_interval)
        for reply in self.firmware.handle(packet):
            if match(reply):
                return reply
        raise LinkTimeout("no answer to %s" % what)
