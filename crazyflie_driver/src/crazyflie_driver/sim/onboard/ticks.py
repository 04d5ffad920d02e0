"""The firmware's clock, in one place: the simulated world advances in ticks of the firmware's main loop.

The current firmware's stabilizer loop runs every 1 ms (1 kHz); its attitude and rate PIDs run on
every second tick (500 Hz), so the motor commands change at 500 Hz (and on the tick a new setpoint,
lock or parameter arrives). The world keeps the 1 ms tick as its unit of time (firmware timers, log
blocks, watchdogs and the motion capture fire on tick boundaries) and runs the gyro, the PIDs and the
rigid-body integration once per control period (docs/world_performance.md).
"""
from __future__ import annotations

FIRMWARE_TICK_S = 0.001        # s, one tick of the firmware's main loop (1 kHz)
CONTROL_TICKS = 2              # ticks between runs of the attitude/rate PIDs (500 Hz)
CONTROL_PERIOD_S = FIRMWARE_TICK_S * CONTROL_TICKS     # s, 2 ms
