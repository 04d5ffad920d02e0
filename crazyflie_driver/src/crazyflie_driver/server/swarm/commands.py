"""Swarm-wide commands with Crazyswarm's meaning, checked before anything goes out, without ROS.

Takeoff, land, go_to, start_trajectory and stop go to every Crazyflie at once by broadcast on every
radio (``SwarmBroadcaster``), each with a group mask: 0 reaches every Crazyflie, otherwise those whose
group mask (``set_group_mask``) shares a bit with it. go_to and start_trajectory are relative, as
Crazyswarm's: one absolute goal for all would send them to one point. A request that fails its checks
(group mask outside 0..255 or addressing no Crazyflie, NaN, a duration that is not > 0, a land that would
drop a Crazyflie, a trajectory some addressed Crazyflie has not uploaded) raises ``CommandValueError``
naming the fault and sends nothing; so does (``FlightRefused``) a takeoff, go_to or start_trajectory that
would cancel an addressed Crazyflie's landing under way. Emergency goes out by broadcast and by unicast
to every Crazyflie, and never raises.
"""
from __future__ import annotations

import logging
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from crazyflie_driver.crtp.uri import parse_uri
from crazyflie_driver.errors import CrazyflieError, FlightRefused, TrajectoryError, UnknownName
from crazyflie_driver.protocol.checks import finite, positive, positive_duration
from crazyflie_driver.protocol.checks import group_mask as checked_group_mask
from crazyflie_driver.protocol.high_level import in_groups, nobody_addressed
from crazyflie_driver.protocol.param import param_value, set_by_name_packet
from crazyflie_driver.server.param_names import Lookup, param_values, ros_param_name
from crazyflie_driver.server.radio_lanes import RadioLanes
from crazyflie_driver.server.safety import checked_landing

LOG = logging.getLogger("crazyflie_driver.server.swarm")


@dataclass
class SwarmMember:
    """One Crazyflie as the swarm commands see it: its worker (``emergency``, ``update_params``,
    ``cf.high_level.trajectories``) and its onboard commands (``group_mask``, ``low_level_active``,
    ``notify_setpoints_stop``)."""

    name: str
    uri: str
    worker: Any
    onboard: Any


