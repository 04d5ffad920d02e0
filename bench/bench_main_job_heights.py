#!/usr/bin/env python3
"""Height tracking of the main job: climb overshoot, descent undershoot and height range during moves.

Run it next to tools/run_demo.sh (it waits up to 60 s for the launch's master on port
ROS_PORT, default 11411, records /tf and both Crazyflies' goal topics until the launch ends,
then prints per vehicle and goal change, over the 3 s after the goal changed (before landing):
the peak after a climb, the low after a descent, the height range during a horizontal move):
  /usr/bin/python3 bench/bench_main_job_heights.py & tools/run_demo.sh
"""
from __future__ import annotations

import os
import sys
import time

import bench_support  # noqa: F401  (the sources on the path, as for every bench)

VEHICLES = (1, 2)
WINDOW = 3.0   # s after a goal change


def main() -> int:
    os.environ["ROS_MASTER_URI"] = "http://127.0.0.1:%s" % os.environ.get("ROS_PORT", "11411")
    import rosgraph

    deadline = time.time() + 60.0
    while not rosgraph.is_master_online():
        if time.time() > deadline:
            print("no ROS master at %s within 60 s" % os.environ["ROS_MASTER_URI"])
            return 1
        time.sleep(0.2)
    import rospy
    from geometry_msgs.msg import PoseStamped
    from tf2_msgs.msg import TFMessage

    rospy.init_node("bench_main_job_heights", anonymous=True, disable_signals=True)
    rows = {k: [] for k in VEHICLES}
    goals = {k: None for k in VEHICLES}
    frames = {"vicon/crazyflie%d/crazyflie%d" % (k, k): k for k in VEHICLES}

    def on_tf(msg: TFMessage) -> None:
        for tr in msg.transforms:
            k = frames.get(tr.child_frame_id.strip("/"))
            if k is not None and goals[k] is not None:
                rows[k].append((tr.header.stamp.to_sec(), tr.transform.translation.z, goals[k]))

    def on_goal(k: int):
        def store(msg: PoseStamped) -> None:
            p = msg.pose.position
            goals[k] = (round(p.x, 3), round(p.y, 3), round(p.z, 3))
        return store

    rospy.Subscriber("/tf", TFMessage, on_tf, queue_size=200)
    for k in VEHICLES:
        rospy.Subscriber("/crazyflie%d/goal" % k, PoseStamped, on_goal(k), queue_size=10)
    try:
        while rosgraph.is_master_online():
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    for k in VEHICLES:
        segments = []
        for t, z, g in rows[k]:
            if not segments or segments[-1][0] != g:
                segments.append((g, []))
            segments[-1][1].append((t, z))
        out, prev = [], None
        for g, samples in segments:
            zs = [z for t, z in samples if t <= samples[0][0] + WINDOW]
            if prev is not None and len(zs) > 20:
                dz = g[2] - prev[2]
                if dz > 0.01:
                    out.append("climb %.1f->%.1f m: peak %.3f (%.3f past)" % (prev[2], g[2], max(zs), max(zs) - g[2]))
                elif dz < -0.01:
                    out.append("descent %.1f->%.1f m: low %.3f (%.3f under)" % (prev[2], g[2], min(zs), g[2] - min(zs)))
                else:
                    out.append("move at %.1f m: z %.3f..%.3f" % (g[2], min(zs), max(zs)))
            prev = g
        print("crazyflie%d: %s" % (k, "; ".join(out) or "no goal changes recorded"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
