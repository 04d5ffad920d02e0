"""The language of fault injection: the ``fault`` command's words and the world server's control arguments.

A user names a fault in words (``unplug 0``, ``loss 0 --packet 0.3 --ack 0.1``, ``latency 0 50ms``,
``power crazyflie1 off``, ``battery crazyflie1 3.3``, ``mocap crazyflie1 --freeze 2``);
``parse_command`` turns them into one control operation of the world server (``WorldServer.control``)
and its JSON arguments. The ``crazyflie_tools fault`` command, the sim node's ``~fault`` service and
its ``faults`` launch argument all use it, so the three take the same words. ``ControlArgs`` reads
and checks the arguments on the server side, where every operation's values are validated once:
every error names the operation, the argument and what is allowed.

Units on input: loss as a fraction 0..1 or a percentage (``0.3``, ``30%``), durations in seconds
or with a unit (``2``, ``2s``, ``50ms``), battery as volts or a charge percentage (``3.3``, ``3.3V``,
``20%``). The control operations keep the medium's units: loss in percent, latency in seconds.
"""
from __future__ import annotations

import argparse
import math
import shlex
from typing import Any, Callable, Dict, List, Mapping, NoReturn, Optional, Sequence, Tuple, Union

MAX_RADIO_LATENCY_S = 1.0        # more than this is not a radio any more: a unit mistake
#: Motion-capture faults of one body (``mocap VEHICLE ...``), bounded to what a tracking system can do:
#: position noise σ (m): 100 m makes nearly every pose a far ghost (beyond the packed format's +-32.767 m),
#: more only overflows;
MAX_MOCAP_NOISE_M = 100.0
#: extra latency (s): real systems deliver in milliseconds; 1 s is five times the swarm's stale threshold,
#: so every reaction to a late pose can be exercised; more is a unit mistake;
MAX_MOCAP_LATENCY_S = 1.0
#: lowest rate (Hz): one frame every 10 s; slower is a hidden body (``--hide`` says so).
MIN_MOCAP_RATE_HZ = 0.1
BATTERY_VOLTS = (2.5, 4.3)       # what a 1S cell can read; anything outside is a mistake


class FaultError(ValueError):
    """A fault command or control argument that cannot be applied; the message says what to type."""


# --- values --------------------------------------------------------------------------------------
def fraction(what: str, text: Union[str, float]) -> float:
    """``0.3`` or ``30%`` -> 0.3; a value outside 0..1 is an error."""
    s = str(text).strip()
    try:
        value = float(s[:-1]) / 100.0 if s.endswith("%") else float(s)
    except ValueError:
        raise FaultError("%s must be a fraction 0..1 or a percentage like 30%%, got %r" % (what, text)) from None
    if not 0.0 <= value <= 1.0:
        raise FaultError("%s must be a fraction 0..1 or a percentage like 30%%, got %r" % (what, text))
    return value


def duration(what: str, text: Union[str, float]) -> float:
    """``2``, ``2s``, ``50ms`` -> seconds (>= 0)."""
    s = str(text).strip().lower()
    scale = 1.0
    if s.endswith("ms"):
        s, scale = s[:-2], 1e-3
    elif s.endswith("s"):
        s = s[:-1]
    try:
        value = float(s) * scale
    except ValueError:
        raise FaultError("%s must be a duration like 2, 2s or 50ms, got %r" % (what, text)) from None
    if not (value >= 0 and math.isfinite(value)):
        raise FaultError("%s must be a duration >= 0, got %r" % (what, text))
    return value


def _number(flag: str, text: Union[str, float], unit: str, minimum: float, maximum: float) -> float:
    """``text`` as a number of ``unit`` within ``minimum``..``maximum``."""
    bound = ">= %g %s" % (minimum, unit) if maximum == math.inf else "from %g to %g %s" % (minimum, maximum, unit)
    try:
        value = float(text)
    except ValueError:
        raise FaultError("%s must be a number %s, got %r" % (flag, bound, text)) from None
    if not minimum <= value <= maximum:
        raise FaultError("%s must be a number %s, got %r" % (flag, bound, text))
    return value


