"""Ctrl-C handling for the stack's rospy nodes, so that a signal can never hang a node.

rospy's own SIGINT handler runs the whole shutdown inside the main thread, and that shutdown
calls the master to unregister. When the signal lands while the main thread is itself in a call
to the master (creating a subscriber, reading a parameter), the handler waits for the master
connection's lock that its own thread holds: the node hangs, ignores SIGTERM too, and is left
running when roslaunch gives up on it. Here the handler only records the signal and a watcher
thread runs ``rospy.signal_shutdown``, so the interrupted call finishes first. A second signal
(roslaunch escalates with SIGTERM after 15 s) exits at once.
"""
from __future__ import annotations

import os
import signal
import threading
from typing import Any

import rospy

HANDLED = (signal.SIGINT, signal.SIGTERM)


class ShutdownOnSignal:
    """Records the first signal for the watcher thread; exits the process on the second."""

    def __init__(self) -> None:
        self._received = threading.Event()
        self._signum = 0
        self._count = 0

    def handle(self, signum: int, _frame: Any) -> None:
        self._count += 1
        if self._count > 1:
            os._exit(128 + signum)        # shutdown already running and stuck: do not wait for it
        self._signum = signum
        self._received.set()

    def watch(self) -> None:
        self._received.wait()
        rospy.signal_shutdown("signal %d" % self._signum)


def init_node(name: str, **kwargs: Any) -> None:
    """``rospy.init_node`` with this module's signal handling instead of rospy's."""
    shutdown = ShutdownOnSignal()
    for signum in HANDLED:
        signal.signal(signum, shutdown.handle)
    rospy.init_node(name, disable_signals=True, **kwargs)
    threading.Thread(target=shutdown.watch, name="shutdown-on-signal", daemon=True).start()


def shutting_down() -> bool:
    """True from the moment a shutdown begins.

    ``rospy.is_shutdown()`` turns true only after rospy has closed every topic, so a loop or
    callback that publishes in between would hit "publish() to a closed topic"; this does not.
    """
    return bool(rospy.core.is_shutdown_requested())


def publish_unless_shutting_down(publisher: "rospy.Publisher", msg: Any) -> bool:
    """Publish ``msg``; False instead of an error when a shutdown has closed the topic."""
    try:
        publisher.publish(msg)
        return True
    except rospy.ROSException:
        if shutting_down():
            return False
        raise
