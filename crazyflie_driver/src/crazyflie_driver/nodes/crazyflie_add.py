"""``crazyflie_add``: reads its private parameters, calls ``/add_crazyflie``, exits (0 ok, 1 error).

Private parameters (as in the original): ``uri`` (required), ``tf_prefix``, ``roll_trim``,
``pitch_trim``, ``enable_logging``, ``enable_parameters``, ``genericLogTopics``,
``genericLogTopicFrequencies`` (a PERIOD in milliseconds per topic, despite the name) and
``genericLogTopic_<name>_Variables``, ``enable_logging_{imu,temperature,magnetic_field,pressure,battery,
packets}`` and ``use_ros_time`` (each default true). The chapter's AddCrazyflie request has no fields
for the last ones, so they are left as parameters under the Crazyflie's namespace, where the server
reads them when the request arrives. ``service_timeout`` (s, default 30): how long to wait for
the server to appear.
"""
from __future__ import annotations

import sys
from typing import Any, Dict

import rospy

from crazyflie_driver.msg import LogBlock
from crazyflie_driver.nodes.ros_signals import init_node
from crazyflie_driver.server.add_config import AddConfigError, config_from_params, topic_switches_from_params
from crazyflie_driver.server.worker import WorkerConfig
from crazyflie_driver.srv import AddCrazyflie, AddCrazyflieRequest


def private_params() -> Dict[str, Any]:
    """Every private parameter of this node, by name without the ``~``."""
    prefix = rospy.get_name().rstrip("/") + "/"
    out = {}
    for full in rospy.get_param_names():
        if full.startswith(prefix):
            out[full[len(prefix):]] = rospy.get_param(full)
    return out


def request_from_config(config: WorkerConfig) -> AddCrazyflieRequest:
    req = AddCrazyflieRequest()
    req.uri, req.tf_prefix = config.uri, config.tf_prefix
    req.roll_trim, req.pitch_trim = config.roll_trim, config.pitch_trim
    req.enable_logging, req.enable_parameters = config.enable_logging, config.enable_parameters
    req.log_blocks = [LogBlock(topic_name=b.topic_name, frequency=b.period_ms, variables=list(b.variables))
                      for b in config.log_blocks]
    return req


def run() -> int:
    init_node("crazyflie_add", anonymous=True)
    params = private_params()
    try:
        config = config_from_params(params)
    except AddConfigError as e:
        rospy.logerr("crazyflie_add: %s", e)
        return 1
    ns = "/" + config.tf_prefix if config.tf_prefix else ""
    for key, value in topic_switches_from_params(params).items():   # checked by config_from_params
        rospy.set_param(ns + "/" + key, value)
    wait = float(params.get("service_timeout", 30.0))
    try:
        rospy.wait_for_service("/add_crazyflie", timeout=wait)
    except rospy.ROSException:
        rospy.logerr("crazyflie_add: service /add_crazyflie not available after %.0f s (is "
                     "crazyflie_server running?)", wait)
        return 1
    try:
        rospy.ServiceProxy("/add_crazyflie", AddCrazyflie)(request_from_config(config))
    except (rospy.ServiceException, rospy.ROSException) as e:
        rospy.logerr("crazyflie_add: %s", e)
        return 1
    rospy.loginfo("crazyflie_add: %s added as %r", config.uri, config.tf_prefix)
    return 0


def main() -> None:
    sys.exit(run())


if __name__ == "__main__":
    main()
