"""The fault table's rows: each fault, how it is injected and cleaned up, on which path."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Callable, List, Tuple

from fault_table.harness import GOAL, KEEPALIVE, NAME, REPO, URI, Bench, Row, fault, node_pid


# --- the rows ------------------------------------------------------------------------------------
def kill_node(bench: Bench, node: str, sig: int = signal.SIGKILL) -> None:
    os.kill(node_pid(node), sig)


def restart_world(bench: Bench) -> None:
    """Stop the sim node (Ctrl-C) and start it again with the same parameters (left on the master)."""
    pid = node_pid("/crazyflie_sim")
    os.kill(pid, signal.SIGINT)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except OSError:
            break
        time.sleep(0.05)
    script = os.path.join(REPO, "crazyflie_driver", "scripts", "crazyflie_sim_node")
    bench.graph.extra.append(subprocess.Popen([sys.executable, script, "__name:=crazyflie_sim"],
                                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                              start_new_session=True))


def emergency(bench: Bench) -> None:
    from std_srvs.srv import Empty
    bench.rospy.ServiceProxy("/%s/emergency" % NAME, Empty)()


def remove(bench: Bench) -> None:
    """``/remove_crazyflie`` while it flies (the controller keeps publishing its setpoints)."""
    from crazyflie_driver.srv import RemoveCrazyflie
    bench.rospy.ServiceProxy("/remove_crazyflie", RemoveCrazyflie)(uri=URI)


GO_TO_PERIOD_S = 0.1     # another client's go_to while the server lands the Crazyflie


def go_to_request(goal: Tuple[float, float, float], group_mask: int = 0):
    import rospy

    from crazyflie_driver.srv import GoTo
    req = GoTo._request_class(groupMask=group_mask, relative=False, yaw=0.0, duration=rospy.Duration(1.0))
    req.goal.x, req.goal.y, req.goal.z = goal
    return req


def remove_with_go_to(bench: Bench) -> None:
    """``/remove_crazyflie`` while it flies, and meanwhile another client's go_to (to the goal) every 0.1 s
    until the removal answers: each one during the server's landing must be refused, not end it in the air."""
    from crazyflie_driver.srv import GoTo
    go_to = bench.rospy.ServiceProxy("/%s/go_to" % NAME, GoTo)
    done = threading.Event()
    said: List[str] = []

    def meanwhile() -> None:
        while not done.is_set():
            try:
                go_to(go_to_request(GOAL))
                said.append("ok")
            except bench.rospy.ServiceException:        # the server answered with an error: a refusal
                said.append("refused")
            except bench.rospy.ROSException:            # no answer at all
                said.append("failed")
            time.sleep(GO_TO_PERIOD_S)
    thread = threading.Thread(target=meanwhile, daemon=True)
    thread.start()
    try:
        remove(bench)
    finally:
        done.set()
        thread.join(2.0)
    print("  go_to during the removal: %s" % ", ".join("%d %s" % (said.count(k), k) for k in ("ok", "refused",
                                                                                           "failed")))


def refused_call(service: str, **fields: Any) -> Callable[[Bench], None]:
    """A ``land`` (height, duration_s) or ``go_to`` (goal, group_mask) of ``/crazyflie1`` that the server
    should refuse, nothing sent: the answer is printed; the row's truth says whether it kept hovering."""
    def act(bench: Bench) -> None:
        from crazyflie_driver.srv import GoTo, Land
        try:
            if service == "go_to":
                bench.rospy.ServiceProxy("/%s/go_to" % NAME, GoTo)(go_to_request(fields["goal"], fields["group_mask"]))
            else:
                bench.rospy.ServiceProxy("/%s/land" % NAME, Land)(
                    groupMask=0, height=fields["height"], duration=bench.rospy.Duration(fields["duration_s"]))
            print("  %s: accepted" % service)
        except bench.rospy.ServiceException as e:
            print("  %s refused: %s" % (service, str(e)[:160]))
    return act


def streamed_then_silent(bench: Bench) -> None:
    """Position setpoints streamed at the goal for 1 s (50 Hz), then none: a setpoint source gone silent."""
    from crazyflie_driver.msg import Position
    pub = bench.rospy.Publisher("/%s/cmd_position" % NAME, Position, queue_size=1, tcp_nodelay=True)
    deadline = time.monotonic() + 5.0
    while pub.get_num_connections() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        pub.publish(Position(x=GOAL[0], y=GOAL[1], z=GOAL[2], yaw=0.0))
        time.sleep(0.02)
    pub.unregister()


def clear(bench: Bench) -> None:
    fault("clear")


def sleep_then(seconds: float, words: str) -> Callable[[Bench], None]:
    def act(bench: Bench) -> None:
        time.sleep(seconds)
        fault(words)
    return act


def both(*acts: Callable[[Bench], None]) -> Callable[[Bench], None]:
    def act(bench: Bench) -> None:
        for a in acts:
            a(bench)
    return act


def inject(words: str) -> Callable[[Bench], None]:
    return lambda bench: fault(words)


