"""What each Crazyradio will carry, against what it can carry: the radio budget, checked before take-off.

Pure. A dongle answers strictly one packet at a time, so its capacity is one over the time a round
trip costs it: a bulk OUT + IN (``BULK_ROUND_TRIP_S``), plus a control transfer
(``CONTROL_TRANSFER_S``) for each radio setting (address, channel, data rate) that changes between
consecutive packets. The server's round trips of several Crazyflies interleave (the dongle's FIFO),
so with two or more addresses on one dongle every round trip pays the address switch: ~1250 round
trips/s for one Crazyflie, ~435/s shared. A broadcast burst switches to the broadcast address with
acks off and back (three control transfers when unicast links share the dongle, four when they all
have one address, whose round trips pay no switch of their own), and each packet costs its air time
(``NO_ACK_PACKET_S``: no ack wait, no IN reply). A Crazyradio 2.0 in inline mode (``inline``) pays
no control transfer at all: each packet carries its settings, a broadcast packet costs a round trip
without the ack wait (``INLINE_NO_ACK_S``). Figures and sources: docs/diagnostics.md, "Radio budget".

What a Crazyflie needs: a round trip per setpoint and per unicast pose, and one per log packet its
blocks produce (each ack carries at most one); the larger of the two, since a setpoint's ack also
fetches a log packet; at least ``KEEPALIVE_FLOOR_HZ``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Collection, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from crazyflie_driver.crtp.uri import RadioUri, parse_uri
from crazyflie_driver.protocol.localization import POSES_PER_PACKET, POSITIONS_PER_PACKET
from crazyflie_driver.radio.shared_radio import UNICAST_RESERVE
from crazyflie_driver.server import diagnostic_thresholds as T

#: A Crazyradio PA over USB (the fake dongle's DongleTiming defaults are the same figures; a test holds them equal).
BULK_ROUND_TRIP_S = 0.0008          # s, bulk OUT + IN of an acked packet
CONTROL_TRANSFER_S = 0.0015         # s, one vendor request (set address, channel, data rate, ack enable)
NO_ACK_PACKET_S = 0.0003            # s, one radio packet without ack at 2M (air time; its USB OUT overlaps)
INLINE_NO_ACK_S = 0.0006            # s, one inline-mode packet without ack: bulk OUT + IN, no ack wait
#: Round trips/s a served Crazyflie gets at least (keep-alives, link-lost detection).
KEEPALIVE_FLOOR_HZ = 10.0
#: Log packets/s of the fixed topics on the current firmware: one 10 ms block (IMU) and one 100 ms block.
FIXED_LOG_PACKETS_HZ = 110.0
#: Setpoints/s assumed for a Crazyflie when nobody says: the chapter's controller sends cmd_vel at 50 Hz.
DEFAULT_SETPOINT_HZ = 50.0
#: Control transfers per broadcast burst on a dongle with unicast links: broadcast address, acks off,
#: acks on again; plus the unicast address back when the unicast round trips do not switch it anyway.
BROADCAST_SWITCHES = 3
#: Motion-capture frames/s a dongle broadcasts at least, whatever its budget: the onboard estimator still
#: holds a hover within about 1 cm at 10 Hz (docs/diagnostics.md, "Radio budget").
MOCAP_FLOOR_HZ = 10.0
#: Share of a dongle's time a swarm's onboard pose topics take at most when the server chooses their period.
POSE_LOG_SHARE = 0.1
#: Shortest period of a chosen pose topic (ms): HEAD's 10 Hz.
POSE_LOG_MIN_PERIOD_MS = 100


@dataclass(frozen=True)
class CrazyflieDemand:
    """What one Crazyflie asks of its dongle, per second."""

    name: str
    uri: RadioUri
    setpoint_hz: float = 0.0        # streamed setpoints (cmd_vel, cmd_position...)
    pose_hz: float = 0.0            # external position/pose sent by unicast
    log_packets_hz: float = 0.0     # log packets its blocks produce

    @property
    def round_trips_hz(self) -> float:
        return max(self.setpoint_hz + self.pose_hz, self.log_packets_hz, KEEPALIVE_FLOOR_HZ)


@dataclass(frozen=True)
class BroadcastDemand:
    """Broadcast bursts on one dongle (e.g. packed mocap poses): ``frames_hz`` bursts of ``packets`` packets."""

    dongle: int
    frames_hz: float
    packets: int
    inline: bool = False            # the dongle sends inline (Crazyradio 2.0 from 5.1): no control transfers


@dataclass(frozen=True)
class DongleBudget:
    """One dongle's budget: ``load`` is the share of each second its planned traffic takes."""

    index: int
    crazyflies: Tuple[str, ...]
    round_trips_hz: float
    broadcast_packets_hz: float
    round_trip_s: float              # dongle time per unicast round trip as it is shared
    capacity_per_s: float            # unicast round trips/s at that cost
    load: float
    level: int                       # 0 OK, 1 WARN, 2 ERROR (diagnostic levels)
    advice: Tuple[str, ...] = field(default=())

    def message(self) -> str:
        head = ("radio %d: %d Crazyflie(s) need %.0f round trips/s%s = %.0f %% of its capacity (%.0f round trips/s "
                "at %.1f ms each)" % (self.index, len(self.crazyflies), self.round_trips_hz,
                                      " + %.0f broadcast packets/s" % self.broadcast_packets_hz
                                      if self.broadcast_packets_hz else "", self.load * 100, self.capacity_per_s,
                                      self.round_trip_s * 1e3))
        return head + ("; " + "; ".join(self.advice) if self.advice else "")


