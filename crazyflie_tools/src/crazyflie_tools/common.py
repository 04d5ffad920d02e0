"""What every command-line tool shares: the --uri/--timeout options, opening a Crazyflie,
and turning the library's errors into one clear line and exit code 1 (no traceback)."""
from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Callable, Optional

from crazyflie_driver import usb_choice
from crazyflie_driver.errors import (
    CrazyflieError,
    LinkTimeout,
    RadioAccessDenied,
    RadioInUse,
    RadioNotFound,
    UnknownName,
    UriError,
)
from crazyflie_driver.protocol.crazyflie import Crazyflie

from .sim_hint import sim_hint

DEFAULT_URI = "radio://0/80/2M/E7E7E7E7E7"
UDEV_HINT = ("install the udev rules shipped in crazyflie_driver/udev into /etc/udev/rules.d/ "
             "and add your user to group plugdev, then re-plug the dongle")


def parser(description: str, uri: bool = True) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    if uri:
        p.add_argument("--uri", default=DEFAULT_URI,
                       help="radio://<dongle>/<channel>/<250K|1M|2M>[/<address>] (default %(default)s)")
    p.add_argument("--timeout", type=float, default=1.0,
                   help="seconds to wait for each answer of the Crazyflie (default %(default)s)")
    return p


def open_crazyflie(args: argparse.Namespace, cache_dir: Optional[str] = None) -> Crazyflie:
    """A connected Crazyflie for ``args.uri`` (errors are left to ``run``)."""
    cf = Crazyflie(args.uri, usb_choice.radio_manager(), cache_dir=cache_dir, timeout=args.timeout)
    cf.connect()
    return cf


POLL_PAUSE_S = 0.002
"""Pause [s] between two polls of a tool that listens (keep-alives fetch what the Crazyflie queued)."""


def listen_then_close(cf: Crazyflie, seconds: float) -> None:
    """Poll ``cf`` for ``seconds`` of wall time (the person's --seconds; no ROS here), then close its link."""
    try:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            cf.send_keepalive()
            time.sleep(POLL_PAUSE_S)
    finally:
        cf.close()


def describe_error(error: BaseException) -> str:
    """One line for the user: what went wrong and, where it helps, what to do."""
    text = str(error) or error.__class__.__name__
    if isinstance(error, RadioInUse):
        return text         # not a permission problem: the udev hint would mislead
    if isinstance(error, RadioAccessDenied):
        if "plugdev" not in text:
            text += " (%s)" % UDEV_HINT
        return text if "permission denied" in text.lower() else "permission denied: " + text
    if isinstance(error, RadioNotFound):
        return text
    if isinstance(error, UriError):
        return "bad URI: " + text
    if isinstance(error, UnknownName):
        return text
    if isinstance(error, LinkTimeout) and error.acked == 0 and "switched on" not in text:
        # only when nothing acknowledged: a Crazyflie that acks is switched on (see RadioLink's reasons)
        return text + " (is the Crazyflie switched on, and on this channel, data rate and address?)"
    return text


def run(main: Callable[[argparse.Namespace], int], args: argparse.Namespace,
        prog: str) -> int:
    """Call ``main(args)``; library, USB and OS errors become ``prog: error: ...`` and code 1."""
    try:
        return main(args)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # the reader went away (`listParams ... | head`): stop quietly, as other command-line tools do
        sys.stdout = open(os.devnull, "w")
        return 0
    except (CrazyflieError, OSError, ValueError) as error:
        # OSError covers pyusb's USBError; ValueError covers bad option values.
        print("%s: error: %s" % (prog, describe_error(error)), file=sys.stderr)
        if isinstance(error, RadioNotFound):
            hint = sim_hint(prog)
            if hint:
                print("%s: %s" % (prog, hint), file=sys.stderr)
        return 1


