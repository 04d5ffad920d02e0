"""A free loopback port for the tests and benchmarks that start a server or a ROS master of their own."""
from __future__ import annotations

import random
import socket

#: Ports handed out here [TCP/UDP port numbers]: above the rostests' fixed ports (19840-19999) and
#: below Linux's ephemeral range (net.ipv4.ip_local_port_range starts at 32768). A port from the
#: ephemeral range, once closed here, can be given by the kernel to any other process binding port 0
#: (every ROS node's XML-RPC and TCPROS servers, in the rostests running beside the unit tests) before
#: the test's own server takes it: the test's clients would then talk to that node, or the test's
#: server find its port taken.
FIRST, LAST = 20000, 32767


def free_port() -> int:
    """A port on 127.0.0.1 that nothing listens on right now, for TCP and UDP alike."""
    for _ in range(200):
        port = random.randint(FIRST, LAST)
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as t, \
                    socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u:
                t.bind(("127.0.0.1", port))
                u.bind(("127.0.0.1", port))
        except OSError:
            continue
        return port
    raise RuntimeError("no free port in %d-%d on 127.0.0.1" % (FIRST, LAST))
