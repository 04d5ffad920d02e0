"""One Crazyflie: the link plus one client per CRTP port (contract in docs/architecture.md).

``connect()`` opens the link and asks which protocol the firmware speaks; the
TOCs are fetched on demand (``params.fetch_toc()``, ``log.fetch_toc()``), so a
tool that only sends setpoints does not pay for them. Every wait has a
timeout; a silent Crazyflie raises ``LinkTimeout`` naming the URI and the step.
"""
from __future__ import annotations

import functools
import logging
from typing import Optional, Tuple, Union

from crazyflie_driver.clock import WALL, Clock
from crazyflie_driver.crtp import nrf_system
from crazyflie_driver.crtp.uri import LinkUri, UsbUri, parse_link_uri
from crazyflie_driver.errors import LinkTimeout, NotSupported
from crazyflie_driver.protocol.commander import Commander
from crazyflie_driver.protocol.console import Console
from crazyflie_driver.protocol.high_level import HighLevelCommander
from crazyflie_driver.protocol.localization import LocalizationSender
from crazyflie_driver.protocol.log import LogClient
from crazyflie_driver.protocol.memory import MemoryClient
from crazyflie_driver.protocol.param import ParamClient
from crazyflie_driver.protocol.platform import Platform, toc_version
from crazyflie_driver.protocol.setpoints import SetpointSender
from crazyflie_driver.protocol.supervisor import Supervisor
from crazyflie_driver.protocol.toccache import TocCache
from crazyflie_driver.radio.link import RadioLink
from crazyflie_driver.radio.shared_radio import RadioManager, default_manager
from crazyflie_driver.radio.usb_crazyflie import UsbCrazyflie, UsbLink

_LOG = logging.getLogger(__name__)


class Crazyflie:
    """Facade composing link, platform, params, log, console and commander."""

    def __init__(self, uri: Union[str, LinkUri], radio_manager: Optional[RadioManager] = None,
                 cache_dir: Optional[str] = None, timeout: float = 1.0, link=None, clock: Clock = WALL) -> None:
        """``link`` replaces the radio link altogether (tests, other transports); ``clock`` times the
        radio link's request timeouts (``timeout`` s of its time)."""
        if timeout <= 0:
            raise ValueError("timeout must be > 0, got %r" % (timeout,))
        self.uri: LinkUri = parse_link_uri(uri) if isinstance(uri, str) else uri
        self.timeout = timeout
        if link is None:
            if isinstance(self.uri, UsbUri):                   # a Crazyflie on a USB cable
                manager = radio_manager or default_manager()
                opener = manager.usb_factory or functools.partial(UsbCrazyflie, backend=manager.backend)
                link = UsbLink(self.uri, opener, clock=clock)
            else:
                link = RadioLink(self.uri, radio_manager, clock=clock)
        self.link = link
        self.cache = TocCache(cache_dir)
        self.protocol_version = -1
        self.connected = False
        self.platform = Platform(self.link, timeout)
        self.params = ParamClient(self.link, self.cache, timeout)
        self.log = LogClient(self.link, self.cache, timeout)
        self.console = Console(self.link)
        self.commander = Commander(self.link)
        label = str(self.uri)
        self.setpoints = SetpointSender(self.link.send)
        self.localization = LocalizationSender(self.link.send)
        self.memory = MemoryClient(self.link.request, timeout, label)
        self.high_level = HighLevelCommander(self.link.send, self.link.request, self.memory, timeout=timeout,
                                             label=label)
        self.supervisor = Supervisor(self.link.send, self.link.request, timeout=timeout, label=label)

    @property
    def toc_version(self) -> int:
        """1 (8-bit TOC ids, firmware before protocol 4) or 2."""
        return toc_version(self.protocol_version)

    def connect(self) -> None:
        """Open the link and detect the protocol version; LinkTimeout if nobody answers."""
        self.link.open()
        try:
            version = self.platform.detect_protocol_version()
        except BaseException:
            self.link.close()
            raise
        self.protocol_version = version
        for client in (self.params, self.log, self.commander, self.setpoints, self.high_level, self.supervisor):
            client.protocol_version = version
        self.connected = True
        _LOG.debug("%s: protocol version %d", self.uri, version)

    def close(self) -> None:
        """Give the dongle back. Idempotent; ``connect()`` may be called again. Log blocks keep
        running onboard until the firmware notices the silence (current firmware) or a reset."""
        self.connected = False
        self.link.close()

    def __enter__(self) -> Crazyflie:
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- setpoints -------------------------------------------------------------------------------
    def send_setpoint(self, roll: float, pitch: float, yawrate: float, thrust: int) -> bool:
        """Raw RPYT setpoint (wire signs); thrust clamped to 0..60000. True when acked."""
        return self.commander.send_setpoint(roll, pitch, yawrate, thrust)

    def send_stop_setpoint(self) -> bool:
        return self.commander.send_stop_setpoint()

    def emergency_stop(self) -> None:
        """The e-stop packet (9:1 on protocol 12+, else 6:1), then a stop setpoint."""
        self.commander.send_emergency_stop()
        self.commander.send_stop_setpoint()

    def send_keepalive(self, background: bool = False) -> bool:
        """A null packet: keeps the link alive and fetches downlink (console, log data); ``background``:
        behind every other round trip waiting for the dongle (``RadioLink.poll``)."""
        return self.link.poll(background=True) if background else self.link.poll()

    # -- reboot and power (the nRF's system commands) ----------------------------------------------
    def _nrf(self, packets: Tuple[bytes, ...], what: str) -> None:
        send = getattr(self.link, "send_nrf_command", None)
        if send is None:
            raise NotSupported("%s: %s needs a radio link (the nRF takes it from the air; this link is %s)"
                               % (self.uri, what, type(self.link).__name__))
        for data in packets:
            if not send(data):
                raise LinkTimeout("%s: %s not acknowledged (is it switched on, and on this channel, data rate "
                                  "and address?)" % (self.uri, what), acked=0)

    def reboot(self, bootloader: bool = False) -> None:
        """Restart the whole Crazyflie into its firmware (or the bootloader): the link drops, parameters
        go back to their defaults and log blocks are gone. LinkTimeout when the nRF does not ack."""
        self._nrf(nrf_system.reboot_packets(bootloader), "reboot to the bootloader" if bootloader else "reboot")

    def power_off_stm(self) -> None:
        """Switch the STM32 domain (flight controller, decks) off; the nRF stays on the radio."""
        self._nrf((nrf_system.stm_power_off_packet(),), "STM32 power off")

    def power_on_stm(self) -> None:
        """Switch the STM32 domain on: it boots with fresh state."""
        self._nrf((nrf_system.stm_power_on_packet(),), "STM32 power on")

    def power_off_all(self) -> None:
        """Everything off, as the power button: nothing on the radio wakes it again."""
        self._nrf((nrf_system.all_off_packet(),), "power off")

    def __repr__(self) -> str:
        return "<Crazyflie %s protocol %d>" % (self.uri, self.protocol_version)
