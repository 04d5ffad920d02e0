"""When a Crazyflie of a swarm must land by itself: its pose went stale, or its radio link was lost.

The onboard estimator keeps flying on its inertial sensors when motion capture stops, and nothing in
the firmware notices (it drifts away). So the server watches every Crazyflie: a pose older than
``stale_after`` s makes it *stale* (named in the log and on /diagnostics); still stale (or still without
its link) ``hold`` s later, it is told to land. A pose that comes back is reported; a Crazyflie told to
land is not sent up again. Pure bookkeeping on times the caller gives (one monotonic clock).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Iterable, List, Optional

#: Defaults: a pose older than this (s) is stale (20 frames of a 100 Hz system; a busy host stalls ~0.1 s) ...
DEFAULT_STALE_AFTER_S = 0.2
#: ... and a Crazyflie stale (or without link) this much longer (s) is landed.
DEFAULT_HOLD_S = 0.5

OK, STALE, LANDING, NO_POSE_YET = "ok", "stale", "landing", "no pose yet"


@dataclass
class WatchEvent:
    name: str
    kind: str           # "stale", "fresh", "land", "link lost", "link restored"
    age: float          # s since the last pose (or since the link was lost)
    reason: str = ""


@dataclass
class _Watched:
    last_pose: Optional[float] = None
    stale_since: Optional[float] = None
    link_lost_since: Optional[float] = None
    land_sent: bool = False
    land_reason: str = ""


class SwarmWatch:
    """Per Crazyflie: last pose time, link state, and whether it was told to land."""

    def __init__(self, names: Iterable[str], stale_after: float = DEFAULT_STALE_AFTER_S,
                 hold: float = DEFAULT_HOLD_S) -> None:
        if not stale_after > 0 or not hold >= 0:
            raise ValueError("stale_after must be > 0 s and hold >= 0 s, got %r and %r" % (stale_after, hold))
        self.stale_after = float(stale_after)
        self.hold = float(hold)
        self._cfs: Dict[str, _Watched] = {n: _Watched() for n in names}

    def pose_seen(self, name: str, now: float) -> None:
        w = self._cfs.get(name)
        if w is not None:
            w.last_pose = now

    def link(self, name: str, ok: bool, now: float) -> None:
        w = self._cfs.get(name)
        if w is None:
            return
        if ok:
            w.link_lost_since = None
        elif w.link_lost_since is None:
            w.link_lost_since = now

    def age(self, name: str, now: float) -> float:
        w = self._cfs[name]
        return float("inf") if w.last_pose is None else max(0.0, now - w.last_pose)

    def state(self, name: str, now: float) -> str:
        w = self._cfs[name]
        if w.land_sent:
            return LANDING
        if w.last_pose is None:
            return NO_POSE_YET
        return STALE if w.stale_since is not None else OK

    def landed_for(self, name: str) -> str:
        """Why the Crazyflie was told to land ("" if it was not)."""
        return self._cfs[name].land_reason

    def rearm(self, name: str) -> None:
        """Forget a landing (the Crazyflie is flown again on purpose, e.g. a new takeoff)."""
        w = self._cfs.get(name)
        if w is not None:
            w.land_sent, w.land_reason = False, ""

    def check(self, now: float) -> List[WatchEvent]:
        """Events due now, at most one of each kind per episode."""
        events: List[WatchEvent] = []
        for name, w in self._cfs.items():
            if w.last_pose is not None:
                age = now - w.last_pose
                if age > self.stale_after and w.stale_since is None:
                    w.stale_since = w.last_pose + self.stale_after
                    events.append(WatchEvent(name, "stale", age))
                elif age <= self.stale_after and w.stale_since is not None:
                    w.stale_since = None
                    events.append(WatchEvent(name, "fresh", age))
            if w.land_sent:
                continue
            if w.stale_since is not None and w.last_pose is not None and now - w.stale_since >= self.hold:
                # stale_since is only ever set from a pose's time
                w.land_sent, w.land_reason = True, "no pose for %.2f s" % (now - w.last_pose)
                events.append(WatchEvent(name, "land", now - w.last_pose, w.land_reason))
            elif w.link_lost_since is not None and now - w.link_lost_since >= self.hold:
                w.land_sent, w.land_reason = True, "radio link lost for %.2f s" % (now - w.link_lost_since)
                events.append(WatchEvent(name, "land", now - w.link_lost_since, w.land_reason))
        return events