def battery_levels() -> Tuple[float, float, float, str]:
    """Voltages for the battery rows (what pm.vbat reads under the hover load right after the fault):
    between the stack's warning and critical levels, below its critical level, and below the firmware's
    cut-off; the stack's levels are its defaults where it has them, else the firmware's own."""
    from crazyflie_driver.sim.room import battery as firmware
    try:
        from crazyflie_driver.server.safety import SafetyConfig
        config = SafetyConfig()
        warning, critical, source = config.battery_warning_v, config.battery_critical_v, "the server's safety"
    except (ImportError, AttributeError):
        warning, critical, source = firmware.LOW_VOLTAGE, firmware.CRITICAL_VOLTAGE, "the firmware's"
    return round((warning + critical) / 2.0, 2), round(critical - 0.05, 2), firmware.CRITICAL_VOLTAGE - 0.05, source


def rows() -> List[Row]:
    warning_v, critical_v, empty_v, source = battery_levels()
    full = lambda b: fault("battery %s 100%%" % NAME)   # noqa: E731
    return [
        Row("loss30", "30 % packet loss", "chapter", inject("loss 0 --packet 0.3"), 6.0, clear),
        Row("loss80", "80 % packet loss", "chapter", inject("loss 0 --packet 0.8"), 6.0, clear),
        Row("ackloss", "50 % ack loss", "chapter", inject("loss 0 --ack 0.5"), 6.0, clear),
        Row("latency", "50 ms radio latency", "chapter", inject("latency 0 50ms"), 6.0, clear),
        Row("unplug1", "dongle unplugged for 1 s", "chapter", both(inject("unplug 0"), sleep_then(1.0, "replug 0")),
            9.0, clear),
        Row("unplug", "dongle unplugged for good", "chapter", inject("unplug 0"), 8.0, clear),
        Row("unplug_onboard", "dongle unplugged for good", "onboard", inject("unplug 0"), 8.0, clear),
        Row("poweroff", "Crazyflie switched off", "chapter", inject("power %s off" % NAME), 4.0,
            lambda b: fault("power %s on" % NAME)),
        Row("controller", "controller killed (SIGKILL): setpoint source silent", "chapter",
            lambda b: kill_node(b, "/%s/controller" % NAME), 10.0),
        Row("server", "server killed (SIGKILL)", "chapter", lambda b: kill_node(b, "/crazyflie_server"), 6.0),
        Row("server_int", "server stopped (Ctrl-C)", "chapter",
            lambda b: kill_node(b, "/crazyflie_server", signal.SIGINT), 10.0),
        Row("server_onboard", "server killed (SIGKILL)", "onboard", lambda b: kill_node(b, "/crazyflie_server"), 8.0),
        Row("server_keepalive", "server killed (SIGKILL)", KEEPALIVE, lambda b: kill_node(b, "/crazyflie_server"),
            8.0),
        Row("unplug_keepalive", "dongle unplugged for good", KEEPALIVE, inject("unplug 0"), 8.0, clear),
        Row("server_int_onboard", "server stopped (Ctrl-C)", "onboard",
            lambda b: kill_node(b, "/crazyflie_server", signal.SIGINT), 8.0),
        Row("silent_onboard", "setpoints streamed for 1 s, then silent (times from the stream start)", "onboard",
            streamed_then_silent, 8.0),
        Row("remove", "/remove_crazyflie while flying", "chapter", remove, 10.0),
        Row("remove_onboard", "/remove_crazyflie while flying", "onboard", remove, 8.0),
        Row("remove_go_to_onboard", "/remove_crazyflie while flying, another client's go_to every 0.1 s", "onboard",
            remove_with_go_to, 8.0),
        Row("land0_onboard", "land with duration 0 (refused: motors off in the air)", "onboard",
            refused_call("land", height=0.0, duration_s=0.0), 4.0),
        Row("land_up_onboard", "land to 1.9 m, above the Crazyflie (refused: a climb, then a fall)", "onboard",
            refused_call("land", height=1.9, duration_s=2.0), 5.0),
        Row("go_to_nobody_onboard", "go_to with a group mask addressing nobody (refused)", "onboard",
            refused_call("go_to", goal=(GOAL[0], GOAL[1], GOAL[2] + 0.5), group_mask=2), 4.0),
        Row("freeze02", "mocap frozen 0.2 s", "chapter", inject("mocap %s --freeze 0.2" % NAME), 5.0, clear),
        Row("freeze2", "mocap frozen 2 s", "chapter", inject("mocap %s --freeze 2" % NAME), 8.0, clear),
        Row("freeze", "mocap frozen for good", "chapter", inject("mocap %s --freeze" % NAME), 10.0, clear),
        Row("hide", "mocap lost for good (body hidden)", "chapter", inject("mocap %s --hide" % NAME), 8.0, clear),
        Row("battery_warn", "battery at warning (%.2f V; levels: %s)" % (warning_v, source), "chapter",
            inject("battery %s %.2f" % (NAME, warning_v)), 8.0, full),
        Row("battery_crit", "battery at critical (%.2f V; levels: %s)" % (critical_v, source), "chapter",
            inject("battery %s %.2f" % (NAME, critical_v)), 12.0, full),
        Row("battery_crit_onboard", "battery at critical (%.2f V; levels: %s)" % (critical_v, source), "onboard",
            inject("battery %s %.2f" % (NAME, critical_v)), 10.0, full),
        Row("battery_empty", "battery below the firmware's cut-off (%.2f V)" % empty_v, "chapter",
            inject("battery %s %.2f" % (NAME, empty_v)), 10.0, full),
        Row("emergency", "emergency while flying", "chapter", emergency, 3.0),
        Row("emergency_onboard", "emergency while flying", "onboard", emergency, 3.0),
        Row("world", "world restarted", "chapter", restart_world, 10.0),
    ]
