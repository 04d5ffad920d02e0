"""Where the swarm's motion capture comes from (``~mocap``): VRPN directly, tf, or PoseStamped topics.

* ``vrpn``: the stack's own VRPN client (``mocap.vrpn_client``) connected to ``~vrpn_server``; one
  tracker per Crazyflie, named by ``~mocap_pattern`` (default its tf_prefix);
* ``tf``: transforms on ``/tf`` from ``~world_frame`` straight to the frame ``~mocap_pattern`` names
  (vrpn_client_ros: ``{name}``; vicon_bridge: ``vicon/{name}/{name}``);
* ``topic``: one ``geometry_msgs/PoseStamped`` topic per Crazyflie (default
  ``/vrpn_client_node/{name}/pose``, as vrpn_client_ros publishes).

Each pose is handed to ``on_pose(name, position, orientation, received)`` with the arrival time on
the server's clock (ROS time: the world's in a simulation).
"""
from __future__ import annotations

from typing import Callable, Dict, List

import rospy
from geometry_msgs.msg import PoseStamped

from crazyflie_driver.clock import WALL, Clock
from crazyflie_driver.mocap.vrpn_client import PoseReport, VrpnClient, parse_server
from crazyflie_driver.server.swarm.options import SwarmOptions

OnPose = Callable[..., bool]


class _VrpnSource:
    def __init__(self, server: str, names: Dict[str, str], on_pose: OnPose, clock: Clock) -> None:
        host, port = parse_server(server)

        def report(r: PoseReport) -> None:
            name = names.get(r.tracker)
            if name is not None:
                on_pose(name, r.position, r.orientation, r.receive_time)

        self.client = VrpnClient(host, port, trackers=list(names), on_pose=report, clock=clock.now,
                                 log=lambda level, text: rospy.logwarn("swarm mocap: %s", text) if level >= 30
                                 else rospy.logdebug("swarm mocap: %s", text)).start()

    def stop(self) -> None:
        self.client.stop()


class _TfSource:
    def __init__(self, world_frame: str, names: Dict[str, str], on_pose: OnPose, clock: Clock) -> None:
        from tf2_msgs.msg import TFMessage

        frames = {f.strip("/"): n for f, n in names.items()}
        world = world_frame.strip("/")

        def on_tf(msg) -> None:
            now = clock.now()
            for t in msg.transforms:
                name = frames.get(t.child_frame_id.strip("/"))
                if name is not None and t.header.frame_id.strip("/") == world:
                    p, q = t.transform.translation, t.transform.rotation
                    on_pose(name, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), now)

        self.sub = rospy.Subscriber("/tf", TFMessage, on_tf, queue_size=100, tcp_nodelay=True)

    def stop(self) -> None:
        self.sub.unregister()


class _TopicSource:
    def __init__(self, names: Dict[str, str], on_pose: OnPose, clock: Clock) -> None:
        def callback(name: str):
            def on_msg(msg: PoseStamped) -> None:
                p, q = msg.pose.position, msg.pose.orientation
                on_pose(name, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), clock.now())
            return on_msg

        self.subs: List[rospy.Subscriber] = [
            rospy.Subscriber(topic, PoseStamped, callback(name), queue_size=10, tcp_nodelay=True)
            for topic, name in names.items()]

    def stop(self) -> None:
        for s in self.subs:
            s.unregister()


def start(options: SwarmOptions, names: Dict[str, str], on_pose: OnPose, clock: Clock = WALL):
    """The source ``options.mocap`` asks for; ``names``: source name (tracker, frame, topic) -> Crazyflie;
    ``clock`` stamps each pose's arrival."""
    if options.mocap == "vrpn":
        return _VrpnSource(options.vrpn_server, names, on_pose, clock)
    if options.mocap == "tf":
        return _TfSource(options.world_frame, names, on_pose, clock)
    return _TopicSource(names, on_pose, clock)