class SwarmCommands:
    """The swarm-wide services behind ``/takeoff``, ``/land``, ``/go_to``, ``/start_trajectory``,
    ``/stop``, ``/emergency``. ``members()`` gives the Crazyflies served now; ``broadcaster`` is a
    ``SwarmBroadcaster`` reaching all of them; ``refusal(member, command)`` why a command must not reach
    that Crazyflie now (its safety monitor's ``refusal``), ``height(member)`` its current height (m) or None."""

    def __init__(self, members: Callable[[], Sequence[SwarmMember]], broadcaster: Any,
                 observe: Optional[Callable[[Sequence[SwarmMember], str, float], None]] = None,
                 refusal: Callable[[SwarmMember, str], Optional[str]] = lambda member, what: None,
                 height: Callable[[SwarmMember], Optional[float]] = lambda member: None) -> None:
        self._members = members
        self.broadcaster = broadcaster
        self._observe = observe     # (targets, command, duration s) after a command went out: the safety monitors
        self._refusal = refusal
        self._height = height
        self._lock = threading.Lock()

    def targets(self, group_mask: int) -> List[SwarmMember]:
        """The Crazyflies ``group_mask`` addresses; CommandValueError when it addresses none (the broadcast
        would go out and do nothing)."""
        mask = checked_group_mask(group_mask)
        members = list(self._members())
        targets = [m for m in members if in_groups(getattr(m.onboard, "group_mask", 0), mask)]
        if not targets:
            masks = sorted(set(getattr(m.onboard, "group_mask", 0) for m in members))
            raise nobody_addressed(mask, "the swarm's Crazyflies have group masks %s" % ", ".join(map(str, masks))
                                   if members else "no Crazyflie is served")
        return targets

    def _check_flight(self, targets: Sequence[SwarmMember], what: str) -> None:
        """FlightRefused, naming each, when ``what`` would cancel an addressed Crazyflie's landing under way."""
        refused = [(m.name, why) for m in targets for why in (self._refusal(m, what),) if why]
        if refused:
            raise FlightRefused("%s refused, nothing sent: %s; leave %s out with a group mask, or wait for the "
                                "landing's end" % (what, "; ".join("%s: %s" % r for r in refused[:3]),
                                                   ", ".join(name for name, _ in refused)))

    def _send(self, targets: Sequence[SwarmMember], broadcast: Callable[[], int], what: str = "",
              duration: float = 0.0) -> int:
        """A Crazyflie whose low-level setpoints hold the priority ignores the high-level commander's
        setpoints: its stream stops, the broadcast goes out (the firmware plans it meanwhile), then
        notify-setpoints-stop (unicast, acknowledged) hands the priority to that plan. In this order
        no tick of an idle planner (its null setpoint stops the motors) falls in between."""
        with self._lock:
            handing = [m for m in targets if m.onboard.low_level_active and not m.worker.emergency_active]
            since = {m.name: m.onboard.stop_stream() for m in handing}
            sent = broadcast()
            for m in handing:
                try:
                    if m.onboard.hand_over(since[m.name]):
                        LOG.warning("%s: a low-level setpoint went out after the %s broadcast and may have "
                                    "stopped its plan: send %s to it again", m.name, what or "command", what)
                except CrazyflieError as e:
                    LOG.warning("%s: %s (the %s broadcast went out)", m.name, e, what or "command")
        if self._observe is not None and what:
            self._observe(targets, what, duration)
        return sent

    def takeoff(self, group_mask: int, height: float, duration_s: float) -> int:
        targets = self.targets(group_mask)
        height, duration = finite("height", height), positive_duration(duration_s)
        self._check_flight(targets, "takeoff")
        return self._send(targets, lambda: self.broadcaster.takeoff(height, duration, group_mask), "takeoff", duration)

    def land(self, group_mask: int, height: float, duration_s: float) -> int:
        targets = self.targets(group_mask)
        for m in targets:       # the per-Crazyflie land's check, with each one's height
            height, duration = checked_landing(height, duration_s, self._height(m), m.name)
        return self._send(targets, lambda: self.broadcaster.land(height, duration, group_mask), "land", duration)

    def stop(self, group_mask: int) -> int:
        targets = self.targets(group_mask)
        return self._send(targets, lambda: self.broadcaster.stop(group_mask), "stop", 0.0)

    def go_to(self, group_mask: int, offset: Sequence[float], yaw: float, duration_s: float) -> int:
        """Every addressed Crazyflie moves by ``offset`` (m) and turns by ``yaw`` (rad)."""
        targets = self.targets(group_mask)
        goal = [finite("goal " + axis, v) for axis, v in zip("xyz", offset)]
        yaw, duration = finite("yaw", yaw), positive_duration(duration_s)
        self._check_flight(targets, "go_to")
        return self._send(targets, lambda: self.broadcaster.go_to(goal, yaw, duration, group_mask), "go_to", duration)

    def start_trajectory(self, group_mask: int, trajectory_id: int, timescale: float, reversed_: bool) -> int:
        """Every addressed Crazyflie flies its own uploaded trajectory from where it is."""
        targets = self.targets(group_mask)
        timescale = positive("timescale", timescale)
        missing = [m.name for m in targets if trajectory_id not in _uploaded(m)]
        if missing:
            raise TrajectoryError("trajectory %r was not uploaded to %s; call their upload_trajectory first"
                                  % (trajectory_id, ", ".join(missing)))
        self._check_flight(targets, "start_trajectory")
        return self._send(targets, lambda: self.broadcaster.start_trajectory(trajectory_id, timescale, reversed_,
                                                                             group_mask), "start_trajectory")

    def emergency(self) -> List[str]:
        """Motors off for every Crazyflie: broadcast e-stop on every radio and each worker's unicast
        emergency, at once. Returns what failed (never raises)."""
        failures: List[str] = []
        members = list(self._members())

        def broadcast() -> None:
            try:
                self.broadcaster.emergency()
            except Exception as e:      # the unicast e-stops still go out
                failures.append("broadcast e-stop: %s" % e)

        thread = threading.Thread(target=broadcast, name="swarm e-stop", daemon=True)
        thread.start()
        if members:
            with ThreadPoolExecutor(max_workers=min(16, len(members))) as pool:
                for m, error in zip(members, pool.map(_emergency_of, members)):
                    if error:
                        failures.append("%s: %s" % (m.name, error))
        thread.join()
        return failures


#: ``/update_params`` of the swarm reads ``<ALL_CFS_NAMESPACE>/<group>/<name>`` first (every Crazyflie).
ALL_CFS_NAMESPACE = "/allcfs"
#: Unicast parameter writes of a swarm-wide ``/update_params`` at once on each radio (acknowledged requests).
PARAM_WRITERS_PER_RADIO = 4


