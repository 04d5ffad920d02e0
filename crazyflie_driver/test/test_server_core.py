"""server_core is now a re-export: every old name must still import, as the same object."""
from __future__ import annotations

import importlib

import pytest

from crazyflie_driver import server_core

NEW_HOMES = ("link_quality", "log_plan", "param_values", "poll_pacer", "registry", "setpoint", "toc",
             "worker")


@pytest.mark.parametrize("name", server_core.__all__)
def test_old_name_is_the_object_of_its_new_module(name):
    homes = [m for m in NEW_HOMES
             if getattr(importlib.import_module("crazyflie_driver." + m), name, None) is getattr(server_core, name)]
    assert homes, "%s is not re-exported from any of %s" % (name, ", ".join(NEW_HOMES))


def test_names_the_server_node_and_bench_used_are_still_there():
    for name in ("BATTERY_TOPIC", "IMU_TOPIC", "MAGNETIC_FIELD_TOPIC", "PRESSURE_TOPIC", "TEMPERATURE_TOPIC",
                 "CrazyflieRegistry", "CrazyflieWorker", "LogBlockSpec", "WorkerConfig", "WorkerListener",
                 "PlannedBlock", "PollPacer", "log_packet_rate"):
        assert name in server_core.__all__ and hasattr(server_core, name), name
