"""What a simulated Crazyflie saw: the record its port handlers update and tests read."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple


@dataclass
class SimState:
    """What the simulated Crazyflie saw, for tests and the world server's control calls."""

    powered: bool = True
    emergency: bool = False
    emergency_reason: str = ""
    armed: bool = True                      # auto-arming is the firmware default
    last_setpoint: Optional[Tuple[float, float, float, int]] = None
    setpoints: int = 0
    last_generic: Optional[Tuple[int, bytes]] = None
    external_position: Optional[Tuple[float, float, float]] = None
    external_measurements: int = 0
    setpoint_stop_notices: int = 0
    rx_unicast: int = 0                     # radio packets taken on the own address (radio.numRxUc)
    rx_broadcast: int = 0                   # and on the broadcast address (radio.numRxBc)
    halted: str = ""                        # why the STM stopped on an assert ('' while it runs)
    estop_watchdog: Optional[float] = None
    packets_by_port: Dict[int, int] = field(default_factory=dict)
    sent_by_port: Dict[int, int] = field(default_factory=dict)     # packets sent to the host (radio or cable)
    tx_dropped: int = 0
    tx_last_wait_s: float = 0.0             # time the last packet handed to the radio spent queued [s, world]
    reboots: int = 0