def battery_level(text: str) -> Dict[str, float]:
    """``3.3`` / ``3.3V`` -> {"voltage": 3.3}; ``20%`` -> {"charge": 0.2}."""
    s = str(text).strip()
    if s.endswith("%"):
        return {"charge": fraction("battery charge", s)}
    try:
        volts = float(s[:-1] if s.lower().endswith("v") else s)
    except ValueError:
        raise FaultError("battery level must be volts (3.3 or 3.3V) or a charge (20%%), got %r" % (text,)) from None
    if not BATTERY_VOLTS[0] <= volts <= BATTERY_VOLTS[1]:
        raise FaultError("battery voltage must be within %.1f..%.1f V (or give a charge like 20%%), got %r"
                         % (BATTERY_VOLTS + (text,)))
    return {"voltage": volts}


# --- the server side: one operation's arguments ---------------------------------------------------
_MISSING = object()


class ControlArgs:
    """The JSON arguments of control operation ``op``, read with their checks (FaultError otherwise)."""

    def __init__(self, op: str, args: Mapping[str, Any]) -> None:
        self.op = op
        self.args = dict(args)

    def _error(self, key: str, what: str) -> NoReturn:
        raise FaultError("%s: %r %s" % (self.op, key, what))

    def _get(self, key: str, default: Any) -> Any:
        value = self.args.get(key)
        if value is None:
            if default is _MISSING:
                self._error(key, "is required")
            return default
        return value

    def has(self, key: str) -> bool:
        return self.args.get(key) is not None

    def text(self, key: str, default: Any = _MISSING) -> Any:
        value = self._get(key, default)
        if value is not default and not isinstance(value, str):
            self._error(key, "must be a string, got %r" % (value,))
        return value

    def integer(self, key: str, default: Any = _MISSING, low: int = 0) -> Any:
        value = self._get(key, default)
        if value is default:
            return value
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            self._error(key, "must be an integer >= %d, got %r" % (low, value))
        return value

    def number(self, key: str, default: Any = _MISSING, low: float = -math.inf, high: float = math.inf) -> Any:
        value = self._get(key, default)
        if value is default:
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
            self._error(key, "must be a number in [%g, %g], got %r" % (low, high, value))
        return float(value)

    def flag(self, key: str, default: Any = _MISSING) -> Any:
        value = self._get(key, default)
        if value is not default and not isinstance(value, bool):
            self._error(key, "must be true or false, got %r" % (value,))
        return value

    def span(self, key: str) -> Optional[float]:
        """A duration in seconds, ``true`` for good (inf), ``false``/0 to end it, or None when not given."""
        value = self.args.get(key)
        if value is None:
            return None
        if value is True:
            return math.inf
        if value is False:
            return 0.0
        return self.number(key, low=0.0)


# --- the command ---------------------------------------------------------------------------------
USAGE = """fault <what> [args]
  list                                  the faults in force
  clear [DONGLE|VEHICLE]                end radio and motion-capture faults (all, or one dongle's/vehicle's)
  unplug DONGLE | replug DONGLE         pull the simulated Crazyradio out / plug it back in
  loss DONGLE [--packet P] [--ack P]    packet loss, ack loss: a fraction 0..1 or a percentage (30%)
  latency DONGLE DURATION               extra delay on every round trip (50ms, 0.05s)
  power VEHICLE on|off                  switch a Crazyflie off or on (on = a fresh boot)
  battery VEHICLE LEVEL                 drain or charge the battery: volts under load (3.3, 3.3V) or 20%
  mocap VEHICLE [--freeze [S]] [--hide [S]] [--noise M] [--latency D] [--rate HZ] [--dropout P] [--clear]
                                        motion-capture faults of one body; no S: for good, 0: end it
VEHICLE is the simulated Crazyflie's name or radio URI; DONGLE the dongle index of radio://<DONGLE>/..."""