def round_trip_cost_s(uris: Sequence[RadioUri], inline: bool = False) -> float:
    """Dongle time of one unicast round trip when ``uris`` share it (interleaved), s; ``inline``: the
    settings travel with each packet (no control transfer)."""
    if inline:
        return BULK_ROUND_TRIP_S
    switches = sum(len(set(values)) > 1 for values in (
        [u.address for u in uris], [u.channel for u in uris], [u.datarate for u in uris]))
    return BULK_ROUND_TRIP_S + switches * CONTROL_TRANSFER_S


def capacity_per_s(uris: Sequence[RadioUri]) -> float:
    """Unicast round trips/s a dongle can carry for these Crazyflies."""
    return 1.0 / round_trip_cost_s(uris) if uris else 1.0 / BULK_ROUND_TRIP_S


def log_packets_hz(enable_logging: bool, custom_periods_ms: Iterable[int] = ()) -> float:
    """Log packets/s before connecting (the fixed topics' estimate + one block per custom topic);
    once connected, the worker's planned blocks give the exact figure."""
    return (FIXED_LOG_PACKETS_HZ if enable_logging else 0.0) + sum(1000.0 / max(1, p) for p in custom_periods_ms)


def mocap_broadcast(dongle: int, crazyflies: int, rate_hz: float, full_pose: bool = True,
                    inline: bool = False) -> BroadcastDemand:
    """Packed mocap by broadcast: one burst per frame, 2 poses (or 4 positions) per packet."""
    per = POSES_PER_PACKET if full_pose else POSITIONS_PER_PACKET
    return BroadcastDemand(dongle, rate_hz, -(-crazyflies // per), inline)


def burst_s(packets: int, unicast: Sequence[RadioUri] = (), inline: bool = False) -> float:
    """Dongle time of one broadcast burst of ``packets`` packets (s). ``unicast``: the Crazyflies whose
    round trips share the dongle; with any, the burst switches to the broadcast address with acks off
    and back (``BROADCAST_SWITCHES``, one more when their round trips keep one address). Pairs of
    packets in one transfer (a PA with the 99.55 image, a 2.0) save USB transfers, not air time."""
    if inline:
        return packets * INLINE_NO_ACK_S
    switches = 0
    if unicast:
        switches = BROADCAST_SWITCHES + (0 if len({u.address for u in unicast}) > 1 else 1)
    return switches * CONTROL_TRANSFER_S + packets * NO_ACK_PACKET_S


def mocap_rate_hz(members: Sequence[CrazyflieDemand], wanted_hz: float, full_pose: bool = True,
                  inline: bool = False) -> float:
    """The motion-capture frames/s one dongle broadcasts to ``members`` (the Crazyflies it reaches):
    ``wanted_hz`` (the motion-capture rate) if the dongle can carry it beside their unicast needs and
    the ``UNICAST_RESERVE`` kept for requests (parameter writes, trajectory uploads), else what it can,
    but never below ``MOCAP_FLOOR_HZ``. ``inline``: the dongle sends inline (a Crazyradio 2.0)."""
    if not members or wanted_hz <= 0:
        return max(0.0, wanted_hz)
    uris = [m.uri for m in members]
    unicast = sum(m.round_trips_hz for m in members) * round_trip_cost_s(uris, inline)
    burst = mocap_broadcast(0, len(members), 1.0, full_pose)
    free = max(0.0, 1.0 - UNICAST_RESERVE - unicast)
    return max(min(wanted_hz, MOCAP_FLOOR_HZ), min(wanted_hz, free / burst_s(burst.packets, uris, inline)))


def pose_log_period_ms(uris: Sequence[RadioUri]) -> int:
    """The onboard pose topic's log period (ms, a multiple of 100) for Crazyflies sharing one dongle, so
    that their log packets (one round trip each) take at most ``POSE_LOG_SHARE`` of it: 100 ms for up to
    four, 400 ms for 16 or 17."""
    need_ms = 1000.0 * len(uris) * round_trip_cost_s(uris) / POSE_LOG_SHARE
    steps = max(1, -(-int(math.ceil(need_ms - 1e-9)) // POSE_LOG_MIN_PERIOD_MS))
    return steps * POSE_LOG_MIN_PERIOD_MS


def pose_log_periods(uris: Mapping[str, str]) -> Dict[str, int]:
    """``pose_log_period_ms`` for each Crazyflie (by name, its URI), from the Crazyflies sharing its dongle."""
    parsed = {name: parse_uri(uri) for name, uri in uris.items()}
    by_dongle: Dict[int, List[RadioUri]] = {}
    for u in parsed.values():
        by_dongle.setdefault(u.index, []).append(u)
    return {name: pose_log_period_ms(by_dongle[u.index]) for name, u in parsed.items()}


def mocap_plan(demands: Sequence[CrazyflieDemand], wanted_hz: float, full_pose: bool = True,
               inline_dongles: Collection[int] = ()) -> List[BroadcastDemand]:
    """The motion-capture bursts of a swarm, per dongle (in dongle order), each at the rate its dongle's
    budget allows (``mocap_rate_hz``); ``inline_dongles``: the indexes of the dongles that send inline."""
    by_dongle: Dict[int, List[CrazyflieDemand]] = {}
    for d in demands:
        by_dongle.setdefault(d.uri.index, []).append(d)
    return [mocap_broadcast(index, len(members), mocap_rate_hz(members, wanted_hz, full_pose, index in inline_dongles),
                            full_pose, index in inline_dongles)
            for index, members in sorted(by_dongle.items())]


def check_budget(demands: Sequence[CrazyflieDemand], broadcasts: Sequence[BroadcastDemand] = ()) -> List[DongleBudget]:
    """The budget of every dongle used, in dongle order, with a level and what to change."""
    by_dongle: Dict[int, List[CrazyflieDemand]] = {}
    for d in demands:
        by_dongle.setdefault(d.uri.index, []).append(d)
    bursts: Dict[int, List[BroadcastDemand]] = {}
    for b in broadcasts:
        bursts.setdefault(b.dongle, []).append(b)
    out = []
    for index in sorted(set(by_dongle) | set(bursts)):
        members = by_dongle.get(index, [])
        uris = [m.uri for m in members]
        bc = bursts.get(index, [])
        inline = any(b.inline for b in bc)
        cost = round_trip_cost_s(uris, inline) if uris else BULK_ROUND_TRIP_S
        rt_hz = sum(m.round_trips_hz for m in members)
        bc_packets = sum(b.frames_hz * b.packets for b in bc)
        load = rt_hz * cost + sum(b.frames_hz * burst_s(b.packets, uris, b.inline) for b in bc)
        level = 2 if load > T.RADIO_LOAD_ERROR else 1 if load > T.RADIO_LOAD_WARN else 0
        advice = _advice(members, bc, load) if level else ()
        out.append(DongleBudget(index, tuple(m.name for m in members), rt_hz, bc_packets, cost, 1.0 / cost, load,
                                level, advice))
    return out


def _advice(members: Sequence[CrazyflieDemand], bursts: Sequence[BroadcastDemand], load: float) -> Tuple[str, ...]:
    advice = []
    logs = sum(m.log_packets_hz for m in members)
    commands = sum(m.setpoint_hz + m.pose_hz for m in members)
    if len(members) > 1:
        keep = max(1, int(len(members) / max(load, 1e-9) * T.RADIO_LOAD_WARN))
        advice.append("put at most %d of these Crazyflies on this Crazyradio and the others on another one"
                      % min(keep, len(members) - 1))
    if logs > 0 and logs >= commands:
        advice.append("log less: %.0f log packets/s planned (fewer log blocks, longer periods, or enable_logging "
                      "false: the fixed topics alone are %.0f packets/s per Crazyflie)" % (logs, FIXED_LOG_PACKETS_HZ))
    if any(m.pose_hz for m in members):
        advice.append("send motion capture by broadcast (packed poses: one burst for every 2 Crazyflies) instead "
                      "of a unicast pose each")
    if any(m.setpoint_hz for m in members) and len(members) > 1:
        advice.append("fly by the onboard high-level commander (broadcast take-off, go_to, trajectories) instead "
                      "of streaming setpoints")
    if bursts:
        shared = members and not any(b.inline for b in bursts)
        advice.append("broadcast less often%s" % (
            " or from a Crazyradio of its own, or a Crazyradio 2.0 (inline mode: each burst here costs %.1f ms "
            "of address and ack switches)" % (burst_s(0, [m.uri for m in members]) * 1e3) if shared else ""))
    return tuple(advice)


def demands_for(entries: Iterable[Tuple[str, str, float, float, float]]) -> List[CrazyflieDemand]:
    """(name, uri, setpoint Hz, unicast pose Hz, log packets Hz) -> demands; a bad URI raises ValueError."""
    out = []
    for name, uri, setpoint_hz, pose_hz, log_hz in entries:
        out.append(CrazyflieDemand(name, parse_uri(uri), float(setpoint_hz), float(pose_hz), float(log_hz)))
    return out


def budget_messages(budgets: Sequence[DongleBudget], only_problems: bool = True) -> List[Tuple[int, str]]:
    """(level, text) per dongle, for the log: what it will carry and what to change."""
    return [(b.level, b.message()) for b in budgets if b.level or not only_problems]


def find(budgets: Sequence[DongleBudget], index: int) -> Optional[DongleBudget]:
    for b in budgets:
        if b.index == index:
            return b
    return None
