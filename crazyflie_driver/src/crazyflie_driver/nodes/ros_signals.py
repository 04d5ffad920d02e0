"""Ctrl-C handling for the stack's rospy nodes, so that a signal can never hang a node.

rospy's own SIGINT handler runs the whole shutdown inside the main thread, and that shutdown
calls the master to unregister. When the signal lands while the main thread is itself in a call
to the master (creating a subscriber, reading a parameter), the handler waits for the master
connection's lock that its own thread holds: the node hangs, ignores SIGTERM too, and is left
running when roslaunch gives up on it. Here the handler only records the signal and a watcher
thread runs ``rospy.signal_shutdown``, so the interrupted call finishes first. A second signal
(roslaunch escalates with SIGTERM after 15 s) exits at once.

Two more guards keep the exit itself prompt:

* rospy raises its shutdown flag part-way through ``signal_shutdown``; a main loop that polls it
  (``while not rospy.is_shutdown()``) then returns and the interpreter starts to finalise while the
  watcher is still closing connections and unregistering. Daemon threads stop where they are once
  finalisation begins, so rospy's shutdown was cut off mid-way with its locks held. At exit the
  process therefore waits (up to SHUTDOWN_WAIT_S) for that shutdown to end.
* Whatever still holds the process after that shutdown (a library thread that is not a daemon
  and waits on a peer, or a lock left held in finalisation) must not hold it until roslaunch's
  SIGTERM 15 s later: once the shutdown has ended the process has EXIT_GRACE_S to end; past that,
  the kernel's alarm (SIGALRM) runs a handler in the main thread that prints every thread's stack
  (where it was held) and ends the process with status 1.

One log record of rospy's own is demoted: when a publisher leaves (its node shuts down first on a
Ctrl-C that reaches every node), rospy closes the subscriber's socket from the master's callback
thread while that connection's receive thread starts its next read, and logs the read's
``OSError: [Errno 9] Bad file descriptor`` as an ERROR traceback on ``rospy.internal``. The
connection was being removed anyway; nothing is lost. :class:`ClosedSocketRace` makes it DEBUG.
"""
from __future__ import annotations

import atexit
import logging
import math
import os
import signal
import sys
import threading
import traceback
from typing import Any

import rospy

HANDLED = (signal.SIGINT, signal.SIGTERM)
SHUTDOWN_WAIT_S = 10.0      # at exit: wait this long for rospy's shutdown still running in the watcher
EXIT_GRACE_S = 5.0          # after rospy's shutdown: the process ends within this, or is ended


class ShutdownOnSignal:
    """Records the first signal for the watcher thread; exits the process on the second."""

    def __init__(self, exit_grace_s: float = EXIT_GRACE_S) -> None:
        self._received = threading.Event()
        self._finished = threading.Event()
        self._signum = 0
        self._count = 0
        self.exit_grace_s = exit_grace_s

    def handle(self, signum: int, _frame: Any) -> None:
        self._count += 1
        if self._count > 1:
            os._exit(128 + signum)        # shutdown already running and stuck: do not wait for it
        self._signum = signum
        self._received.set()

    def watch(self) -> None:
        self._received.wait()
        try:
            rospy.signal_shutdown("signal %d" % self._signum)
        finally:
            self._finished.set()
            self._end_within_grace()

    def wait_for_shutdown(self) -> None:
        """At exit (atexit, before rospy's own handler): let a shutdown begun by a signal finish."""
        if self._received.is_set():
            self._finished.wait(SHUTDOWN_WAIT_S)

    def _end_within_grace(self) -> None:
        if self.exit_grace_s > 0:
            signal.alarm(int(math.ceil(self.exit_grace_s)))

    def on_alarm(self, _signum: int, _frame: Any) -> None:
        """Past the grace: print every thread's stack (where the exit was held) and end with status 1.

        The kernel's alarm and a handler in the main thread, not a timer thread: a thread still
        sleeping while the interpreter finalised crashed the process (SIGSEGV) on busy machines, both
        as faulthandler's C timer and as a Python daemon thread.
        """
        stream = sys.__stderr__
        try:
            if stream is not None:
                names = {t.ident: t.name for t in threading.enumerate()}
                stream.write("node still running %.0f s after its shutdown; its threads:\n" % self.exit_grace_s)
                for ident, frame in sys._current_frames().items():
                    stream.write("Thread %s (%s):\n" % (names.get(ident, "?"), ident))
                    stream.write("".join(traceback.format_stack(frame)))
                stream.flush()
        finally:
            os._exit(1)


class ClosedSocketRace(logging.Filter):
    """Demotes rospy's ERROR for a read on a socket rospy itself just closed to DEBUG.

    rospy logs it as the bare text of a traceback (no exception object on the record), so its
    text is all there is to recognise: a read in ``receive_once`` failing with EBADF.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.ERROR and record.name == RECEIVE_LOGGER:
            text = record.getMessage()
            if "in receive_once" in text and text.rstrip().endswith(CLOSED_SOCKET_ERROR):
                record.levelno, record.levelname = logging.DEBUG, "DEBUG"
        return True


RECEIVE_LOGGER = "rospy.internal"               # the logger rospy's TCPROS receive loop writes to
CLOSED_SOCKET_ERROR = "OSError: [Errno 9] Bad file descriptor"


def init_node(name: str, **kwargs: Any) -> None:
    """``rospy.init_node`` with this module's signal handling instead of rospy's."""
    logging.getLogger(RECEIVE_LOGGER).addFilter(ClosedSocketRace())
    shutdown = ShutdownOnSignal()
    for signum in HANDLED:
        signal.signal(signum, shutdown.handle)
    signal.signal(signal.SIGALRM, shutdown.on_alarm)     # armed only once rospy's shutdown has ended
    rospy.init_node(name, disable_signals=True, **kwargs)
    # registered after rospy's (rospy.core registers at import), so it runs first: atexit is LIFO
    atexit.register(shutdown.wait_for_shutdown)
    threading.Thread(target=shutdown.watch, name="shutdown-on-signal", daemon=True).start()


def shutting_down() -> bool:
    """True from the moment a shutdown begins.

    ``rospy.is_shutdown()`` turns true only after rospy has closed every topic, so a loop or
    callback that publishes in between would hit "publish() to a closed topic"; this does not.
    """
    return bool(rospy.core.is_shutdown_requested())


def publish_unless_shutting_down(publisher: rospy.Publisher, msg: Any) -> bool:
    """Publish ``msg``; False instead of an error when a shutdown has closed the topic."""
    try:
        publisher.publish(msg)
        return True
    except rospy.ROSException:
        if shutting_down():
            return False
        raise


class RosLogHandler(logging.Handler):
    """Sends Python log records to rosout at their level (the library's, a ROS-free module's)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record)
        except Exception:
            text = record.getMessage()
        if record.levelno >= logging.ERROR:
            rospy.logerr(text)
        elif record.levelno >= logging.WARNING:
            rospy.logwarn(text)
        elif record.levelno >= logging.INFO:
            rospy.loginfo(text)
        else:
            rospy.logdebug(text)