class _Parser(argparse.ArgumentParser):
    """argparse that raises FaultError instead of exiting (a service must not exit)."""

    def error(self, message: str) -> NoReturn:
        raise FaultError(message)


def _build_parser() -> _Parser:
    p = _Parser(prog="fault", add_help=False, usage=USAGE.replace("%", "%%"))
    sub = p.add_subparsers(dest="what", metavar="what")
    sub.required = True

    def add(name: str) -> _Parser:
        return sub.add_parser(name, add_help=False, usage=("fault " + _usage_line(name)).replace("%", "%%"))

    add("list")
    add("clear").add_argument("target", nargs="?")
    for name in ("unplug", "replug"):
        add(name).add_argument("dongle")
    q = add("loss")
    q.add_argument("dongle")
    q.add_argument("--packet")
    q.add_argument("--ack")
    q = add("latency")
    q.add_argument("dongle")
    q.add_argument("delay")
    q = add("power")
    q.add_argument("vehicle")
    q.add_argument("state", choices=("on", "off"))
    q = add("battery")
    q.add_argument("vehicle")
    q.add_argument("level")
    q = add("mocap")
    q.add_argument("vehicle")
    q.add_argument("--freeze", nargs="?", const="forever")
    q.add_argument("--hide", nargs="?", const="forever")
    q.add_argument("--noise")
    q.add_argument("--latency")
    q.add_argument("--rate")
    q.add_argument("--dropout")
    q.add_argument("--clear", action="store_true")
    return p


def _usage_line(name: str) -> str:
    for line in USAGE.splitlines():
        words = line.split()
        if words and words[0] == name:
            return line.split("  ")[1].strip()
    return name


