"""sim.priority: the world's process raises every thread's priority where the system allows it."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from crazyflie_driver.sim.priority import raise_priority

CHILD = """
import json, os, threading
from crazyflie_driver.sim.priority import raise_priority
ready, done = threading.Event(), threading.Event()
def worker():
    ready.set(); done.wait(5.0)
t = threading.Thread(target=worker); t.start(); ready.wait(5.0)
nice = lambda: {int(x): os.getpriority(os.PRIO_PROCESS, int(x)) for x in os.listdir("/proc/self/task")}
before = nice()
refused = raise_priority(3)
after = nice()
later = []
def late():
    later.append(os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))
u = threading.Thread(target=late); u.start(); u.join()
done.set(); t.join()
print(json.dumps({"before": before, "after": after, "refused": refused, "later": later,
                  "main": threading.get_native_id()}))
"""


def test_zero_does_nothing_and_a_negative_boost_is_refused():
    assert raise_priority(0) is None
    with pytest.raises(ValueError, match=">= 0"):
        raise_priority(-1)


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="needs Linux /proc")
def test_every_thread_and_the_threads_started_later_get_the_boost_or_the_reason_why_not():
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=30,
                         env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert len(r["before"]) >= 2                         # the main thread and the worker
    if r["refused"] is None:
        assert {t: r["before"][t] - 3 for t in r["before"]} == r["after"]
        assert r["later"] == [r["after"][str(r["main"])]]     # a thread started later inherits it
    else:
        assert "CAP_SYS_NICE" in r["refused"] and r["after"] == r["before"]
