"""CPU priority of the simulated world's process.

The simulated world stands for the physical one, which never waits for a CPU. Starved on a busy
machine, it stalls: its radio answers and motion capture stop while the host's nodes and clocks run
on, and the host then sees a lost pose or a lost link that no real room would produce. Where the
system allows it (root, or CAP_SYS_NICE), the world's process takes a higher priority than the
host's nodes; where it does not, the world runs at normal priority and says so.
"""
from __future__ import annotations

import os
from typing import Optional

#: Niceness steps the world's process is raised by, by default (lower niceness: more CPU share when
#: the machine is busy; 5 steps give about three times a normal process's share).
DEFAULT_PRIORITY_BOOST = 5


def raise_priority(steps: int) -> Optional[str]:
    """Lower the niceness of every thread of this process by ``steps`` (on Linux niceness belongs to
    each thread, and threads started later inherit their creator's). None when done (or ``steps``
    is 0), else why not."""
    if steps < 0:
        raise ValueError("priority boost must be >= 0 niceness steps, got %r" % (steps,))
    if steps == 0:
        return None
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        tids = [0]                      # no /proc: the calling thread only
    try:
        for tid in tids:
            os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) - steps)
    except ProcessLookupError:
        pass                            # a thread that ended meanwhile
    except OSError as e:
        return "%s (raising a priority needs root or CAP_SYS_NICE)" % (e.strerror or e)
    return None
