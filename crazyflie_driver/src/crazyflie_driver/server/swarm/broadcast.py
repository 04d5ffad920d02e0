"""Swarm-wide commands and motion capture by broadcast, without ROS.

One ``BroadcastLink`` per (dongle, channel, data rate) that the swarm's Crazyflies use. Commands
are built once (so a bad one is refused before anything goes out), then sent on every link, each
repeated ``repeats`` times because a broadcast is never acknowledged. Motion capture goes out as
packed poses (or positions), each link carrying only the Crazyflies it reaches, one burst per frame,
within the share of each dongle that a stream of bursts may take (``radio.broadcast``).

As swarm servers do, a broadcast go_to and start_trajectory are always relative: the same absolute
goal for every Crazyflie would send them all to one point. Every high-level packet is answered by
each Crazyflie; those answers leave only on unicast acks, so the per-Crazyflie workers must keep
polling (they do) or the Crazyflies' transmit queues fill up.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.crtp.uri import RadioUri, parse_uri
from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.protocol import high_level, param
from crazyflie_driver.protocol.commander import emergency_stop_packet
from crazyflie_driver.protocol.localization import address_id, packed_pose_packets, packed_position_packets
from crazyflie_driver.protocol.setpoints import notify_setpoints_stop_packet
from crazyflie_driver.protocol.supervisor import arm_packet, watchdog_packet
from crazyflie_driver.radio.broadcast import DEFAULT_REPEAT_INTERVAL_S, DEFAULT_REPEATS, BroadcastLink
from crazyflie_driver.radio.shared_radio import RadioManager

Pose = Tuple[float, float, float, float, float, float, float]     # x, y, z, qx, qy, qz, qw
LinkKey = Tuple[int, int, int]                                   # dongle, channel, data rate


def group_by_link(uris: Iterable[RadioUri]) -> OrderedDict[LinkKey, List[int]]:
    """The broadcast links a swarm needs and the packed-item ids each one reaches, in first-seen order.
    Two Crazyflies with the same id on one link would both take each other's poses: refused."""
    groups: OrderedDict[LinkKey, List[int]] = OrderedDict()
    for uri in uris:
        key = (uri.index, uri.channel, uri.datarate)
        ident = address_id(uri.address)
        members = groups.setdefault(key, [])
        if ident in members:
            raise ValueError("two Crazyflies on radio %d channel %d share the address ending 0x%02X (%s): packed "
                             "mocap could not tell them apart; give each its own last address byte"
                             % (uri.index, uri.channel, ident, uri))
        members.append(ident)
    return groups


