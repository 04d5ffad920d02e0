"""Say once when a Crazyflie's firmware has stopped its motors because its setpoints stopped, and what to do.

The firmware's commander levels a Crazyflie out 0.5 s after the last setpoint and stops its motors
after 2 s (``crtp.firmware_limits``); current firmware's supervisor then stays locked until the
Crazyflie is restarted, firmware 2016.02 sets its thrust lock again (a setpoint with thrust 0
releases it). Nothing tells the host: a pilot whose stick stopped sending, or whose radio went
away, sees a Crazyflie that no longer answers the sticks. :class:`WatchdogNotice` follows what
the server itself sent (setpoints and their times) and, where the firmware has a supervisor port,
asks it whether it is locked; it never looks at the simulator. It says so once, and again only
after the Crazyflie has flown again. docs/protocol.md ("Priorities and the watchdog") has the facts.
"""
from __future__ import annotations

from typing import Callable, Optional

from crazyflie_driver.crtp.firmware_limits import MIN_THRUST, SETPOINT_WATCHDOG_CUT_S, SETPOINT_WATCHDOG_LEVEL_S
from crazyflie_driver.crtp.packet import PORT_GENERIC_SETPOINT, CRTPPacket
from crazyflie_driver.protocol.commander import SUPERVISOR_FROM
from crazyflie_driver.protocol.setpoints import TYPE_STOP
from crazyflie_driver.server import power_control

RESTART_ADVICE = "restart it (the lock holds until a reboot): " + power_control.REBOOT_ADVICE
ZERO_THRUST_ADVICE = ("send one setpoint with thrust 0 (cmd_vel all zero; the teleop's thrust stick down) to "
                      "release its thrust lock, then fly again")


def asks_for_thrust(setpoint) -> bool:
    """Whether a setpoint the worker streams keeps the motors running: an RPYT setpoint (anything
    with ``thrust``) with thrust the commander does not take as 0, or a port-7 setpoint other than stop."""
    if isinstance(setpoint, CRTPPacket):
        return (setpoint.port == PORT_GENERIC_SETPOINT and setpoint.channel == 0 and len(setpoint.data) > 0
                and setpoint.data[0] != TYPE_STOP)
    return getattr(setpoint, "thrust", 0) >= MIN_THRUST


def cut_message(silent_s: float, locked: Optional[bool], protocol_version: int, link_down: bool) -> str:
    """What happened and what to do, in one sentence for /rosout (after the URI) and the status topic.

    ``locked``: the supervisor's answer (None: not asked or no answer); ``link_down``: the radio
    link was lost meanwhile (nothing could reach the Crazyflie)."""
    if link_down:
        why = "nothing reached it for %.1f s after a setpoint with thrust (the radio link is down)" % silent_s
    else:
        why = "no setpoint was sent for %.1f s after one with thrust" % silent_s
    if locked or (locked is None and protocol_version >= SUPERVISOR_FROM):
        what = "its firmware's watchdog stopped the motors and its supervisor locked it"
        if locked is None:
            what += " (this firmware locks on a watchdog cut)"
        advice = RESTART_ADVICE
    elif locked is False:
        what = "its firmware's watchdog stopped the motors (the supervisor reports no lock)"
        advice = ZERO_THRUST_ADVICE
    else:
        what = "its firmware's watchdog stopped the motors and set the thrust lock again"
        advice = ZERO_THRUST_ADVICE + " (if it still does not start, restart it and add it again)"
    return "%s: %s; to fly it again %s" % (why, what, advice)


def flying_when_lost_message(silent_s: float) -> str:
    """The part of a link-lost message for a Crazyflie whose last setpoint asked for thrust."""
    return ("it was flying and nothing reaches it now: its firmware levels it out %.1f s and stops its motors %.1f s "
            "after the last setpoint (%.1f s ago)" % (SETPOINT_WATCHDOG_LEVEL_S, SETPOINT_WATCHDOG_CUT_S, silent_s))


class WatchdogNotice:
    """The setpoint stream of one worker, as far as the firmware's watchdog is concerned.

    ``sent(setpoint, now)`` for every setpoint the worker sends, ``handed_over()`` when the stream
    stops on purpose (the high-level commander takes over), ``due(now)`` to learn whether the
    watchdog has cut the motors since (once per cut), then ``said(text, locked)`` with the message.
    After a cut, setpoints with thrust are taken as flying again only once the firmware would let
    them: after a zero-thrust setpoint (thrust lock), or never (supervisor lock) until
    ``restarted(False)``. ``message`` is the standing notice ("" when none) for the status topic.
    """

    def __init__(self, protocol_version: Callable[[], int]) -> None:
        self._protocol_version = protocol_version
        self.message = ""
        self.cuts = 0                    # notices given
        self._last_at: Optional[float] = None
        self._thrust = False             # the last setpoint sent asks for thrust (and may fly)
        self._stuck = ""                 # after a cut: "lock" (until a restart), "thrust" (until thrust 0)
        self._next_check = 0.0

    def sent(self, setpoint, now: float) -> None:
        self._last_at = now
        if not asks_for_thrust(setpoint):
            self._thrust = False
            if self._stuck == "thrust":
                self._stuck = ""
            return
        if self._stuck:
            return                       # the firmware ignores it: still cut, nothing new to say
        self._thrust = True
        self.message = ""

    def handed_over(self) -> None:
        """The low-level stream ended on purpose: the high-level commander holds the setpoint now."""
        self._thrust = False

    def flying_for(self, now: float) -> Optional[float]:
        """Seconds since the last setpoint if it asked for thrust and the watchdog has not cut yet, else None."""
        if not self._thrust or self._last_at is None:
            return None
        silent = now - self._last_at
        return silent if silent < SETPOINT_WATCHDOG_CUT_S else None

    def due(self, now: float) -> Optional[float]:
        """Seconds of silence when the watchdog has cut the motors and nothing was said yet, else None."""
        if not self._thrust or self._last_at is None or now < self._next_check:
            return None
        silent = now - self._last_at
        return silent if silent >= SETPOINT_WATCHDOG_CUT_S else None

    def not_yet(self, now: float, wait: float = 0.1) -> None:
        """The Crazyflie still reports flying (its clock runs behind ours): look again in ``wait`` s."""
        self._next_check = now + wait

    def said(self, text: str, locked: Optional[bool]) -> None:
        """The notice given for the cut ``due`` reported; ``locked`` as in :func:`cut_message`."""
        self.message = text
        self.cuts += 1
        self._thrust = False
        lock = locked or (locked is None and self._protocol_version() >= SUPERVISOR_FROM)
        self._stuck = "lock" if lock else "thrust"

    @property
    def locked_until_restart(self) -> bool:
        return self._stuck == "lock"

    def restarted(self, locked: Optional[bool]) -> None:
        """The supervisor's lock as read after the link came back (None: not known). A Crazyflie
        restarted meanwhile is no longer locked; after boot its thrust lock wants thrust 0 first."""
        if self._stuck == "lock" and locked is False:
            self._stuck = "thrust"
            self.message = ""
