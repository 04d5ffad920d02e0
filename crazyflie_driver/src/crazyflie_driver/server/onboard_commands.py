"""crazyflie_ros HEAD's per-Crazyflie setpoint topics and high-level services, without ROS.

Streaming setpoints (``cmd_position``, ``cmd_hover``, ``cmd_full_state``, ``cmd_velocity_world``,
``cmd_stop``) become port-7 packets handed to the worker, which sends the latest one in its next
round trip, like cmd_vel. ``external_position`` / ``external_pose`` go out at once (port 6).
High-level services run in the caller's thread and wait for the Crazyflie's answer.

Where this differs from crazyflie_ros HEAD (see the package README):
* ``go_to`` yaw is radians, the firmware's unit (HEAD's comment says degrees);
* ``cmd_hover`` / ``cmd_velocity_world`` yaw rates mean the same on every firmware (HEAD passes
  them raw into the legacy types, whose yaw rate the firmware negates);
* a high-level command after low-level setpoints (the zero setpoints every connect sends, this
  API's streams and the worker's own: cmd_vel, a controller's RPYT) is followed by
  notify-setpoints-stop, because the firmware ignores the high-level commander while low-level
  setpoints hold the priority, and an idle planner given the priority stops the motors at its next
  tick (docs/protocol.md, "The commander's priority"); HEAD leaves that to the user;
* a command whose group mask does not address this Crazyflie is refused (HEAD sends it, the firmware
  answers OK and does nothing), and so is a land that would drop it (``server.safety.checked_landing``).
"""
from __future__ import annotations

import threading
from typing import Any, Callable, Mapping, MutableMapping, Optional, Sequence

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import CrazyflieError, EmergencyActive
from crazyflie_driver.protocol import high_level, setpoints
from crazyflie_driver.protocol.commander import stop_packet
from crazyflie_driver.protocol.high_level import in_groups, nobody_addressed
from crazyflie_driver.protocol.localization import external_pose_packet, external_position_packet
from crazyflie_driver.protocol.trajectory import make_piece
from crazyflie_driver.server import power_control
from crazyflie_driver.server.safety import checked_landing

Quaternion = Sequence[float]

#: The firmware parameter holding a Crazyflie's groups (set_group_mask sets the same variable).
GROUP_MASK_PARAM = "hlCommander.groupmask"


def known_group_mask(params: Mapping[str, Any]) -> int:
    """A Crazyflie's group mask from its parameter values as read at connect: a Crazyflie not restarted
    since an earlier session keeps its groups. 0 (the firmware's start value) when not read."""
    try:
        return int(params.get(GROUP_MASK_PARAM, 0)) & 0xFF
    except (TypeError, ValueError):
        return 0