class SwarmBroadcaster:
    """Broadcasts to a swarm. ``protocol_version``: the lowest of the swarm's Crazyflies (commands
    every one of them understands)."""

    def __init__(self, uris: Sequence, protocol_version: int, manager: Optional[RadioManager] = None,
                 repeats: int = DEFAULT_REPEATS, interval_s: float = DEFAULT_REPEAT_INTERVAL_S, sleep=None) -> None:
        parsed = [parse_uri(u) if isinstance(u, str) else u for u in uris]
        self.protocol_version = protocol_version
        self.repeats = repeats
        self.interval_s = interval_s
        options = {} if sleep is None else {"sleep": sleep}
        self.members: Dict[LinkKey, List[int]] = dict(group_by_link(parsed))
        self.links: Dict[LinkKey, BroadcastLink] = {
            key: BroadcastLink(key[0], key[1], key[2], manager, **options) for key in self.members}

    def open(self) -> None:
        for link in self.links.values():
            link.open()

    def close(self) -> None:
        for link in self.links.values():
            link.close()

    def __enter__(self) -> SwarmBroadcaster:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _on_every_link(self, send: Callable[[BroadcastLink], int]) -> int:
        """``send(link)`` on every link at once, one thread per further link (the radios work in parallel,
        so a command reaches every radio's Crazyflies at the same time), each even when another fails (an
        unplugged radio must not keep a command from the others); then CrazyflieError naming each failed
        one, else the transfers made."""
        items = list(self.links.items())
        results: List[object] = [0] * len(items)

        def one(i: int) -> None:
            key, link = items[i]
            try:
                results[i] = send(link)
            except CrazyflieError as e:
                results[i] = "radio %d channel %d: %s" % (key[0], key[1], e)

        threads = [threading.Thread(target=one, args=(i,), name="broadcast %d" % i, daemon=True)
                   for i in range(1, len(items))]
        for t in threads:
            t.start()
        if items:
            one(0)
        for t in threads:
            t.join()
        taken = sum(r for r in results if isinstance(r, int))
        failed = [r for r in results if isinstance(r, str)]
        if failed:
            raise CrazyflieError("broadcast not sent on %d of %d radio links (the others took it): %s"
                                 % (len(failed), len(self.links), "; ".join(failed)))
        return taken

    def _everywhere(self, packet: CRTPPacket) -> int:
        return self._on_every_link(lambda link: link.send_repeated(packet, self.repeats, self.interval_s))

    def watchdog(self) -> int:
        """One emergency-stop watchdog keep-alive on every link (not repeated: the next one follows soon)."""
        packet = watchdog_packet(self.protocol_version)
        return self._on_every_link(lambda link: link.send(packet))

    # -- commands (checked before anything is sent; return the USB transfers made) --------------
    def takeoff(self, height: float, duration_s: float, group_mask: int = 0) -> int:
        return self._everywhere(high_level.takeoff_packet(height, duration_s, self.protocol_version, group_mask))

    def land(self, height: float, duration_s: float, group_mask: int = 0) -> int:
        return self._everywhere(high_level.land_packet(height, duration_s, self.protocol_version, group_mask))

    def stop(self, group_mask: int = 0) -> int:
        return self._everywhere(high_level.stop_packet(group_mask))

    def go_to(self, offset: Sequence[float], yaw: float, duration_s: float, group_mask: int = 0) -> int:
        """Every Crazyflie moves by ``offset`` (m) and turns by ``yaw`` (rad)."""
        return self._everywhere(high_level.go_to_packet(offset[0], offset[1], offset[2], yaw, duration_s,
                                                        self.protocol_version, relative=True,
                                                        group_mask_=group_mask))

    def start_trajectory(self, trajectory_id: int, timescale: float = 1.0, reversed_: bool = False,
                         group_mask: int = 0) -> int:
        """Every Crazyflie flies its own uploaded trajectory ``trajectory_id``, from where it is."""
        return self._everywhere(high_level.start_trajectory_packet(trajectory_id, self.protocol_version, timescale,
                                                                   reversed_, relative=True,
                                                                   group_mask_=group_mask))

    def set_param(self, full_name: str, ctype_name: str, value) -> int:
        """Parameter ``full_name`` (of C type ``ctype_name`` on these Crazyflies) set to ``value`` on every
        Crazyflie by name (SET_BY_NAME): unacknowledged, repeated like every command."""
        return self._everywhere(param.set_by_name_packet(full_name, ctype_name, value))

    def notify_setpoints_stop(self) -> int:
        return self._everywhere(notify_setpoints_stop_packet(0))

    def arm(self, do_arm: bool = True) -> int:
        """Every Crazyflie armed (or disarmed): the supervisor port from protocol 12, the platform port
        before (NotSupported below 6: such firmware arms itself). Unacknowledged, repeated."""
        return self._everywhere(arm_packet(do_arm, self.protocol_version))

    def emergency(self) -> int:
        """Motors off for every Crazyflie until restarted."""
        return self._everywhere(emergency_stop_packet(self.protocol_version))

    # -- motion capture ----------------------------------------------------------------------
    def send_poses(self, poses: Mapping[Any, Pose], position_only: bool = False) -> int:
        """One mocap frame: ``poses`` by Crazyflie URI; each link sends, in one burst, the poses of the
        Crazyflies it reaches. Returns the USB transfers made."""
        by_link: Dict[LinkKey, List[tuple]] = {}
        for uri, pose in poses.items():
            u: RadioUri = parse_uri(uri) if isinstance(uri, str) else uri
            key = (u.index, u.channel, u.datarate)
            if address_id(u.address) not in self.members.get(key, ()):
                raise ValueError("%s is not in this swarm" % (u,))
            by_link.setdefault(key, []).append((address_id(u.address),) + tuple(pose))
        transfers = 0
        for key, here in by_link.items():
            link = self.links[key]
            if position_only:
                packets = packed_position_packets([item[:4] for item in here])
            else:
                packets = packed_pose_packets(here)
            transfers += link.send_all(packets, capped=True)
        return transfers