def _dongle(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise FaultError("dongle must be a number (the 0 of radio://0/...), got %r" % (text,)) from None
    if value < 0:
        raise FaultError("dongle must be >= 0, got %r" % (text,))
    return value


def _span(what: str, text: str) -> Union[float, bool]:
    """``--freeze``/``--hide`` value: ``forever`` (no value given) -> True, else seconds."""
    return True if text == "forever" else duration(what, text)


def parse_command(words: Union[str, Sequence[str]]) -> Tuple[str, Dict[str, Any]]:
    """The control operation and arguments for a fault command (words or one string); FaultError if bad."""
    if isinstance(words, str):
        try:
            words = shlex.split(words)
        except ValueError as e:
            raise FaultError("cannot read %r: %s" % (words, e)) from None
    words = list(words)
    if not words:
        raise FaultError("say which fault: list, clear, unplug, replug, loss, latency, power, battery or mocap")
    a = _build_parser().parse_args(words)
    return _COMMANDS[a.what](a)


_Command = Tuple[str, Dict[str, Any]]


def _list_command(a: argparse.Namespace) -> _Command:
    return "faults", {}


def _clear_command(a: argparse.Namespace) -> _Command:
    """``clear``: every fault, one dongle's (a number) or one vehicle's (a name or URI)."""
    if a.target is None:
        return "clear_faults", {}
    if a.target.isdigit():
        return "clear_faults", {"dongle": int(a.target)}
    return "clear_faults", {"uri": a.target}


def _plug_command(a: argparse.Namespace) -> _Command:
    return "set_dongle_faults", {"dongle": _dongle(a.dongle), "unplugged": a.what == "unplug"}


def _loss_command(a: argparse.Namespace) -> _Command:
    """``loss``: fractions on input, percent for the medium."""
    if a.packet is None and a.ack is None:
        raise FaultError("loss: give --packet P and/or --ack P (a fraction 0..1 or a percentage)")
    args: Dict[str, Any] = {"dongle": _dongle(a.dongle)}
    if a.packet is not None:
        args["packet_loss"] = fraction("packet loss", a.packet) * 100.0
    if a.ack is not None:
        args["ack_loss"] = fraction("ack loss", a.ack) * 100.0
    return "set_dongle_faults", args


def _latency_command(a: argparse.Namespace) -> _Command:
    delay = duration("latency", a.delay)
    if delay > MAX_RADIO_LATENCY_S:
        raise FaultError("latency %r is over %g s: give a unit, e.g. %sms" % (a.delay, MAX_RADIO_LATENCY_S,
                                                                              a.delay))
    return "set_dongle_faults", {"dongle": _dongle(a.dongle), "latency_s": delay}


def _power_command(a: argparse.Namespace) -> _Command:
    return "power", {"uri": a.vehicle, "on": a.state == "on"}


def _battery_command(a: argparse.Namespace) -> _Command:
    return "set_battery", dict(battery_level(a.level), uri=a.vehicle)


def _mocap_command(a: argparse.Namespace) -> _Command:
    return "set_mocap_faults", _mocap_args(a)


#: The parser's sub-command -> the control operation and its arguments.
_COMMANDS: Dict[str, Callable[[argparse.Namespace], _Command]] = {
    "list": _list_command,
    "clear": _clear_command,
    "unplug": _plug_command,
    "replug": _plug_command,
    "loss": _loss_command,
    "latency": _latency_command,
    "power": _power_command,
    "battery": _battery_command,
    "mocap": _mocap_command,
}


def _mocap_args(a: argparse.Namespace) -> Dict[str, Any]:
    args: Dict[str, Any] = {"uri": a.vehicle}
    if a.clear:
        args["clear"] = True
    if a.freeze is not None:
        args["freeze_s"] = _span("--freeze", a.freeze)
    if a.hide is not None:
        args["hide_s"] = _span("--hide", a.hide)
    if a.noise is not None:
        args["noise_m"] = _number("--noise", a.noise, "m", 0.0, MAX_MOCAP_NOISE_M)
    if a.latency is not None:
        args["latency_s"] = duration("--latency", a.latency)
        if args["latency_s"] > MAX_MOCAP_LATENCY_S:
            raise FaultError("--latency %r is over %g s (motion capture delivers in milliseconds): give a unit, "
                             "e.g. %sms" % (a.latency, MAX_MOCAP_LATENCY_S, a.latency))
    if a.rate is not None:
        args["rate_hz"] = _number("--rate", a.rate, "Hz", MIN_MOCAP_RATE_HZ, math.inf)
    if a.dropout is not None:
        args["dropout"] = fraction("--dropout", a.dropout)
    if len(args) == 1:
        raise FaultError("mocap: say what goes wrong: --freeze [S], --hide [S], --noise M, --latency D, "
                         "--rate HZ, --dropout P or --clear")
    return args


def split_commands(text: str) -> List[str]:
    """The ``faults`` launch argument: fault commands separated by ';' (blank ones skipped)."""
    return [c.strip() for c in str(text).split(";") if c.strip()]


def format_faults(faults: Sequence[Sequence[str]]) -> str:
    """The ``faults`` operation's answer (``[target, description]`` pairs) as lines for a terminal."""
    if not faults:
        return "no faults injected"
    width = max(len(t) for t, _ in faults)
    return "\n".join("%-*s  %s" % (width, t, d) for t, d in faults)


def describe_result(op: str, args: Dict[str, Any], result: Any) -> str:
    """What the world answered, in one line (several for ``list``)."""
    if op in ("faults", "clear_faults"):
        return format_faults(result)
    if op == "set_dongle_faults":
        r = result
        state = "unplugged" if r["unplugged"] else "plugged in"
        return "dongle %d: %s, packet loss %.0f %%, ack loss %.0f %%, latency %.0f ms" % (
            r["dongle"], state, r["packet_loss"], r["ack_loss"], r["latency_s"] * 1000.0)
    if op == "power":
        return "%s: switched %s" % (args["uri"], "on" if result["powered"] else "off")
    if op == "set_battery":
        return args["uri"] + ": battery %.2f V, %.0f %% charge" % (result["vbat"], result["charge"] * 100.0)
    if op == "set_mocap_faults":
        return "%s: motion capture %s" % (result["name"], result["faults"])
    return str(result)