def update_params(members: Sequence[SwarmMember], names: Sequence[str], lookup: Lookup, broadcaster: Any,
                  per_radio: int = PARAM_WRITERS_PER_RADIO) -> Tuple[Dict[str, List[str]], List[str]]:
    """``/update_params`` of the swarm: (``{parameter: [Crazyflies written]}``, errors).

    A value every Crazyflie takes from ``/allcfs`` goes out as one write by name (SET_BY_NAME) broadcast on
    every radio at once, repeated, as swarm servers send it, once each Crazyflie's TOC has it writable with
    one C type and the value converts to it: its answers wait in the transmit queues, which broadcast
    high-level commands fill (every one is answered, and only unicast polls drain them), so waiting for 49
    of them took minutes. The rest (a Crazyflie's own ``/<name>/...`` values, or where the TOC check fails,
    so the unicast names the fault) by acknowledged unicast, the radios in parallel (``RadioLanes``, up to
    ``per_radio`` at once on each). ``lookup`` is asked once per ROS name."""
    lookup = _once_per_name(lookup)
    plans = {m.name: update_param_values(names, m.name, lookup) for m in members}
    errors: List[str] = []
    written: Dict[str, List[str]] = {}
    for full, (ctype_name, value) in _broadcastable(members, names, lookup).items():
        broadcaster.set_param(full, ctype_name, value)
        converted = param_value(full, ctype_name, value)
        for m in members:
            m.worker.param_values[full] = converted
            m.worker.user_params[full] = converted      # set again after a reboot, as a unicast write is
            plans[m.name][0].pop(full, None)
        written[full] = [m.name for m in members]

    def write(m: SwarmMember) -> Tuple[List[str], List[str]]:
        values, lookup_errors = plans[m.name]
        done, write_errors = m.worker.update_params(values) if values else ([], [])
        return done, lookup_errors + ["%s: %s" % (m.name, e) for e in write_errors]

    with RadioLanes(per_radio, "update_params") as lanes:
        results = lanes.map(lambda m: parse_uri(m.uri).index, write, list(members))
    for m, (done, member_errors) in zip(members, results):
        for full in done:
            written.setdefault(full, []).append(m.name)
        errors.extend(member_errors)
    return written, list(dict.fromkeys(errors))       # a bad name once, not once per Crazyflie


def _broadcastable(members: Sequence[SwarmMember], names: Sequence[str], lookup: Lookup) -> Dict[str, Tuple[str,
                                                                                                      Any]]:
    """{"group.name": (C type, value)} of the names every member takes from ``/allcfs`` and can be written by
    one broadcast: in each one's TOC, writable, of one C type, the value converting to it and fitting a packet."""
    out: Dict[str, Tuple[str, Any]] = {}
    if not members:
        return out
    for raw in names:
        try:
            p = ros_param_name(raw)
        except UnknownName:
            continue
        value = lookup(ALL_CFS_NAMESPACE + "/" + p)
        if value is None:
            continue
        full = p.replace("/", ".")
        types = set()
        for m in members:
            toc = getattr(getattr(m.worker.cf, "params", None), "toc", None)
            entry = toc.find(full) if toc is not None else None
            types.add(None if entry is None or entry.readonly else entry.ctype)
        if len(types) != 1 or None in types:
            continue
        ctype_name = types.pop()
        assert ctype_name is not None       # None was excluded above
        try:
            set_by_name_packet(full, ctype_name, value)
        except (ValueError, CrazyflieError):
            continue
        out[full] = (ctype_name, value)
    return out


def _once_per_name(lookup: Lookup) -> Lookup:
    seen: Dict[str, Any] = {}

    def cached(name: str) -> Any:
        if name not in seen:
            seen[name] = lookup(name)
        return seen[name]
    return cached


def update_param_values(names: Sequence[str], cf_name: str, lookup: Lookup) -> Tuple[Dict[str, Any], List[str]]:
    """The values ``/update_params`` writes to one Crazyflie: each ``group/name`` (checked as every service
    checks parameter names, ``server.param_names``) from ``/allcfs/group/name`` or else
    ``/<cf_name>/group/name`` (``lookup(ros_name)`` returns None when unset). Returns ({"group.name": value},
    errors naming what is missing or malformed)."""
    return param_values(names, (ALL_CFS_NAMESPACE, "/" + cf_name), lookup)


def _uploaded(member: SwarmMember) -> Dict[int, Any]:
    return getattr(getattr(member.worker.cf, "high_level", None), "trajectories", {}) or {}


def _emergency_of(member: SwarmMember) -> Optional[str]:
    try:
        member.worker.emergency()
        return None
    except Exception as e:      # the worker's own zero-thrust setpoints follow anyway
        return str(e)
