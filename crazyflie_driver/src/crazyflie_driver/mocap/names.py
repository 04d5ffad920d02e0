"""Tracker names -> ROS names, the way vrpn_client_ros cleans them.

A VRPN sender name is whatever the mocap software calls the body (Motive: "Rigid Body 1").
vrpn_client_ros drops an invalid first character (valid: a letter, '/' or '~'), then removes
every later character that is not a letter, digit, '/' or '_', and creates no topics when the
result still is not a valid ROS name. "Rigid Body 1" -> "RigidBody1", "cf-1" -> "cf1",
"_cf" -> "cf", "12cf" -> "2cf" (invalid: no topics).
"""
from __future__ import annotations

from typing import Optional


def _valid_first(c: str) -> bool:
    return (c.isascii() and c.isalpha()) or c in "/~"


def _valid_later(c: str) -> bool:
    return (c.isascii() and c.isalnum()) or c in "/_"


def is_valid_ros_name(name: str) -> bool:
    """ROS 1 graph-name syntax: first char a letter, '/' or '~'; then letters, digits, '_', '/'."""
    return bool(name) and _valid_first(name[0]) and all(_valid_later(c) for c in name[1:])


def clean_tracker_name(name: str) -> Optional[str]:
    """The ROS name vrpn_client_ros makes of a tracker name, or None when none is possible."""
    if not name:
        return None
    head = name[0] if _valid_first(name[0]) else ""     # an invalid first char is dropped
    cleaned = head + "".join(c for c in name[1:] if _valid_later(c))
    return cleaned if is_valid_ros_name(cleaned) else None


def frame_name(clean_name: str) -> str:
    """tf frame id for a cleaned tracker name (tf2 frame ids carry no leading '/')."""
    return clean_name.lstrip("/")
