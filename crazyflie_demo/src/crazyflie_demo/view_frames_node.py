"""``rosrun crazyflie_demo view_frames [seconds] [--dot FILE]``: print the tf tree heard on /tf and /tf_static.

The chapter's ``rosrun tf view_frames`` (§6.1) needs tf, which Debian does not package. This
listens for ``seconds`` (default 5, as tf's tool does), prints the tree (frame, rate, publisher) and,
with ``--dot FILE``, writes it in Graphviz's DOT language for ``dot -Tpdf FILE -o frames.pdf``.
"""
from __future__ import annotations

import argparse
import sys
from typing import List, Optional

import rospy
from tf2_msgs.msg import TFMessage

from crazyflie_demo.tf_tree import TfTree
from crazyflie_driver.nodes.ros_signals import init_node

DEFAULT_LISTEN_S = 5.0


def parse(argv: List[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="view_frames", description=__doc__.split("\n\n")[0])
    parser.add_argument("seconds", nargs="?", type=float, default=DEFAULT_LISTEN_S,
                        help="how long to listen (default %(default)s s)")
    parser.add_argument("--dot", metavar="FILE", help="also write the tree as a Graphviz file")
    args = parser.parse_args(argv)
    if not 0 < args.seconds < 3600:
        parser.error("seconds must be more than 0 and less than 3600, got %r" % args.seconds)
    return args


def main(argv: Optional[List[str]] = None) -> int:
    args = parse(rospy.myargv(sys.argv)[1:] if argv is None else argv)
    init_node("view_frames", anonymous=True)
    tree = TfTree()

    def heard(msg: TFMessage, static: bool) -> None:
        caller = (getattr(msg, "_connection_header", None) or {}).get("callerid", "")
        for t in msg.transforms:
            tree.add(t.header.frame_id, t.child_frame_id, t.header.stamp.to_sec(), caller, static)

    rospy.Subscriber("/tf", TFMessage, heard, callback_args=False, queue_size=100)
    rospy.Subscriber("/tf_static", TFMessage, heard, callback_args=True, queue_size=100)
    rospy.loginfo("view_frames: listening to /tf and /tf_static for %.1f s", args.seconds)
    try:
        rospy.sleep(args.seconds)
    except rospy.ROSInterruptException:
        return 1
    print(tree.text(), flush=True)
    if args.dot:
        try:
            with open(args.dot, "w") as f:
                f.write(tree.dot())
        except OSError as e:
            print("view_frames: cannot write %s: %s" % (args.dot, e), file=sys.stderr)
            return 1
        print("view_frames: wrote %s (render it: dot -Tpdf %s -o frames.pdf)" % (args.dot, args.dot))
    return 0 if tree.edges else 1
