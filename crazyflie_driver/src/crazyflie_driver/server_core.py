"""Former home of the server's ROS-free core; kept so that old imports keep working.

New code imports from the modules that now hold each part:

* ``log_plan``: fixed and custom log topics, their validation and packing into log blocks;
* ``param_values``: ROS parameter values converted to a Crazyflie parameter's type;
* ``setpoint``: the cmd_vel -> RPYT setpoint mapping;
* ``link_quality``: per-Crazyflie link quality and its warning thresholds;
* ``poll_pacer``: timing of the polls that fetch queued log packets;
* ``toc``: ``toc_entries`` / ``toc_types`` of a TOC in any shape;
* ``worker``: ``CrazyflieWorker``, its config, listener and states;
* ``registry``: ``CrazyflieRegistry`` and ``DuplicateCrazyflie``.
"""
from __future__ import annotations

from .link_quality import (LINK_QUALITY_MIN_SAMPLES, LINK_QUALITY_RECOVERED, LINK_QUALITY_WARNING,
                           LINK_QUALITY_WINDOW, LinkQuality)
from .log_plan import (BATTERY_TOPIC, CTYPE_SIZES, FIXED_LOG_TOPICS, IMU_TOPIC, LOG_BLOCK_MAX_BYTES,
                       LOG_PERIOD_MAX_MS, LOG_PERIOD_MIN_MS, MAGNETIC_FIELD_TOPIC, PRESSURE_TOPIC,
                       RADIO_RSSI_TOPIC, RESERVED_TOPIC_NAMES, RSSI_LOG_VARIABLE, TEMPERATURE_TOPIC,
                       LogBlockSpec, PlannedBlock, log_packet_rate, plan_log_blocks, topic_size,
                       validate_log_block_specs)
from .param_values import coerce_param_value
from .poll_pacer import PollPacer
from .registry import CrazyflieRegistry, DuplicateCrazyflie
from .setpoint import MAX_THRUST, Setpoint, setpoint_from_twist
from .toc import toc_entries, toc_types
from .worker import LOG, CrazyflieWorker, WorkerConfig, WorkerListener, WorkerState

__all__ = [
    "BATTERY_TOPIC", "CTYPE_SIZES", "FIXED_LOG_TOPICS", "IMU_TOPIC", "LINK_QUALITY_MIN_SAMPLES",
    "LINK_QUALITY_RECOVERED", "LINK_QUALITY_WARNING", "LINK_QUALITY_WINDOW", "LOG",
    "LOG_BLOCK_MAX_BYTES", "LOG_PERIOD_MAX_MS", "LOG_PERIOD_MIN_MS", "MAGNETIC_FIELD_TOPIC",
    "MAX_THRUST", "PRESSURE_TOPIC", "RADIO_RSSI_TOPIC", "RESERVED_TOPIC_NAMES", "RSSI_LOG_VARIABLE",
    "TEMPERATURE_TOPIC", "CrazyflieRegistry", "CrazyflieWorker", "DuplicateCrazyflie", "LinkQuality",
    "LogBlockSpec", "PlannedBlock", "PollPacer", "Setpoint", "WorkerConfig", "WorkerListener",
    "WorkerState", "coerce_param_value", "log_packet_rate", "plan_log_blocks", "setpoint_from_twist",
    "toc_entries", "toc_types", "topic_size", "validate_log_block_specs",
]
