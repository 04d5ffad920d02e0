"""ros_signals: Ctrl-C stops a node even in the middle of a call to the ROS master.

A child process initialised with ``ros_signals.init_node`` reads a parameter from a real
rosmaster in a tight loop, so a SIGINT almost always arrives inside an XML-RPC call; it must
shut down cleanly within a few seconds, every time. (With rospy's own handler the same loop
hung in 6 of 6 tries: the handler waits for the lock of the call it interrupted.) Also: a
second signal exits at once, and publishing while rospy closes the topics is not an error.
"""
from __future__ import annotations

import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time
import xmlrpc.client

import pytest

from support.ports import free_port

pytest.importorskip("rospy")
if shutil.which("rosmaster") is None:
    pytest.skip("rosmaster is not installed", allow_module_level=True)

SRC = pathlib.Path(__file__).resolve().parents[3] / "src"
CHILD = r"""
import rospy
from crazyflie_driver.nodes.ros_signals import init_node
init_node("signal_probe", anonymous=True)
print("ready", flush=True)
calls = 0
while not rospy.is_shutdown():
    try:
        rospy.get_param("/signal_probe_value", 0)
    except Exception:          # the master connection closing under us at shutdown
        break
    calls += 1
print("clean exit after %d master calls" % calls, flush=True)
"""


IN_WINDOW = r"""
import rospy
from std_msgs.msg import Int32
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down, shutting_down
init_node("window_probe", anonymous=True)
pub = rospy.Publisher("window_probe", Int32, queue_size=10)
seen = []

def in_window(reason):
    # added after init_node, so rospy runs it after closing every topic, before is_shutdown()
    seen.append("is_shutdown=%s shutting_down=%s" % (rospy.is_shutdown(), shutting_down()))
    seen.append("helper=%s" % publish_unless_shutting_down(pub, Int32(1)))
    try:
        pub.publish(Int32(2))
        seen.append("plain=ok")
    except rospy.ROSException as e:
        seen.append("plain=%s" % e)

rospy.core.add_preshutdown_hook(in_window)
print("ready", flush=True)
rospy.spin()
print(" | ".join(seen), flush=True)
"""


