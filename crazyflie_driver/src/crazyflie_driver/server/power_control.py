"""When the server may arm, recover, reboot or switch a Crazyflie, and what it says: decided without ROS.

The worker (``server.worker``) carries these out on its link; the node only registers the services.
A reboot or a power change while the server is streaming thrust would drop the Crazyflie out of the
air, so it is refused with the way out (land, or the emergency service); after an emergency the
supervisor stays locked until a reboot, so arming and crash recovery are refused and the reboot
service is named instead.
"""
from __future__ import annotations

from typing import Optional

#: The per-Crazyflie services (beside ``emergency``): the names Crazyswarm2 and crazyflie_ros use.
ARM_SERVICE = "arm"
RECOVER_SERVICE = "recover"
REBOOT_SERVICE = "reboot"
POWER_OFF_SERVICE = "power_off"
POWER_ON_SERVICE = "power_on"

#: How to fly a Crazyflie again whose supervisor holds it locked (an emergency, a watchdog cut).
REBOOT_ADVICE = ("call its %s service (the server sets its parameters and log blocks up again by itself); "
                 "switched off and on by hand it must be removed and added again" % REBOOT_SERVICE)


def arm_refusal(do_arm: bool, emergency: bool, offline: str) -> Optional[str]:
    """Why an arming (or disarming) request is refused, or None. ``offline``: '' while the link runs,
    else what is wrong with it. Disarming is always allowed where it can reach the Crazyflie."""
    if offline:
        return "cannot %s it: %s" % ("arm" if do_arm else "disarm", offline)
    if do_arm and emergency:
        return "not armed: an emergency stop holds it until a reboot; " + REBOOT_ADVICE
    return None


def recover_refusal(emergency: bool, offline: str) -> Optional[str]:
    """Why a crash-recovery request is refused, or None."""
    if offline:
        return "cannot recover it: %s" % offline
    if emergency:
        return "not recovered: an emergency stop is not a crash, it holds until a reboot; " + REBOOT_ADVICE
    return None


def power_change_refusal(what: str, flying_for: Optional[float], supervisor_flying: bool,
                         emergency: bool) -> Optional[str]:
    """Why a reboot or power-off is refused, or None: never while it flies (``flying_for``: seconds
    since the server's last setpoint with thrust, None when it streams none; ``supervisor_flying``:
    its supervisor's latest report says flying, e.g. under the high-level commander)."""
    if emergency:
        return None
    if flying_for is not None:
        why = "it was sent thrust %.1f s ago" % flying_for
    elif supervisor_flying:
        why = "its supervisor reports it flying"
    else:
        return None
    return ("not done: a %s would drop it out of the air (%s); land it first, or stop it with its "
            "emergency service" % (what, why))
