"""The nRF51 side of the simulated Crazyflie's radio: safelink, empty acks, side-channel commands.

Faithful to the nRF firmware (docs/protocol.md, "Safelink, empty acks and RSSI"): the STM releases at most one
downlink packet per uplink packet, the downlink rides in the ack, and with safelink the sequence bits make duplicates
harmless (an uplink seen twice is delivered once; an ack lost in the air is sent again).

Like the real radio, the ack payload is chosen before the uplink reaches the STM, so the answer to a
request arrives in the ack of a later packet (the host polls with null packets to fetch it).
"""
from __future__ import annotations

from typing import Callable, Optional

from crazyflie_driver.crtp.nrf_system import TARGET_NRF

NULL_MASK = 0xF3
SAFELINK_CMD = 0x05
RADIO_CTRL_CMD = 0x03



class NrfLink:
    """Radio link state of one Crazyflie.

    ``deliver(bytes)`` hands a CRTP packet to the STM; ``next_downlink()`` pops the next queued
    downlink packet (or None); ``rssi()`` is the uplink RSSI in -dBm (positive, as the nRF reports it);
    ``system(command)`` performs an nRF system command (its bytes after the 0xFE target).
    """

    def __init__(self, deliver: Callable[[bytes], None], next_downlink: Callable[[], Optional[bytes]],
                 rssi: Callable[[], int], rssi_in_empty_ack: bool,
                 system: Callable[[bytes], None] = lambda cmd: None) -> None:
        self._deliver = deliver
        self._next_downlink = next_downlink
        self._rssi = rssi
        self._rssi_in_empty_ack = rssi_in_empty_ack
        self._system = system
        self.reset()

    def reset(self) -> None:
        self.safelink = False
        self.curr_up = 1
        self.curr_down = 1
        self.last_ack = b""
        self.duplicates = 0

    def empty_ack(self) -> bytes:
        header = NULL_MASK | (self.curr_down << 2)
        if self._rssi_in_empty_ack:
            return bytes([header, 0x01, max(0, min(255, int(self._rssi())))])
        return bytes([header])

    def handle(self, data: bytes, ack_requested: bool = True) -> bytes:
        """One uplink packet in, the ack payload out (never raises on malformed input)."""
        if not data:
            return self.empty_ack() if ack_requested else b""
        header = data[0]
        is_null = (header & NULL_MASK) == NULL_MASK
        if is_null and len(data) > 1:
            side = self._side_channel(data)
            if side is not None:
                return side
        if not ack_requested:  # broadcast / no-ack: no sequence handling, nothing goes down
            if not is_null:
                self._deliver(bytes(data))
            return b""
        if self.safelink:
            if (header >> 3) & 1 != self.curr_up:
                self.curr_up ^= 1
                deliver = True
            else:
                deliver = False
                self.duplicates += 1
            if (header >> 2) & 1 != self.curr_down:
                self.curr_down ^= 1
                ack = self._take_downlink()
            else:
                ack = self.last_ack or self.empty_ack()
        else:
            deliver = True
            self.curr_down ^= 1
            ack = self._take_downlink()
        self.last_ack = ack
        if deliver and not is_null:
            self._deliver(bytes(data))
        return ack

    def _take_downlink(self) -> bytes:
        packet = self._next_downlink()
        if not packet:
            return self.empty_ack()
        return bytes([(packet[0] & NULL_MASK) | (self.curr_down << 2)]) + packet[1:]

    def _side_channel(self, data: bytes) -> Optional[bytes]:
        """nRF commands carried by null packets; None means 'not a side-channel command'."""
        cmd = data[1]
        if cmd == SAFELINK_CMD:
            if len(data) != 3:
                return None
            self.safelink = data[2] != 0
            self.curr_up = 1
            self.curr_down = 1
            self.last_ack = b""
            return bytes(data[:3])
        if cmd == RADIO_CTRL_CMD:
            # channel / datarate / power changes are acknowledged; the simulated air does not move
            # the Crazyflie (the world server re-registers it if asked to)
            return self.empty_ack()
        if cmd == TARGET_NRF and len(data) > 2:
            self._system(bytes(data[2:]))
            return self.empty_ack()
        if 0x80 <= cmd <= 0x8F:  # peer-to-peer
            return b""
        return None