def start_child(code: str, master_uri: str) -> subprocess.Popen:
    """A Python child running ``code`` against ``master_uri``; its first line must be 'ready'."""
    env = dict(os.environ, ROS_MASTER_URI=master_uri,
               PYTHONPATH=os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]),
               ROS_LOG_DIR=os.environ.get("ROS_LOG_DIR", "/tmp"))
    child = subprocess.Popen([sys.executable, "-c", code], env=env, text=True,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    line = child.stdout.readline().strip()
    if line != "ready":
        child.kill()
        rest, _ = child.communicate()
        pytest.fail("the child node did not start:\n%s%s" % (line, rest))
    return child


@pytest.fixture(scope="module")
def master_uri():
    port = free_port()
    uri = "http://127.0.0.1:%d" % port
    proc = subprocess.Popen(["rosmaster", "--core", "-p", str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 15.0
    while True:
        try:
            xmlrpc.client.ServerProxy(uri).getSystemState("/test")
            break
        except OSError:
            if time.monotonic() > deadline:
                proc.kill()
                pytest.fail("rosmaster did not come up on port %d" % port)
            time.sleep(0.1)
    yield uri
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(10.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_master_calls_shuts_the_node_down(master_uri, signum):
    for attempt in range(5):
        child = start_child(CHILD, master_uri)
        try:
            time.sleep(0.2)                   # well inside the loop of master calls
            child.send_signal(signum)
            out, _ = child.communicate(timeout=5.0)
        except subprocess.TimeoutExpired:
            child.kill()
            out, _ = child.communicate()
            pytest.fail("attempt %d: the node hung after signal %d:\n%s" % (attempt, signum, out))
        assert child.returncode == 0, out
        assert "clean exit after" in out, out
        calls = int(out.split("clean exit after ")[1].split()[0])
        assert calls > 10, "the child barely called the master (%d calls): not a real check" % calls


def test_a_second_signal_exits_at_once(master_uri):
    """roslaunch escalates to SIGTERM when SIGINT did not stop a node: that must end it."""
    child_code = CHILD.replace("calls = 0", "import time\ncalls = 0\nrospy.on_shutdown(lambda: time.sleep(60))")
    child = start_child(child_code, master_uri)
    try:
        child.send_signal(signal.SIGINT)      # its shutdown hook now blocks for a minute
        time.sleep(0.5)
        assert child.poll() is None, "a shutdown hook of 60 s cannot have finished"
        child.send_signal(signal.SIGTERM)
        child.wait(5.0)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == 128 + signal.SIGTERM


def test_publishing_while_rospy_closes_the_topics_is_not_an_error(master_uri):
    """Between closing the topics and is_shutdown() turning true, publish must stay quiet."""
    child = start_child(IN_WINDOW, master_uri)
    try:
        child.send_signal(signal.SIGINT)
        out, _ = child.communicate(timeout=5.0)
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert child.returncode == 0, out
    # the probe really ran inside the window: rospy itself refuses a plain publish there
    assert "is_shutdown=False shutting_down=True" in out, out
    assert "plain=publish() to a closed topic" in out, out
    assert "helper=False" in out, out


SLOW_SHUTDOWN = r"""
import time
import rospy
from crazyflie_driver.nodes.ros_signals import init_node
init_node("slow_shutdown_probe", anonymous=True)

def slow_step(reason):
    # one of rospy's own shutdown steps (they run after is_shutdown() turned true), taking as long
    # as closing connections and unregistering from a busy master can
    time.sleep(1.0)
    print("shutdown finished", flush=True)

rospy.core.add_shutdown_hook(slow_step)
print("ready", flush=True)
while not rospy.is_shutdown():      # the demo's loop: it returns as soon as the flag rises
    time.sleep(0.01)
print("main returned", flush=True)
"""


def test_the_process_does_not_finalise_in_the_middle_of_rospys_shutdown(master_uri):
    """A main loop that polls is_shutdown() returns while rospy still closes and unregisters in the
    signal's thread; the interpreter must not finalise (freezing that thread with its locks) first."""
    child = start_child(SLOW_SHUTDOWN, master_uri)
    try:
        child.send_signal(signal.SIGINT)
        out, _ = child.communicate(timeout=8.0)
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert "main returned" in out, out
    assert "shutdown finished" in out, "rospy's shutdown was cut off by the exit:\n" + out
    assert child.returncode == 0, out



HELD_EXIT = r"""
import threading
import time
import rospy
from crazyflie_driver.nodes.ros_signals import init_node
init_node("held_exit_probe", anonymous=True)
print("ready", flush=True)
rospy.spin()

def waits_for_a_peer():
    time.sleep(60)       # a library's non-daemon thread waiting for a peer that never answers

threading.Thread(target=waits_for_a_peer, name="waits_for_a_peer").start()
print("spin returned", flush=True)
"""


def test_a_thread_left_waiting_cannot_hold_the_exit(master_uri):
    """Once rospy's shutdown has ended the node ends within EXIT_GRACE_S, whatever thread the
    interpreter would wait for; the stacks printed say where it was held."""
    from crazyflie_driver.nodes.ros_signals import EXIT_GRACE_S
    child = start_child(HELD_EXIT, master_uri)
    try:
        t0 = time.monotonic()
        child.send_signal(signal.SIGINT)
        out, _ = child.communicate(timeout=EXIT_GRACE_S + 10.0)
        took = time.monotonic() - t0
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert "spin returned" in out, out
    assert took < EXIT_GRACE_S + 3.0, "took %.1f s:\n%s" % (took, out)
    assert child.returncode == 1 and "waits_for_a_peer" in out, out


def test_rospys_read_on_a_socket_it_closed_is_not_an_error():
    """rospy's receive loop reading a socket that rospy closed under it (a publisher leaving)
    logs a traceback as ERROR; with the filter init_node installs it is DEBUG. Any other error
    of rospy's stays an ERROR."""
    import logging
    import socket

    from rospy.impl.tcpros_base import TCPROSTransport, TCPROSTransportProtocol, TransportException
    from std_msgs.msg import String

    from crazyflie_driver.nodes.ros_signals import RECEIVE_LOGGER, ClosedSocketRace

    records = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(record)

    logger = logging.getLogger(RECEIVE_LOGGER)
    race, keep = ClosedSocketRace(), Keep(logging.DEBUG)
    logger.addFilter(race)
    logger.addHandler(keep)
    old_level = logger.level
    logger.setLevel(logging.DEBUG)
    try:
        transport = TCPROSTransport(TCPROSTransportProtocol("/probe", String), "/probe")
        sock = socket.socket()
        sock.close()                    # what rospy's removal of the connection does
        transport.socket = sock
        with pytest.raises(TransportException):
            transport.receive_once()
        logger.error("Traceback (most recent call last):\nValueError: something else")
    finally:
        logger.removeFilter(race)
        logger.removeHandler(keep)
        logger.setLevel(old_level)
    closed = [r for r in records if "receive_once" in r.getMessage()]
    assert len(closed) == 1 and closed[0].levelno == logging.DEBUG, [r.getMessage() for r in records]
    other = [r for r in records if "something else" in r.getMessage()]
    assert len(other) == 1 and other[0].levelno == logging.ERROR
