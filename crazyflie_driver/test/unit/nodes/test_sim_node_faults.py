"""The sim node's fault parameters (``~packet_loss``, ``~ack_loss``, ``~latency_ms``, ``~faults``) and the
injected faults' diagnostics status, without ROS."""
from __future__ import annotations

import pytest

from crazyflie_driver.sim.node_config import SimConfigError, faults_status, start_faults_from_params


def test_no_fault_parameters_means_no_operations():
    assert start_faults_from_params({}, 2) == []
    assert start_faults_from_params({"packet_loss": 0.0, "ack_loss": 0.0, "latency_ms": 0.0, "faults": ""}, 2) == []


def test_radio_faults_go_to_every_dongle_and_commands_follow_in_order():
    ops = start_faults_from_params({"packet_loss": 0.3, "ack_loss": "10%", "latency_ms": 50,
                                    "faults": "unplug 1; battery crazyflie1 3.4"}, 2)
    assert ops[:2] == [("set_dongle_faults", {"dongle": d, "packet_loss": pytest.approx(30.0),
                                              "ack_loss": pytest.approx(10.0), "latency_s": pytest.approx(0.05)})
                       for d in (0, 1)]
    assert ops[2:] == [("set_dongle_faults", {"dongle": 1, "unplugged": True}),
                       ("set_battery", {"uri": "crazyflie1", "voltage": 3.4})]


@pytest.mark.parametrize("params, says", [
    ({"packet_loss": 30}, "~packet_loss must be a fraction 0..1"),
    ({"ack_loss": "x"}, "~ack_loss must be a fraction"),
    ({"latency_ms": -5}, "~latency_ms must be a duration"),
    ({"faults": "unplug 0; explode"}, "~faults: 'explode'"),
    ({"faults": "battery crazyflie1 12"}, "~faults: 'battery crazyflie1 12': battery voltage must be within"),
])
def test_a_wrong_fault_parameter_is_named(params, says):
    with pytest.raises(SimConfigError) as e:
        start_faults_from_params(params, 1)
    assert says in str(e.value)


def test_faults_status_lists_what_is_in_force():
    assert faults_status([]).level == 0 and faults_status([]).message == "no faults injected"
    st = faults_status([["dongle 0", "unplugged"], ["crazyflie1", "switched off"]])
    assert st.level == 1
    assert st.message == "2 injected: dongle 0 unplugged; crazyflie1 switched off"
    assert st.values == (("dongle 0", "unplugged"), ("crazyflie1", "switched off"))
