"""controller.py: the chapter's joystick buttons wired to the Crazyflie's services.

Button 0 lands, 1 is emergency, 2 takes off (those two only with ~use_crazyflie_controller),
4 toggles ring/headlightEnable through update_params. Service calls run on a worker thread
so a slow service never blocks the joystick callback, except emergency, which is called at
once from the callback itself.
"""
from __future__ import annotations

import queue
import threading

import rospy
from sensor_msgs.msg import Joy
from std_srvs.srv import Empty

from crazyflie_demo.joystick_buttons import ButtonEdges, actions_for
from crazyflie_demo.rosutil import wait_for_service
from crazyflie_driver.nodes.ros_signals import init_node, shutting_down


class JoystickController:
    def __init__(self, use_controller: bool, joy_topic: str) -> None:
        from crazyflie_driver.srv import UpdateParams
        self._emergency = rospy.ServiceProxy("emergency", Empty)
        self._update_params = rospy.ServiceProxy("update_params", UpdateParams)
        self._takeoff = rospy.ServiceProxy("takeoff", Empty) if use_controller else None
        self._land = rospy.ServiceProxy("land", Empty) if use_controller else None
        self._edges = ButtonEdges()
        self._jobs: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._work, name="joystick_actions", daemon=True).start()
        rospy.Subscriber(joy_topic, Joy, self._on_joy, queue_size=10)

    def _on_joy(self, msg: Joy) -> None:
        for action in actions_for(self._edges.pressed(msg.buttons)):
            if action == "emergency":
                self._call("emergency", self._emergency)
            else:
                self._jobs.put(action)

    def _work(self) -> None:
        while not rospy.is_shutdown():
            try:
                action = self._jobs.get(timeout=0.5)
            except queue.Empty:
                continue
            if action == "takeoff" and self._takeoff:
                self._call("takeoff", self._takeoff)
            elif action == "land" and self._land:
                self._call("land", self._land)
            elif action == "headlight":
                self._toggle_headlight()

    def _toggle_headlight(self) -> None:
        name = "ring/headlightEnable"
        value = int(rospy.get_param(name, 0))
        rospy.set_param(name, 0 if value else 1)
        self._call("update_params", self._update_params, [name])
        rospy.loginfo("headlight %s", "off" if value else "on")

    @staticmethod
    def _call(what: str, proxy, *args) -> None:
        try:
            proxy(*args)
        except (rospy.ServiceException, rospy.ROSException) as exc:
            rospy.logerr("%s failed: %s", what, exc)


def main() -> None:
    init_node("joystick_controller")
    use_controller = bool(rospy.get_param("~use_crazyflie_controller", False))
    joy_topic = rospy.get_param("~joy_topic", "joy")
    wait_for_service("update_params", 30.0)
    if use_controller:
        wait_for_service("takeoff", 30.0)
    if shutting_down():
        return
    JoystickController(use_controller, joy_topic)
    rospy.spin()
