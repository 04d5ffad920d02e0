"""The I/O side of the safety reactions: what a setpoint or an onboard command tells the monitor,
and the packets an :class:`~crazyflie_driver.server.safety.Action` becomes (the decisions stay in
``server.safety``).
"""
from __future__ import annotations

import logging
import time
from typing import Any, Callable, MutableMapping, Optional, Tuple

from crazyflie_driver.crtp.packet import PORT_GENERIC_SETPOINT, CRTPPacket
from crazyflie_driver.errors import CrazyflieError, FlightRefused
from crazyflie_driver.protocol import high_level, setpoints
from crazyflie_driver.protocol.supervisor import WATCHDOG_KEEPALIVE_PERIOD_S, watchdog_packet
from crazyflie_driver.server.onboard_commands import OnboardCommands
from crazyflie_driver.server.safety import Action, SafetyMonitor
from crazyflie_driver.server.setpoint import Setpoint

__all__ = ["WATCHDOG_KEEPALIVE_PERIOD_S", "ObservedOnboardCommands", "carry_out", "send_watchdog_keepalive",
           "setpoint_thrust"]

LOG = logging.getLogger("crazyflie_driver.server.safety")


def setpoint_thrust(setpoint: Any) -> Tuple[Optional[int], bool]:
    """(RPYT thrust or None for a port-7 packet, whether it is the stop type) of a worker setpoint."""
    if isinstance(setpoint, CRTPPacket):
        stop = setpoint.port == PORT_GENERIC_SETPOINT and setpoint.channel == setpoints.CH_SETPOINT \
            and setpoint.data[:1] == bytes([setpoints.TYPE_STOP])
        return None, stop
    return int(setpoint.thrust), False


def carry_out(action: Action, cf: Any) -> Optional[Setpoint]:
    """Send what ``action`` needs beyond a setpoint; the setpoint to stream this round trip, if any.

    A refused or unanswered landing is logged: the firmware's own watchdog is then what is left.
    """
    if action.kind == "thrust":
        return Setpoint(0.0, 0.0, 0.0, action.thrust)
    if action.kind == "off":
        return Setpoint(0.0, 0.0, 0.0, 0)
    try:
        if action.kind == "land":
            # Down to the floor by a relative go_to, which the planner then holds: a land command ends
            # with the motors off at the plan's end wherever the Crazyflie is, and the position loop
            # trails the plan by centimetres (a drop). The monitor stops the motors once it rests.
            # Planned first (the commander accepts it while low-level setpoints hold the priority), then
            # handed over: after notify-setpoints-stop an idle planner's null setpoint would stop the
            # motors at its next tick (10 ms) unless a plan is already there.
            cf.high_level.command(high_level.go_to_packet(0.0, 0.0, -action.distance, 0.0, action.duration,
                                                          cf.protocol_version, relative=True), idempotent=False)
            notify = setpoints.notify_setpoints_stop_packet(0)
            if not cf.link.send(notify):
                cf.link.send(notify)
        elif action.kind == "hl_stop":
            cf.high_level.command(high_level.stop_packet())
    except CrazyflieError as e:
        LOG.error("%s: safety %s failed: %s", getattr(cf, "uri", "?"), action.kind, e)
    return None


def send_watchdog_keepalive(cf: Any) -> bool:
    """One emergency-stop watchdog keep-alive; False (not an error) when it was not acked."""
    try:
        return bool(cf.link.send(watchdog_packet(cf.protocol_version)))
    except CrazyflieError:
        return False        # a lost link: the watchdog then stops the Crazyflie, which is the point


class ObservedOnboardCommands(OnboardCommands):
    """Onboard commands that also tell the Crazyflie's safety monitor about the poses sent to its
    estimator and the high-level commands it accepted (to choose how to land it), and that refuse
    what the monitor rules out (a command that would cancel a landing under way)."""

    def __init__(self, cf, stream, emergency_active, label: str, monitor: SafetyMonitor,
                 clock: Callable[[], float] = time.monotonic, on_pose: Optional[Callable[[], None]] = None,
                 low_level_sent: Optional[Callable[[], int]] = None, group_mask: int = 0,
                 params: Optional[Callable[[], MutableMapping[str, Any]]] = None) -> None:
        super().__init__(cf, stream, emergency_active, label, on_pose=on_pose, low_level_sent=low_level_sent,
                         group_mask=group_mask, params=params)
        self._monitor = monitor
        self._clock = clock

    def external_position(self, x: float, y: float, z: float) -> bool:
        sent = super().external_position(x, y, z)
        if sent:
            self._monitor.note_pose(self._clock(), z)
        return sent

    def external_pose(self, x: float, y: float, z: float, quaternion) -> bool:
        sent = super().external_pose(x, y, z, quaternion)
        if sent:
            self._monitor.note_pose(self._clock(), z)
        return sent

    def _refuse(self, what: str, group_mask: int) -> None:
        super()._refuse(what, group_mask)
        why = self._monitor.refusal(self._clock(), what)
        if why is not None:
            raise FlightRefused("%s: %s refused, nothing sent: %s" % (self.label, what, why))

    def _height(self) -> Optional[float]:
        return self._monitor.current_height(self._clock())

    def _fly(self, what: str, packet: CRTPPacket, group_mask: int, idempotent: bool = True) -> None:
        super()._fly(what, packet, group_mask, idempotent)
        self._monitor.note_high_level(self._clock(), what)

    def land(self, group_mask: int, height: float, duration_s: float) -> None:
        asked_at = self._clock()    # the firmware starts the plan later: the monitor never outlasts its landing
        super().land(group_mask, height, duration_s)
        self._monitor.note_high_level(asked_at, "land", duration_s)


def worker_onboard_commands(worker: Any, label: str) -> ObservedOnboardCommands:
    """The HEAD API of a served Crazyflie, wired on its worker: its setpoint stream, emergency state,
    safety monitor, clock, pose and low-level counts, and its parameter values (so a group mask written
    by ``update_params`` is the one every group-mask check follows)."""
    return ObservedOnboardCommands(worker.cf, worker.set_packet_setpoint, lambda: worker.emergency_active, label,
                                   worker.safety, clock=worker.clock.now, on_pose=worker.health.pose_sent,
                                   low_level_sent=lambda: worker.setpoints_sent, params=lambda: worker.param_values)
