"""Motion-capture transforms written straight into ROS's wire format: one tf2_msgs/TFMessage per frame.

A simulated motion-capture frame of many bodies becomes ONE ``tf2_msgs/TFMessage`` on ``/tf`` (as
``tf2_ros.TransformBroadcaster`` publishes a list) whose bytes are packed here with one precompiled
``struct`` per body, instead of a ``geometry_msgs/TransformStamped`` object per body that genpy
then serialises field by field. The same bytes serve a body's own ``TransformStamped`` topic
(vicon_bridge's ``/vicon/<name>/<name>``). Wire layout of a TransformStamped (ROS 1
serialisation, little endian): header (seq u32, stamp secs u32, nsecs u32, frame_id u32 length +
bytes), child_frame_id (u32 length + bytes), translation 3 × f64, rotation x, y, z, w 4 × f64.
"""
from __future__ import annotations

import struct
from typing import Any, Sequence

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<3I")       # seq, secs, nsecs
_POSE = struct.Struct("<7d")        # x, y, z, qx, qy, qz, qw
_NSEC = 1000000000


def _string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return _U32.pack(len(raw)) + raw


class TransformWire:
    """Packs one body's TransformStamped (parent -> child) for a stamp and a pose."""

    def __init__(self, parent: str, child: str) -> None:
        self.child = child
        self._frames = _string(parent) + _string(child)

    def pack(self, stamp_ns: int, position: Sequence[float], quaternion: Sequence[float], seq: int = 0) -> bytes:
        """Wire bytes of the TransformStamped; ``stamp_ns`` ROS time in integer nanoseconds."""
        secs, nsecs = divmod(int(stamp_ns), _NSEC)
        return (_STAMP.pack(seq & 0xFFFFFFFF, secs, nsecs) + self._frames
                + _POSE.pack(float(position[0]), float(position[1]), float(position[2]), float(quaternion[0]),
                             float(quaternion[1]), float(quaternion[2]), float(quaternion[3])))


def packed_message_types():
    """(PackedTFMessage, PackedTransformStamped): message classes rospy publishes from packed bytes.

    They are the real tf2_msgs/TFMessage and geometry_msgs/TransformStamped types (same md5, same
    wire format) whose ``serialize`` writes bytes packed by ``TransformWire``.
    """
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    class PackedTFMessage(TFMessage):
        __slots__ = ("_parts",)

        def __init__(self, parts: Sequence[bytes]) -> None:
            super().__init__()
            self._parts = list(parts)

        def serialize(self, buff: Any) -> None:
            buff.write(_U32.pack(len(self._parts)))
            for part in self._parts:
                buff.write(part)

    class PackedTransformStamped(TransformStamped):
        __slots__ = ("_packed",)

        def __init__(self, packed: bytes) -> None:
            super().__init__()
            self._packed = packed

        def serialize(self, buff: Any) -> None:
            # rospy numbers each message through header.seq; the rest is as packed
            buff.write(_U32.pack(self.header.seq & 0xFFFFFFFF))
            buff.write(self._packed[4:])

    return PackedTFMessage, PackedTransformStamped
