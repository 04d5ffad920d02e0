"""The tf tree as a reader wants to see it: which frame hangs below which, who publishes it, how often.

tf's ``view_frames`` (the chapter's §6.1) is not packaged for Debian; ``rosrun crazyflie_demo
view_frames`` listens to ``/tf`` and ``/tf_static`` for a few seconds and prints this tree, and
optionally writes it as a Graphviz file. This module is ROS-free: it takes each transform as
(parent, child, stamp, publisher, static) and renders text or DOT.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Set


def clean(frame: str) -> str:
    """tf2 frame ids carry no leading '/'; the chapter's (``/vicon/crazyflie/crazyflie``) do."""
    return frame.strip().lstrip("/")


@dataclass
class Edge:
    """One parent -> child transform as heard."""
    parent: str
    child: str
    static: bool = False
    count: int = 0
    first_stamp: float = 0.0
    last_stamp: float = 0.0
    publishers: Set[str] = field(default_factory=set)

    def rate_hz(self) -> Optional[float]:
        """Average rate over the stamps heard; None for a static transform or too few stamps."""
        span = self.last_stamp - self.first_stamp
        if self.static or self.count < 2 or span <= 0:
            return None
        return (self.count - 1) / span


class TfTree:
    """Transforms heard on /tf and /tf_static, by child frame (tf allows one parent per frame)."""

    def __init__(self) -> None:
        self.edges: Dict[str, Edge] = {}
        self.reparented: List[str] = []     # "child: parent a, then b": tf would complain too

    def add(self, parent: str, child: str, stamp: float, publisher: str = "", static: bool = False) -> None:
        parent, child = clean(parent), clean(child)
        if not parent or not child or parent == child:
            return
        edge = self.edges.get(child)
        if edge is None or edge.parent != parent:
            if edge is not None:
                self.reparented.append("%s: parent %s, then %s" % (child, edge.parent, parent))
            edge = self.edges[child] = Edge(parent, child, static, first_stamp=stamp)
        edge.count += 1
        edge.static = edge.static or static
        edge.last_stamp = max(edge.last_stamp, stamp)
        edge.first_stamp = min(edge.first_stamp, stamp)
        if publisher:
            edge.publishers.add(publisher)

    def frames(self) -> Set[str]:
        return set(self.edges) | {e.parent for e in self.edges.values()}

    def roots(self) -> List[str]:
        """Frames that are nobody's child: one root means every frame can be looked up in it."""
        return sorted(f for f in self.frames() if f not in self.edges)

    def children(self, frame: str) -> List[str]:
        return sorted(e.child for e in self.edges.values() if e.parent == frame)

    def _label(self, edge: Edge) -> str:
        rate = edge.rate_hz()
        how = "static" if edge.static else ("%.1f Hz" % rate if rate is not None else "%d message" % edge.count)
        who = ", ".join(sorted(edge.publishers))
        return "%s%s" % (how, ", from " + who if who else "")

    def text(self) -> str:
        """The tree, one frame a line, indented below its parent."""
        if not self.edges:
            return "no transforms heard on /tf or /tf_static (is the motion capture, or the simulated world, running?)"
        lines: List[str] = []
        seen: Set[str] = set()

        def walk(frame: str, indent: str, last: bool, top: bool) -> None:
            seen.add(frame)
            if top:
                lines.append(frame)
                lead = ""
            else:
                branch = "`--" if last else "|--"
                lines.append("%s%s %s  (%s)" % (indent, branch, frame, self._label(self.edges[frame])))
                lead = indent + ("    " if last else "|   ")
            kids = [k for k in self.children(frame) if k not in seen]
            for i, kid in enumerate(kids):
                walk(kid, lead, i == len(kids) - 1, False)

        roots = self.roots()
        for root in roots:
            walk(root, "", True, True)
        loops = sorted(set(self.edges) - seen)
        if loops:
            lines.append("in a loop (tf cannot look these up): %s" % ", ".join(loops))
        if len(roots) > 1:
            lines.append("%d separate trees: a frame of one cannot be looked up in another (roots: %s)"
                         % (len(roots), ", ".join(roots)))
        for note in self.reparented:
            lines.append("published with two parents: %s" % note)
        return "\n".join(lines)

    def dot(self) -> str:
        """The tree in Graphviz's DOT language (``dot -Tpdf frames.gv -o frames.pdf``)."""
        out = ["digraph tf {", "  rankdir=TB;", "  node [shape=box];"]
        for frame in sorted(self.frames()):
            out.append("  %s;" % _quote(frame))
        for child in sorted(self.edges):
            edge = self.edges[child]
            out.append("  %s -> %s [label=%s];" % (_quote(edge.parent), _quote(child), _quote(self._label(edge))))
        out.append("}")
        return "\n".join(out) + "\n"


def _quote(text: str) -> str:
    return '"%s"' % text.replace("\\", "\\\\").replace('"', '\\"')
