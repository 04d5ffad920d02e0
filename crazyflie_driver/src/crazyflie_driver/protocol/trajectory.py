"""Trajectories for the high-level commander: poly4d pieces, their two memory formats.

A piece is a duration (s) and, per axis x, y, z (m) and yaw (rad), 8 polynomial coefficients in
ascending powers of the time since the start of the piece. ``pack_poly4d`` lays pieces out as the
firmware reads them (33 little-endian f32 each); ``pack_compressed`` writes the compact format
(int16 mm / tenths of a degree, each segment a Bezier curve of degree 0, 1, 3 or 7 that starts
where the previous one ended). Layouts are in docs/protocol.md.
"""
from __future__ import annotations

import math
import struct
from typing import Iterable, List, NamedTuple, Sequence, Tuple

from crazyflie_driver.errors import TrajectoryError
from crazyflie_driver.protocol.checks import INT16_MAX

COEFFICIENTS = 8
PIECE_BYTES = 33 * 4
#: Trajectory identifiers the firmware accepts (it keeps 31 descriptors).
MAX_TRAJECTORY_ID = 30
#: Coefficients this small (after scaling to the piece's duration) count as zero when choosing
#: the lowest Bezier degree of a compressed segment: below a tenth of a wire unit.
_ZERO = 1e-5


class Piece(NamedTuple):
    """One poly4d piece: duration (s) and 8 coefficients per axis (m, m, m, rad)."""

    duration: float
    x: Tuple[float, ...]
    y: Tuple[float, ...]
    z: Tuple[float, ...]
    yaw: Tuple[float, ...]


def make_piece(duration: float, x: Sequence[float], y: Sequence[float], z: Sequence[float],
               yaw: Sequence[float], index: int = 0) -> Piece:
    """A checked piece; TrajectoryError names the piece ``index`` and what is wrong with it."""
    try:
        d = float(duration)
    except (TypeError, ValueError):
        d = float("nan")
    if not (math.isfinite(d) and d > 0):
        raise TrajectoryError("piece %d: duration must be a finite number of seconds > 0, got %r" % (index, duration))
    axes = []
    for name, coefficients in (("x", x), ("y", y), ("z", z), ("yaw", yaw)):
        values = list(coefficients)
        if len(values) != COEFFICIENTS:
            raise TrajectoryError("piece %d: %s has %d coefficients; every axis needs exactly %d (ascending powers "
                                  "of time)" % (index, name, len(values), COEFFICIENTS))
        for k, c in enumerate(values):
            if isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c):
                raise TrajectoryError("piece %d: %s coefficient %d is not a finite number: %r" % (index, name, k, c))
        axes.append(tuple(float(c) for c in values))
    return Piece(d, *axes)


def pieces_from_rows(rows: Iterable[Sequence[float]]) -> List[Piece]:
    """Pieces from rows ``duration, x^0..x^7, y^0..y^7, z^0..z^7, yaw^0..yaw^7`` (the usual CSV form)."""
    pieces = []
    for i, row in enumerate(rows):
        row = list(row)
        if len(row) != 1 + 4 * COEFFICIENTS:
            raise TrajectoryError("row %d has %d values; a piece row needs 33 (duration and 8 coefficients for "
                                  "each of x, y, z, yaw)" % (i, len(row)))
        pieces.append(make_piece(row[0], row[1:9], row[9:17], row[17:25], row[25:33], index=i))
    return pieces


def check_id(trajectory_id: int) -> int:
    if isinstance(trajectory_id, bool) or not isinstance(trajectory_id, int) \
            or not 0 <= trajectory_id <= MAX_TRAJECTORY_ID:
        raise TrajectoryError("trajectory id must be an integer 0..%d, got %r" % (MAX_TRAJECTORY_ID, trajectory_id))
    return trajectory_id


