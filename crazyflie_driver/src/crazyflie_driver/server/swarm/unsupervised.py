"""Crazyflies of the swarm file the server could not add, but that would hear the swarm's broadcasts.

A broadcast (takeoff, go_to, the emergency-stop watchdog's keep-alive) reaches every Crazyflie that
listens on its channel and data rate, whatever its address: a Crazyflie of the file that was left out
(a fault in its entry, its firmware refused a setting) but is switched on would take off with the
others, with no motion capture, no watch and no landing. So before the first broadcast each such
Crazyflie gets an emergency stop by unicast, on the ground: its motors stay locked (the firmware's
supervisor, or the stabilizer's emergency stop before protocol 12) until it is rebooted or switched
off and on. One that does not answer is named, with what to do.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, List, Optional, Sequence, Tuple

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.crtp.uri import RadioUri, parse_uri
from crazyflie_driver.errors import CrazyflieError
from crazyflie_driver.protocol.commander import SUPERVISOR_FROM, emergency_stop_packet
from crazyflie_driver.radio.link import open_link

#: The emergency stop of each protocol generation (the supervisor's from 12 on, the localization
#: port's before); a firmware ignores the one its generation does not have, and its version is
#: unknown without a connect.
ESTOP_PACKETS: Tuple[CRTPPacket, ...] = (emergency_stop_packet(SUPERVISOR_FROM),
                                         emergency_stop_packet(SUPERVISOR_FROM - 1))


@dataclass(frozen=True)
class LeftOut:
    """A Crazyflie of the file that is not a member."""

    name: str
    uri: str
    why: str        # why it was not added


def hearing_broadcasts(left_out: Iterable[LeftOut], member_uris: Sequence[str]) -> List[LeftOut]:
    """The left-out Crazyflies on a member's channel and data rate (so on a channel the swarm broadcasts
    on), except one at a member's own channel and address: that is the member itself, listed twice."""
    members = [_radio(u) for u in member_uris]
    channels = {(m.channel, m.datarate) for m in members if m is not None}
    addressed = {(m.channel, m.address) for m in members if m is not None}
    out = []
    for cf in left_out:
        u = _radio(cf.uri)
        if u is not None and (u.channel, u.datarate) in channels and (u.channel, u.address) not in addressed:
            out.append(cf)
    return out


def _radio(uri: str) -> Optional[RadioUri]:
    """The radio URI, or None (a Crazyflie on a USB cable hears no broadcast; a malformed URI reached nothing)."""
    try:
        return parse_uri(uri)
    except CrazyflieError:
        return None


@contextlib.contextmanager
def unicast(uri: str, manager: Any) -> Iterator[Callable[[CRTPPacket], bool]]:
    """A link to one Crazyflie on ``manager``'s radios without a connect (the greeting only), as its
    ``send`` (True when acked). LinkTimeout when nothing answers the greeting."""
    link = open_link(uri, manager)
    try:
        yield link.send
    finally:
        link.close()


def lock_on_ground(send: Callable[[CRTPPacket], bool]) -> bool:
    """Both emergency stops by unicast (``send`` True when acked); True when one was acknowledged."""
    acked = False
    for packet in ESTOP_PACKETS:
        acked = send(packet) or acked
    return acked


def locked_text(cf: LeftOut) -> str:
    return ("swarm: %s (%s) was not added (%s) but answers on the swarm's channel: its motors are locked "
            "(emergency stop) so the swarm's broadcasts cannot fly it unsupervised; fix its entry, then reboot "
            "it (rosrun crazyflie_tools reboot --uri %s, with the server stopped) or switch it off and on"
            % (cf.name, cf.uri, cf.why, cf.uri))


def unanswered_text(cf: LeftOut, error: str) -> str:
    return ("swarm: %s (%s) was not added (%s) and did not answer an emergency stop (%s): if it is switched "
            "on, switch it off: it listens on a channel the swarm broadcasts on and would take off with the "
            "others, unsupervised" % (cf.name, cf.uri, cf.why, error))
