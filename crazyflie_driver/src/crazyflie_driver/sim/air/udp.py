"""UDP endpoints for cflib: ``udp://127.0.0.1:19850+i`` serves the i-th simulated Crazyflie.

cflib's UDP driver (docs/protocol.md, "The UDP link") sends one datagram per CRTP packet (``[header, payload]``) from a
``connect()``ed socket and scans by sending a lone 0xFF to ports 19850..19859. So an endpoint replies
from the port it listens on to the client's address, answers the probe at once, and pushes every
packet the Crazyflie queues (replies, console text, log data) to the last client it heard from.
"""
from __future__ import annotations

import logging
import os
import select
import socket
import threading
from typing import Optional, Tuple

_log = logging.getLogger(__name__)
PROBE = b"\xff"


class UdpEndpoint:
    """One loopback UDP port in front of one SimulatedCrazyflie."""

    def __init__(self, crazyflie, port: int, host: str = "127.0.0.1") -> None:
        if not host.startswith("127."):
            raise ValueError("UDP endpoints are loopback only, got host %r" % (host,))
        self.crazyflie = crazyflie
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError as e:
            self.sock.close()
            raise ValueError("cannot open UDP endpoint %s:%d: %s" % (host, port, e.strerror or e)) from None
        self.sock.setblocking(False)
        self.host, self.port = self.sock.getsockname()[:2]
        self.client: Optional[Tuple[str, int]] = None
        self.datagrams_in = 0
        self.datagrams_out = 0
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    @property
    def uri(self) -> str:
        return "udp://%s:%d" % (self.host, self.port)

    def start(self) -> None:
        self.crazyflie.set_tx_listener(self._wake)
        self._thread = threading.Thread(target=self._run, name="udp-%d" % self.port, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._wake()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        self.crazyflie.set_tx_listener(None)
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
        self.sock.close()

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"x")
        except (BlockingIOError, OSError):
            pass  # a wake-up is already pending (or we are closing)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                readable, _, _ = select.select([self.sock, self._wake_r], [], [], 0.5)
            except (OSError, ValueError):
                break
            if self._wake_r in readable:
                try:
                    while os.read(self._wake_r, 4096):
                        pass
                except (BlockingIOError, OSError):
                    pass
            if self.sock in readable:
                self._receive()
            self._flush()

    def _receive(self) -> None:
        for _ in range(64):  # drain what is there without starving the flush
            try:
                data, addr = self.sock.recvfrom(1024)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return  # e.g. ICMP port unreachable reported for an earlier send
            self.datagrams_in += 1
            self.client = addr
            if data == PROBE:
                self._sendto(PROBE, addr)   # a scan probe: any answer will do
            elif data:
                self.crazyflie.handle_crtp(data)

    def _flush(self) -> None:
        if self.client is None:
            return  # text printed before a host connects waits in the TX queue
        while True:
            # None also when a radio host came after the UDP client: the queue is the radio's now.
            packet = self.crazyflie.pop_outgoing(packet_link=True)
            if packet is None:
                return
            self._sendto(packet, self.client)

    def _sendto(self, data: bytes, addr) -> None:
        try:
            self.sock.sendto(data, addr)
            self.datagrams_out += 1
        except OSError as e:
            _log.debug("UDP send to %s failed: %s", addr, e)