def pack_poly4d(pieces: Sequence[Piece]) -> bytes:
    """The pieces as the trajectory memory holds them: x, y, z, yaw coefficients, then duration."""
    if not pieces:
        raise TrajectoryError("a trajectory needs at least one piece")
    return b"".join(struct.pack("<33f", *p.x, *p.y, *p.z, *p.yaw, p.duration) for p in pieces)


def evaluate(piece: Piece, t: float) -> Tuple[float, float, float, float]:
    """(x, y, z, yaw) of ``piece`` at ``t`` seconds after its start."""
    def at_t(axis: Sequence[float]) -> float:
        return float(sum(c * t ** k for k, c in enumerate(axis)))
    return at_t(piece.x), at_t(piece.y), at_t(piece.z), at_t(piece.yaw)


def bezier_points(coefficients: Sequence[float], duration: float) -> List[float]:
    """Control points of the polynomial over [0, duration] in the lowest degree of 0, 1, 3, 7 that
    represents it; the first point (the start) is included."""
    a = [c * duration ** k for k, c in enumerate(coefficients)]   # the same curve in s = t / duration
    top = max((k for k, v in enumerate(a) if abs(v) > _ZERO), default=0)
    degree = 0 if top == 0 else 1 if top == 1 else 3 if top <= 3 else 7
    return [sum(math.comb(i, k) / math.comb(degree, k) * a[k] for k in range(min(i, top) + 1))
            for i in range(degree + 1)]


_TYPE_OF_DEGREE = {0: 0, 1: 1, 3: 2, 7: 3}


def _mm(value: float, what: str) -> int:
    n = int(value * 1000.0)
    if not -INT16_MAX <= n <= INT16_MAX:
        raise TrajectoryError("%s = %.3f m is outside the compressed format's +-32.767 m" % (what, value))
    return n


def _decidegrees(value: float, what: str) -> int:
    n = int(math.degrees(value) * 10.0)
    if not -INT16_MAX <= n <= INT16_MAX:
        raise TrajectoryError("%s = %.3f rad is outside the compressed format's +-3276.7 degrees" % (what, value))
    return n


def pack_compressed(pieces: Sequence[Piece]) -> bytes:
    """The compressed format: start point, one segment per piece, then an end marker (duration 0).

    Each piece must start where the previous one ended (the format stores that point once).
    """
    if not pieces:
        raise TrajectoryError("a trajectory needs at least one piece")
    start = evaluate(pieces[0], 0.0)
    out = struct.pack("<4h", *(_mm(v, "start " + a) for v, a in zip(start[:3], "xyz")),
                      _decidegrees(start[3], "start yaw"))
    previous = start
    for i, piece in enumerate(pieces):
        here = evaluate(piece, 0.0)
        for axis, (a, b) in enumerate(zip(previous, here)):
            if abs(a - b) > 1e-3:
                raise TrajectoryError("piece %d starts at %s = %.4f but piece %d ended at %.4f; the compressed format "
                                      "needs continuous pieces" % (i, "xyz"[axis] if axis < 3 else "yaw", b, i - 1, a))
        duration_ms = int(piece.duration * 1000.0)
        if not 0 < duration_ms <= 0xFFFF:
            raise TrajectoryError("piece %d: duration %.3f s does not fit the compressed format (1 ms .. 65.535 s)"
                                  % (i, piece.duration))
        types = 0
        body = b""
        for axis, coefficients in enumerate((piece.x, piece.y, piece.z, piece.yaw)):
            points = bezier_points(coefficients, piece.duration)
            types |= _TYPE_OF_DEGREE[len(points) - 1] << (2 * axis)
            encode = _decidegrees if axis == 3 else _mm
            what = "piece %d %s control point" % (i, "xyzw"[axis] if axis < 3 else "yaw")
            body += b"".join(struct.pack("<h", encode(p, what)) for p in points[1:])
        out += struct.pack("<BH", types, duration_ms) + body
        previous = evaluate(piece, piece.duration)
    return out + struct.pack("<BH", 0, 0)