class OnboardCommands:
    """The HEAD API for one Crazyflie. ``cf`` is a connected ``Crazyflie`` (its ``high_level``,
    ``link``, ``protocol_version``); ``stream(packet) -> bool`` hands a setpoint to the worker
    (False after emergency); ``emergency_active()`` tells whether the worker is in emergency;
    ``on_pose()``, if given, is called for each external position/pose the Crazyflie acknowledged (for
    ``/diagnostics``);
    ``low_level_sent()``, if given, counts the low-level setpoints the worker has sent (any source):
    one sent since the last notify-setpoints-stop holds the firmware's priority again; ``params()``, if
    given, the worker's parameter values as read and written since (a mapping this also writes to): the
    group mask is their ``hlCommander.groupmask``, so a write by ``update_params`` counts as
    ``set_group_mask`` does; ``group_mask``: the groups to start with where ``params`` has none (0 after
    a restart)."""

    def __init__(self, cf, stream: Callable[[Optional[CRTPPacket]], bool], emergency_active: Callable[[], bool],
                 label: str = "", on_pose: Optional[Callable[[], None]] = None,
                 low_level_sent: Optional[Callable[[], int]] = None, group_mask: int = 0,
                 params: Optional[Callable[[], MutableMapping[str, Any]]] = None) -> None:
        self.cf = cf
        own: MutableMapping[str, Any] = {}
        self._params: Callable[[], MutableMapping[str, Any]] = params if params is not None else (lambda: own)
        self._on_pose = on_pose
        self._low_level_sent = low_level_sent
        self._sent_at_notify: Optional[int] = None
        self._stream = stream
        self._emergency_active = emergency_active
        self.label = label or str(getattr(cf, "uri", ""))
        self._lock = threading.Lock()
        self._low_level_active = True    # connect sends zero setpoints: assume low level owns it
        if GROUP_MASK_PARAM not in self._params():
            self.group_mask = group_mask

    @property
    def group_mask(self) -> int:
        """The Crazyflie's groups as last set: by ``set_group_mask`` or by a write of ``hlCommander.groupmask``
        (the firmware's variable behind both), whichever came last."""
        return known_group_mask(self._params())

    @group_mask.setter
    def group_mask(self, mask: int) -> None:
        self._params()[GROUP_MASK_PARAM] = int(mask) & 0xFF

    @property
    def low_level_active(self) -> bool:
        """Low-level setpoints (or the connect's zero setpoints) hold the firmware's priority: a
        high-level command needs notify-setpoints-stop first."""
        if self._low_level_active:
            return True
        return self._low_level_sent is not None and self._low_level_sent() != self._sent_at_notify

    # -- streaming setpoints --------------------------------------------------------------------
    def _set(self, packet: CRTPPacket) -> bool:
        self._low_level_active = True
        return self._stream(packet)

    def cmd_position(self, x: float, y: float, z: float, yaw_deg: float) -> bool:
        return self._set(setpoints.position_packet(x, y, z, yaw_deg))

    def cmd_hover(self, vx: float, vy: float, yawrate_deg: float, z: float) -> bool:
        return self._set(setpoints.hover_packet(vx, vy, yawrate_deg, z, self.cf.protocol_version))

    def cmd_velocity_world(self, vx: float, vy: float, vz: float, yawrate_deg: float) -> bool:
        return self._set(setpoints.velocity_world_packet(vx, vy, vz, yawrate_deg, self.cf.protocol_version))

    def cmd_full_state(self, position: Sequence[float], quaternion: Quaternion, velocity: Sequence[float],
                       body_rates: Sequence[float], acceleration: Sequence[float]) -> bool:
        return self._set(setpoints.full_state_packet(position, velocity, acceleration, quaternion, body_rates))

    def cmd_stop(self) -> bool:
        return self._set(stop_packet(self.cf.protocol_version))

    # -- motion capture (unicast, sent at once) -------------------------------------------------
    def external_position(self, x: float, y: float, z: float) -> bool:
        if self._emergency_active():
            return False
        return self._pose_out(external_position_packet(x, y, z))

    def external_pose(self, x: float, y: float, z: float, quaternion: Quaternion) -> bool:
        if self._emergency_active():
            return False
        return self._pose_out(external_pose_packet(x, y, z, quaternion))

    def _pose_out(self, packet: CRTPPacket) -> bool:
        """Send a built pose packet; it counts for ``/diagnostics`` only once the Crazyflie took it (a pose
        refused by the builder or lost on the radio must not make the pose look fresh)."""
        taken = self.cf.link.send(packet)
        if taken and self._on_pose is not None:
            self._on_pose()
        return taken

    # -- high-level services --------------------------------------------------------------------
    def _refuse(self, what: str, group_mask: int) -> None:
        """Raise, before anything is sent, when ``what`` must not go out: after emergency, or when
        ``group_mask`` does not address this Crazyflie."""
        if self._emergency_active():
            raise EmergencyActive("%s: %s refused: emergency is active (the Crazyflie stays stopped until a "
                                  "reboot: %s)" % (self.label, what, power_control.REBOOT_ADVICE))
        if not in_groups(self.group_mask, group_mask):
            raise nobody_addressed(group_mask, "%s is in group mask %d" % (self.label, self.group_mask),
                                   "%s: %s" % (self.label, what))

    def _height(self) -> Optional[float]:
        """The Crazyflie's current height (m) where known, for the checks of a landing."""
        return None

    def _fly(self, what: str, packet: CRTPPacket, group_mask: int, idempotent: bool = True) -> None:
        """Send a checked high-level packet. After low-level setpoints it goes out first and
        notify-setpoints-stop after it: the plan is in place when the priority comes back, so no tick of
        the idle planner (its null setpoint stops the motors) falls between the two packets, however
        late the second one is."""
        with self._lock:
            self._refuse(what, group_mask)
            if not self.low_level_active:
                self.cf.high_level.command(packet, idempotent=idempotent)
                return
            since = self.stop_stream()
            self.cf.high_level.command(packet, idempotent=idempotent)
            if self.hand_over(since) and idempotent:
                # a setpoint already on its way went out after the command and stopped its plan
                self.cf.high_level.command(packet, idempotent=idempotent)

    def stop_stream(self) -> Optional[int]:
        """Stop the worker's low-level stream before a high-level command; the count of low-level
        setpoints sent so far (None when not counted), for ``hand_over``."""
        self._stream(None)
        return self._low_level_sent() if self._low_level_sent is not None else None

    def hand_over(self, since: Optional[int]) -> bool:
        """Notify-setpoints-stop after a high-level command went out (the firmware plans a command
        while a low-level setpoint holds the priority; notify hands the priority to that plan). True
        when a low-level setpoint went out after ``stop_stream`` counted ``since``: it may have stopped
        the plan, so the command needs sending again."""
        self.notify_setpoints_stop(0)
        return since is not None and self._sent_at_notify != since

    def notify_setpoints_stop(self, remain_valid_ms: int = 0) -> None:
        """Give control back to the high-level commander (stops the worker's low-level stream)."""
        packet = setpoints.notify_setpoints_stop_packet(remain_valid_ms)
        self._stream(None)
        count = self._low_level_sent
        for _ in range(2):                  # a setpoint already in the worker's hands may go out just after
            before = count() if count is not None else None
            if not self.cf.link.send(packet) and not self.cf.link.send(packet):
                raise CrazyflieError("%s: notify-setpoints-stop was not acknowledged" % self.label)
            if count is None or count() == before:
                break
        self._sent_at_notify = count() if count is not None else None
        self._low_level_active = False

    def takeoff(self, group_mask: int, height: float, duration_s: float) -> None:
        self._fly("takeoff", high_level.takeoff_packet(height, duration_s, self.cf.protocol_version, group_mask),
                  group_mask)

    def land(self, group_mask: int, height: float, duration_s: float) -> None:
        height, duration_s = checked_landing(height, duration_s, self._height(), self.label)
        self._fly("land", high_level.land_packet(height, duration_s, self.cf.protocol_version, group_mask), group_mask)

    def stop(self, group_mask: int) -> None:
        self._fly("stop", high_level.stop_packet(group_mask), group_mask)

    def go_to(self, group_mask: int, relative: bool, goal: Sequence[float], yaw: float, duration_s: float) -> None:
        packet = high_level.go_to_packet(goal[0], goal[1], goal[2], yaw, duration_s, self.cf.protocol_version,
                                         relative=relative, group_mask_=group_mask)
        self._fly("go_to", packet, group_mask, idempotent=not relative)

    def start_trajectory(self, group_mask: int, trajectory_id: int, timescale: float, reversed_: bool,
                         relative: bool) -> None:
        packet = self.cf.high_level.start_trajectory_packet(trajectory_id, timescale, reversed_, relative,
                                                            group_mask=group_mask)
        self._fly("start_trajectory", packet, group_mask)

    def set_group_mask(self, group_mask: int) -> None:
        packet = high_level.set_group_mask_packet(group_mask)
        with self._lock:
            self.cf.high_level.command(packet)
            self.group_mask = group_mask

    def upload_trajectory(self, trajectory_id: int, piece_offset: int, pieces) -> None:
        """``pieces``: (duration s, poly_x, poly_y, poly_z, poly_yaw) per piece; checked first."""
        checked = [make_piece(d, x, y, z, yaw, index=i) for i, (d, x, y, z, yaw) in enumerate(pieces)]
        with self._lock:
            if self._emergency_active():
                raise EmergencyActive("%s: upload_trajectory refused: emergency is active" % self.label)
            self.cf.high_level.upload_trajectory(trajectory_id, checked, piece_offset)


def stream_into(worker) -> Callable[[Optional[CRTPPacket]], bool]:
    """``stream`` for a worker: the packet becomes its pending setpoint (None drops a pending one)."""
    return worker.set_packet_setpoint
