"""What the Crazyflie firmware accepts: setpoint ranges, thrust, log block limits. One home for each.

The host checks these before sending, so a request the firmware would refuse (or act on badly)
fails with a sentence that names the limit; the simulated firmware enforces the same numbers.
docs/protocol.md lists them with their sources.
"""
from __future__ import annotations

from dataclasses import dataclass

# -- RPYT setpoints (port 3) ------------------------------------------------------------------------

#: Highest thrust the commander passes on (raw units, uint16 on the wire); higher values are cut to it.
MAX_THRUST = 60000
#: Raw thrust below this is taken as 0 (motors off) by the commander.
MIN_THRUST = 1000
#: Roll and pitch setpoints in angle mode (the default), degrees: beyond +-90 the attitude asked for
#: is upside down, which the attitude controller cannot hold.
MAX_ANGLE_DEG = 90.0
#: Rate setpoints (yaw always; roll and pitch in rate mode), degrees per second: the gyro's full
#: scale. A larger rate cannot even be measured onboard, let alone tracked.
MAX_RATE_DEG_S = 2000.0

# -- the commander's setpoint watchdog (ports 3 and 7) -----------------------------------------------

#: Seconds after the last setpoint at which the commander levels the vehicle out (thrust kept).
SETPOINT_WATCHDOG_LEVEL_S = 0.5
#: Seconds after the last setpoint at which it stops the motors of a flying vehicle: current firmware's
#: supervisor then stays locked until a reboot; firmware 2016.02 sets the thrust lock again instead
#: (released by a setpoint with thrust 0).
SETPOINT_WATCHDOG_CUT_S = 2.0


# -- log blocks (port 5) ----------------------------------------------------------------------------

@dataclass(frozen=True)
class LogLimits:
    """Log limits of one firmware generation."""

    max_blocks: int     # log blocks that exist at once
    max_ops: int        # log variables over all blocks
    max_bytes: int      # bytes of values in one block (one data packet)


#: Current firmware (the TOC info answer also reports blocks and ops).
LOG_LIMITS = LogLimits(max_blocks=16, max_ops=128, max_bytes=26)
#: Firmware 2016.02, the original crazyflie_ros era.
LOG_LIMITS_2016 = LogLimits(max_blocks=8, max_ops=64, max_bytes=30)

#: Bytes of values one log block may carry on any firmware (the smaller of the generations').
LOG_BLOCK_MAX_BYTES = min(LOG_LIMITS.max_bytes, LOG_LIMITS_2016.max_bytes)
#: Log blocks the host ever asks for (the TOC info may report fewer).
LOG_MAX_BLOCKS = LOG_LIMITS.max_blocks
#: Log variables over all blocks the host ever asks for (the TOC info may report fewer).
LOG_MAX_OPS = LOG_LIMITS.max_ops

#: Log period, ms: START carries it in 10 ms units in one byte (1..255).
LOG_PERIOD_UNIT_MS = 10
LOG_PERIOD_MIN_MS = LOG_PERIOD_UNIT_MS
LOG_PERIOD_MAX_MS = 255 * LOG_PERIOD_UNIT_MS
#: Log period with START_V2 (protocol version 8 and later): whole ms in a uint16.
LOG_PERIOD_V2_MAX_MS = 0xFFFF

# -- TOC names ---------------------------------------------------------------------------------------

#: The firmware asserts at boot that ``group NUL name NUL`` of each TOC entry fits in this many bytes.
TOC_NAME_MAX_BYTES = 26
