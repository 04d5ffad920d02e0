"""Exceptions of the library. Each message names the URI and what was being done."""
from __future__ import annotations


class CrazyflieError(Exception):
    """Base class of every error this library raises on purpose."""


class UriError(CrazyflieError, ValueError):
    """A malformed Crazyflie URI; the message names the bad part."""


class RadioNotFound(CrazyflieError):
    """No Crazyradio dongle at the requested index."""


class RadioAccessDenied(CrazyflieError):
    """The dongle exists but cannot be opened (usually missing udev rules)."""


class RadioUnplugged(CrazyflieError):
    """The dongle disappeared while in use."""


class RadioMediumGone(CrazyflieError, ConnectionError):
    """What carries a radio's packets went away: the simulated world behind a fake Crazyradio stopped.
    (A real Crazyradio has no such thing; a pulled dongle is RadioUnplugged.)"""


class RadioInUse(RadioAccessDenied):
    """Another program holds the dongle (one program at a time can use a Crazyradio)."""


class LinkTimeout(CrazyflieError, TimeoutError):
    """The Crazyflie did not answer in time. ``acked``: packets it acknowledged meanwhile (None: not
    counted), so a caller can tell a silent Crazyflie (0) from one whose answer went elsewhere."""

    def __init__(self, message: str = "", acked=None) -> None:
        super().__init__(message)
        self.acked = acked


class LinkLost(CrazyflieError):
    """Too many packets in a row went unacknowledged."""


class ConnectCancelled(CrazyflieError):
    """A connect sequence stopped before it finished: its add timed out or it was removed meanwhile."""


class ProtocolError(CrazyflieError):
    """The Crazyflie answered something the protocol does not allow."""


class UnknownName(CrazyflieError, KeyError):
    """A parameter or log variable that is not in the Crazyflie's TOC."""

    def __str__(self) -> str:  # KeyError would add quotes
        return str(self.args[0]) if self.args else "unknown name"


class LogConfigError(CrazyflieError, ValueError):
    """A log block the firmware cannot hold (too big, too many, bad period)."""


class ReadOnlyParam(CrazyflieError):
    """A write to a parameter the firmware marks read-only."""


class ParamValueError(CrazyflieError, ValueError):
    """A parameter value that cannot be converted to the parameter's type or is out of range."""


class CommandValueError(CrazyflieError, ValueError):
    """A command argument that cannot go on the wire (NaN, out of range, bad group mask)."""


class TrajectoryError(CommandValueError):
    """A trajectory that cannot be uploaded or started (piece shape, memory size, identifier)."""


class NotSupported(CrazyflieError):
    """The Crazyflie's protocol version lacks the port or command asked for."""


class CommandRejected(CrazyflieError):
    """A command not taken: the Crazyflie answered it with an error code, or (a subclass) the server
    refused it before anything was sent."""


class FlightRefused(CommandRejected):
    """A takeoff, go_to or start_trajectory refused by the server, nothing sent: it would cancel a
    landing under way (a safety reaction's, the shutdown's or removal's, or a land command's) or start
    a flight nobody would supervise (the server is letting the Crazyflie go). Land and stop are
    still taken, and the command is once the landing has ended."""


class EmergencyActive(CommandRejected):
    """A command refused by the server, nothing sent, because the Crazyflie is in emergency: its motors
    are stopped until it is restarted (and removed and added again)."""


class SwarmConfigError(CrazyflieError, ValueError):
    """A swarm file that cannot be flown; the message names the file, the line or entry, and the fix."""


class FirmwareTableError(CrazyflieError, ValueError):
    """A simulated firmware variable table that cannot be loaded; the message names the file, the line and the fix."""


class ConfigBlockError(CrazyflieError, ValueError):
    """Bytes that are not a valid EEPROM configuration block, or values one cannot hold."""


class FirmwareImageError(CrazyflieError, ValueError):
    """A file given to flash is not a firmware image for the chosen target (the message says why)."""
