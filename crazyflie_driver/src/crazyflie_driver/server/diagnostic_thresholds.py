"""Where ``/diagnostics`` turns a Crazyflie's or a dongle's figure into OK, WARN or ERROR.

Every threshold of the server's diagnostics lives here, with its unit; docs/diagnostics.md gives the
reason for each. A figure exactly at a WARN threshold is still OK; an ERROR threshold also warns.
"""
from __future__ import annotations

# -- the window figures are counted over ------------------------------------------------------------
FIGURE_WINDOW_S = 2.0               # s of host time rates and ratios are counted over
MIN_ROUND_TRIPS = 20                # round trips in the window before the ack ratio gives a verdict
MIN_LOG_PACKETS = 10                # log packets (received + lost) in the window before the receive ratio does

# -- link -------------------------------------------------------------------------------------------
ACK_RATIO_WARN = 0.9                # acked / sent round trips below this: WARN
ACK_RATIO_ERROR = 0.5               # below this: ERROR (most packets need a re-send)
ROUND_TRIP_WARN_S = 0.010           # mean round trip (dongle wait included) above this: WARN
ROUND_TRIP_ERROR_S = 0.050          # above this: ERROR
LOG_RECEIVE_RATIO_WARN = 0.9        # log packets received / due (onboard timestamps) below this: WARN
LOG_RECEIVE_RATIO_ERROR = 0.5       # below this: ERROR

# -- battery (pm.vbat, pm.state) --------------------------------------------------------------------
BATTERY_WARN_V = 3.2                # V under load: the firmware's own low-battery level
BATTERY_CRITICAL_V = 3.0            # V: the firmware's critical level; land now
BATTERY_SAMPLE_STALE_S = 1.0        # s without a battery sample (sent every 0.1 s): WARN
PM_STATES = {0: "battery", 1: "charging", 2: "charged", 3: "low power", 4: "shutdown"}
PM_STATE_LOW_POWER = 3              # pm.state values that are a WARN
PM_STATE_SHUTDOWN = 4               # and an ERROR

# -- commands sent ----------------------------------------------------------------------------------
POSE_AGE_WARN_S = 0.5               # s since the last external position/pose, once poses flowed: WARN

# -- a dongle (radio budget) ------------------------------------------------------------------------
RADIO_LOAD_WARN = 0.8               # share of the dongle's modelled capacity in use above this: WARN
RADIO_LOAD_ERROR = 1.0              # planned load beyond the capacity: ERROR (data will be late or lost)

# -- what limits the data flow (the bottleneck entry) -------------------------------------------------
WORLD_BEHIND_FACTOR = 0.9           # simulated world below this share of its speed: it is the bottleneck
LOOP_LAG_WARN_S = 0.05              # s the server's own periodic timer wakes late: the host's CPU is
WORLD_FIGURE_STALE_S = 5.0          # s after which the world's last real-time factor is no longer trusted
