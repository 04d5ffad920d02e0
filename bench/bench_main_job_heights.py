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
from typing import Dict, List, Optional, Tuple

import bench_support  # noqa: F401  (the sources on the path, as for every bench)

VEHICLES = (1, 2)
WINDOW = 3.0   # s after a goal change


Goal = Tuple[float, float, float]
Row = Tuple[float, float, Goal]         # (stamp s, height m, the goal then)


def main() -> int:
    os.environ["ROS_MASTER_URI"] = "http://127.0.0.1:%s" % os.environ.get("ROS_PORT", "11411")
    if not wait_for_master(60.0):
        print("no ROS master at %s within 60 s" % os.environ["ROS_MASTER_URI"])
        return 1
    rows = record_until_master_gone()
    for k in VEHICLES:
        out = goal_change_lines(goal_segments(rows[k]))
        print("crazyflie%d: %s" % (k, "; ".join(out) or "no goal changes recorded"))
    return 0


def wait_for_master(timeout_s: float) -> bool:
    """Whether the launch's ROS master came up within ``timeout_s``."""
    import rosgraph

    deadline = time.time() + timeout_s
    while not rosgraph.is_master_online():
        if time.time() > deadline:
            return False
        time.sleep(0.2)
    return True


def record_until_master_gone() -> Dict[int, List[Row]]:
    """Each vehicle's heights from /tf with its goal at the time, from its first goal until the master ends."""
    import rosgraph
    import rospy
    from geometry_msgs.msg import PoseStamped
    from tf2_msgs.msg import TFMessage

    rospy.init_node("bench_main_job_heights", anonymous=True, disable_signals=True)
    rows: Dict[int, List[Row]] = {k: [] for k in VEHICLES}
    goals: Dict[int, Optional[Goal]] = {k: None for k in VEHICLES}
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
    return rows


def goal_segments(rows: List[Row]) -> List[Tuple[Goal, List[Tuple[float, float]]]]:
    """The rows cut where the goal changes: (goal, [(stamp, height), ...]) in order."""
    segments: List[Tuple[Goal, List[Tuple[float, float]]]] = []
    for t, z, g in rows:
        if not segments or segments[-1][0] != g:
            segments.append((g, []))
        segments[-1][1].append((t, z))
    return segments


def goal_change_lines(segments: List[Tuple[Goal, List[Tuple[float, float]]]]) -> List[str]:
    """One line per goal change with more than 20 samples in the ``WINDOW`` s after it."""
    out, prev = [], None
    for g, samples in segments:
        zs = [z for t, z in samples if t <= samples[0][0] + WINDOW]
        if prev is not None and len(zs) > 20:
            out.append(goal_change_line(prev[2], g[2], zs))
        prev = g
    return out


def goal_change_line(z_from: float, z_to: float, zs: List[float]) -> str:
    """A climb's peak, a descent's low, or a level move's range (m) from the heights ``zs`` after it."""
    dz = z_to - z_from
    if dz > 0.01:
        return "climb %.1f->%.1f m: peak %.3f (%.3f past)" % (z_from, z_to, max(zs), max(zs) - z_to)
    if dz < -0.01:
        return "descent %.1f->%.1f m: low %.3f (%.3f under)" % (z_from, z_to, min(zs), z_to - min(zs))
    return "move at %.1f m: z %.3f..%.3f" % (z_to, min(zs), max(zs))


if __name__ == "__main__":
    sys.exit(main())
